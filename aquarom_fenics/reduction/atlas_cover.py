"""The PROM atlas's cover of a design box and the PROM at a centre: below the optimisers,
used by ``sweep --model prom`` (:mod:`~aquarom_fenics.studies.atlas`) and the multi-start screen
(:mod:`~aquarom_fenics.optimization.screen`).

One PROM answers only inside its validity radius r (SPEC §8). The atlas covers the scene's box
[lower, upper] with a grid of cells, each the box around its centre c of half-width h_k per shape,

    n_k = ⌈(upper_k - lower_k) / (2 s r_k)⌉ cells,   h_k = (upper_k - lower_k) / (2 n_k) ≤ s r_k,
    c_k = lower_k + (2 i_k + 1) h_k,   i_k = ⌊(ξ_k - lower_k) / (2 h_k)⌋,

with s the scene's ``[reduction] atlas_scale`` (default :data:`RADIUS_SCALE`). A design ξ belongs to the cell i above (clipped to the box's cells when ξ
is in the box; a design beyond the box falls in a cell of the grid continued outside it): that cell's
centre is the one nearest to ξ in the radius-scaled norm max_k |ξ_k - c_k| / h_k, and it holds ξ within
h_k ≤ r_k of it, so the centre's PROM answers ξ. A centre's PROM is built through the PROM cache
(:func:`center_prom`), keyed by the scene and the centre: every user of the atlas on one scene shares it.
How s is set (the PROM within 3 % of the FOM inside a cell) is told in :mod:`~aquarom_fenics.studies.atlas`:
the default holds on SO1's box, not on every scene's (SO3's), so a scene sets its own.
Where ``[reduction] validity_change`` caps a PROM's radius below its cell, the cell is bisected
(:mod:`~aquarom_fenics.reduction.atlas_refine`); without the cap the cells are these. With ``[reduction]
atlas_check`` > 0 a cell is also halved where its PROM's distance differs from its corners' PROMs' by more than
that (:mod:`~aquarom_fenics.reduction.atlas_check`): a scene nobody checked need not trust s.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish_cache import shared_fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.scene_sections import ATLAS_SCALE

RADIUS_SCALE = ATLAS_SCALE
"""The default s of ``[reduction] atlas_scale``: the atlas's cell half-width ÷ the scene's validity radius, at most
(scripts/validate_atlas.py: the PROM against the FOM on SO1's box, largest distance error 1.43 % at s = 0.7 and
2.93 % at the corners of every cell; 3.51 % at a corner at s = 0.8, 3.38 % at s = 0.9, 3.19 % at s = 1; the limit
3 %). It does not hold on every box: on SO3's the PROM errs +22.8 % at a cell's corner at s = 0.7."""


# ---------------------------------------------------------------------- the cover
@dataclass(frozen=True)
class Cover:
    """The grid of cells over the box: per shape its lower bound, cell half-width h [shape unit] and
    number of cells in the box, and the validity radius r the cells were cut from."""

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    half_width: np.ndarray
    counts: np.ndarray
    radius: np.ndarray
    scale: float

    def cells(self, xis: np.ndarray) -> np.ndarray:
        """(N, p) cell indices i_k = ⌊(ξ_k - lower_k) / 2h_k⌋ of designs (N, p); clipped to the box's
        cells for a design in the box (its upper bound belongs to the last cell); 0 where h_k = 0."""
        xis = np.atleast_2d(np.asarray(xis, dtype=float))
        width = 2 * self.half_width
        raw = np.floor(np.divide(xis - self.lower, width, out=np.zeros_like(xis), where=width > 0)).astype(int)
        inside = (xis >= self.lower) & (xis <= self.upper)
        return np.where(inside, np.clip(raw, 0, self.counts - 1), raw)

    def center(self, cell) -> np.ndarray:
        """c_k = lower_k + (2 i_k + 1) h_k."""
        return self.lower + (2 * np.asarray(cell) + 1) * self.half_width

    def scaled_distance(self, xis: np.ndarray, cell) -> np.ndarray:
        """max_k |ξ_k - c_k| / h_k of designs (N, p) from the centre of ``cell`` (1 at the cell's corners;
        a shape with h_k = 0 counts 0)."""
        gap = np.abs(np.atleast_2d(xis) - self.center(cell))
        return np.max(np.divide(gap, self.half_width, out=np.zeros_like(gap), where=self.half_width > 0), axis=1,
                      initial=0.0)

    def box_cells(self) -> int:
        return int(np.prod(self.counts))


def cover(scene: Scene, scale: float | None = None) -> Cover:
    """The atlas's grid over the scene's bounds, cells of half-width at most s × the validity radius, s = ``scale``
    or, by default, the scene's ``[reduction] atlas_scale``."""
    scale = scene.reduction.atlas_scale if scale is None else scale
    if not scene.shapes and not scene.gait:
        raise InputError(f"scene {scene.source} has no [shapes]: there is no design box to cover")
    if not 0 < scale <= 1:
        raise InputError(f"atlas radius scale {scale:g}: must be in (0, 1] (a fraction of the validity radius)")
    lower = np.array([s.lower for s in scene.shapes], dtype=float)
    upper = np.array([s.upper for s in scene.shapes], dtype=float)
    radius = np.array(scene.validity_radii(), dtype=float)
    span = upper - lower
    for name, width, r in zip(scene.shape_names, span, radius):
        if width > 0 and r <= 0:
            raise InputError(f"shape {name}: validity radius {r:g} cannot cover its bounds of width {width:g}; "
                             "give it a radius > 0")
    counts = np.where(span > 0, np.ceil(np.divide(span, 2 * scale * radius, out=np.ones_like(span),
                                                  where=radius > 0) * (1 - 1e-12)), 1).astype(int)
    counts = np.maximum(counts, 1)
    return Cover(tuple(scene.shape_names), lower, upper, span / (2 * counts), counts, radius, float(scale))


ONE_CENTRE = "0"
"""The name of the one centre of a scene without shapes (its ``[gait]`` variables alone: no cells to cut)."""


def center_id(cell) -> str:
    """A centre's name: its cell indices joined by "_" (e.g. "2_0_5"); :data:`ONE_CENTRE` without shapes."""
    return "_".join(str(int(i)) for i in cell) or ONE_CENTRE


def cell_of(name: str, grid: Cover) -> list[int]:
    """The cell indices of a centre's name (:func:`center_id`)."""
    return [int(i) for i in name.split("_")] if grid.names else []


def assign(grid: Cover, designs: list[dict]) -> dict[tuple, list[int]]:
    """The designs of each centre: positions in ``designs`` by cell, cells in the order first met."""
    if not designs:
        return {}
    xis = np.array([[design[name] for name in grid.names] for design in designs])
    groups: dict[tuple, list[int]] = {}
    for k, cell in enumerate(map(tuple, grid.cells(xis).tolist())):
        groups.setdefault(cell, []).append(k)
    return groups


BUILT_HERE = [0]
"""PROMs this process built for the atlas (the first also sets up the FOM the later builds move: ``kept_model``)."""


def center_prom(scene: Scene, center: dict, fish=None):
    """The PROM at ``center`` from the PROM cache (built there if missing) and whether it was built here;
    ``fish`` the scene's (:func:`shared_fish` by default)."""
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.reduction.reductor import build_prom

    fish = fish or shared_fish(scene)
    vector = fish.parameter_vector(center)
    built = []

    def build():
        built.append(True)
        BUILT_HERE[0] += 1
        return build_prom(scene, xi_center=vector, fish=fish, parametric=True)

    return cached_prom(scene, vector, build, parametric=True), bool(built)
