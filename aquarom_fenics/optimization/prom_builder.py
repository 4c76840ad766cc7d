"""PROMs centred on designs for the optimisers: built or taken from the cache, checked for a stable gait; with
``[optimizer] atlas`` the PROMs of the atlas's cell centres (:mod:`~aquarom_fenics.reduction.atlas_cover`)."""
from __future__ import annotations

import logging
import time

import numpy as np

from aquarom_fenics.dynamics.batched import reduced_distances
from aquarom_fenics.dynamics.reduced_dynamics import reduced_stability
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import DesignSpace, Evaluation, amplitude_of, cost_value, evaluate, scene_at
from aquarom_fenics.reduction.atlas_cover import cover
from aquarom_fenics.reduction.atlas_refine import Refiner, holds, leaf_record
from aquarom_fenics.reduction.cache import cached_prom
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.verification.local_stability import prom_tail_stability


STABILITY_STROKES = 2
"""Strokes the horizon must hold before the gait's stability is judged."""

BASIS_REUSE_FRACTION = 0.5
"""A PROM centred within this fraction of the validity radius of the last PROM whose basis was built
(every |ξ - ξ_b|_k ≤ f r_k) reuses that basis; its tensors are projected at its own centre."""

log = logging.getLogger("aquarom")


def judges_stability(scene: Scene) -> bool:
    """Whether the horizon holds the strokes a stability verdict needs (a start-up from rest is no
    periodic gait)."""
    return scene.solver.duration * scene.actuation.frequency >= STABILITY_STROKES


def screens_tail(scene: Scene) -> bool:
    """Whether the builds run the tail screen: judged horizon, ``[optimizer] tail_screen``, thrust on."""
    return judges_stability(scene) and scene.optimizer.tail_screen and scene.fluid.thrust


def stability_plan(scene: Scene) -> str:
    """What :meth:`PromBuilder._refuse_unstable` judges at every build, and what it skips, one line."""
    if not judges_stability(scene):
        return f"not judged (horizon below {STABILITY_STROKES} strokes)"
    floquet = "the PROM's Floquet test at every PROM build"
    if not scene.optimizer.tail_screen:
        return f"{floquet}; tail screen skipped ([optimizer] tail_screen = false)"
    if not scene.fluid.thrust:
        return f"{floquet}; tail screen skipped (thrust off: nothing drives the tail)"
    return (f"{floquet}, then the tail screen (the FOM's tail region within {scene.optimizer.tail_region_radius:g} m "
            f"linearised at the PROM's last-stroke states, growth limit {scene.optimizer.tail_growth_limit:g} 1/s)")


class PromBuilder:
    """Builds PROMs centred on designs, counting builds, cache reuses, basis reuses and their time.

    ``basis_center`` is the centre of the last PROM whose basis was built (the source of reused
    bases); a resumed run sets it from its checkpoint, and the PROM there comes from the cache.
    """

    def __init__(self, scene: Scene, fish: Fish, space: DesignSpace):
        self.scene, self.fish, self.space = scene, fish, space
        self.builds = 0
        self.reused = 0
        self.basis_reuses = 0
        self.last_size = 0
        self.build_time = 0.0
        self.solve_time = 0.0
        self.screen_time = 0.0               # the tail screens' time [s]
        self.radius = np.array(scene.validity_radii())
        self.basis_center: np.ndarray | None = None
        self.records: list[dict] = []        # per build: design, cache hit, basis source, time
        self._basis_source: ReducedModel | None = None
        self._own_basis: list[ReducedModel] = []     # the PROMs built here on a basis built at their centre
        self._atlas: Refiner | None = None   # [optimizer] atlas: the refined cells met, their PROMs' radii

    def build(self, z: np.ndarray, own_basis: bool = False) -> ReducedModel:
        """The PROM at z: on the basis of the last PROM whose basis was built if that PROM's centre is within
        ``BASIS_REUSE_FRACTION`` of the validity radius, else (or with ``own_basis``) on a basis built at z,
        which the next PROMs then reuse."""
        if self.scene.optimizer.atlas:
            prom = self._atlas_build(z)
            if prom is not None:
                return prom
        started = time.perf_counter()
        center = z[: self.space.n_shapes]
        source = None if own_basis else self._basis_source_near(center)
        built = []

        def build_here():
            built.append(build_prom(self.scene, xi_center=center, fish=self.fish, basis_from=source))
            return built[0]

        prom = cached_prom(self.scene, center, build_here,
                           basis_center=None if source is None else source.xi_center)
        if source is None:
            self._basis_source, self.basis_center = prom, center.copy()
            self._own_basis.append(prom)
        elapsed = time.perf_counter() - started
        self.build_time += elapsed
        self.builds += 1
        self.reused += not built
        self.basis_reuses += source is not None
        self.last_size = prom.size
        record = {"build": self.builds, "design": self.space.as_dict(z), "from_cache": not built,
                  "basis_from": None if source is None else dict(zip(self.space.names, source.xi_center.tolist())),
                  "radius_fraction": None if source is None else self._radius_fraction(center, source.xi_center),
                  "time": elapsed}
        self.records.append(record)
        log.info("PROM %d at %s: %s; basis %s; %.2f s", self.builds, record["design"],
                 "from the cache" if record["from_cache"] else "built",
                 "built here" if source is None else f"reused from {record['basis_from']} (largest |Δξ_k| / r_k "
                 f"{record['radius_fraction']:.2f}: every tensor projected here)", elapsed)
        self._refuse_unstable(prom, z)
        return prom

    def _atlas_build(self, z: np.ndarray) -> ReducedModel | None:
        """``[optimizer] atlas``: the PROM at the centre c of the atlas leaf holding the shapes of z
        (``atlas_refine.Refiner``: the regular cell, bisected where a capped radius needs it; every PROM through
        the PROM cache; |ξ - c|_k ≤ h_k ≤ s R_k), checked for a stable gait at z. None when the leaf is at the
        depth limit and its PROM's radius R does not hold z: the caller builds at z."""
        started = time.perf_counter()
        refiner = self._refiner()
        known = set(refiner.met)
        leaf = refiner.leaf(z[: self.space.n_shapes])
        if not leaf.answers(refiner.grid, z[: self.space.n_shapes]):
            log.warning("atlas cell %s is at the depth limit (%d bisections) and its PROM's radius %s does not hold "
                        "%s: a PROM is built at the design", leaf.node.id, refiner.max_depth,
                        np.round(leaf.radius, 5).tolist(), self.space.as_dict(z))
            return None
        prom = refiner.prom(leaf.node)
        built_here = sum(met["built"] for node, met in refiner.met.items() if node not in known)
        elapsed = time.perf_counter() - started
        self.build_time += elapsed
        self.builds += 1
        self.reused += not built_here
        self.last_size = prom.size
        record = {"build": self.builds, "design": self.space.as_dict(z), "from_cache": not built_here,
                  "basis_from": None, "radius_fraction": None, "atlas_cell": leaf.node.id, "time": elapsed}
        if leaf.path or leaf.at_limit:
            record.update(atlas_refined=leaf_record(refiner.grid, leaf), atlas_builds=int(built_here))
        self.records.append(record)
        log.info("PROM %d for %s: the atlas centre %s's, %s%s; %.2f s", self.builds, record["design"], leaf.node.id,
                 f"{built_here} built on the way" if built_here else "from the cache",
                 " (at the depth limit)" if leaf.at_limit else "", elapsed)
        self._refuse_unstable(prom, z)
        return prom

    def _refiner(self) -> Refiner:
        if self._atlas is None:
            self._atlas = Refiner(self.scene, cover(self.scene), self.fish, distances=reduced_distances)
        return self._atlas

    def _radius_fraction(self, xi: np.ndarray, other: np.ndarray) -> float:
        """max_k |ξ_k - ξ'_k| / r_k, r the scene's validity radius (a parameter with r_k = 0, fixed by
        equal bounds, counts 0 where ξ_k = ξ'_k, else infinity)."""
        gap = np.abs(xi - other)
        ratio = np.divide(gap, self.radius, out=np.where(gap > 0, np.inf, 0.0), where=self.radius > 0)
        return float(np.max(ratio, initial=0.0))

    def _basis_source_near(self, center: np.ndarray) -> ReducedModel | None:
        """The PROM whose basis a PROM at ``center`` reuses, or None (its basis is built)."""
        if self.basis_center is None or not center.size:
            return None
        if self._radius_fraction(center, self.basis_center) > BASIS_REUSE_FRACTION:
            return None
        if self._basis_source is None:      # resumed: the PROM at the basis centre is in the cache
            source_center = self.basis_center.copy()
            self._basis_source = cached_prom(self.scene, source_center,
                                             lambda: build_prom(self.scene, xi_center=source_center, fish=self.fish))
        return self._basis_source

    @staticmethod
    def validity_radius(prom: ReducedModel) -> np.ndarray:
        """r_k of ``prom``: the scene's validity radius, capped where ``[reduction] validity_change`` caps it."""
        return np.asarray(prom.validity_radius, dtype=float)

    def trusts(self, prom: ReducedModel | None, z: np.ndarray) -> bool:
        """Whether z is inside the validity radius of ``prom`` (every |ξ - ξ_c|_k ≤ r_k); with
        ``[optimizer] atlas``, whether z is in the atlas leaf whose centre is ``prom``'s (and, at the depth
        limit, within its radius); a PROM built at a design beyond such a leaf's radius is judged by its radius."""
        if prom is not None and self.scene.optimizer.atlas:
            refiner = self._refiner()
            leaf = refiner.leaf(np.asarray(prom.xi_center, dtype=float))
            if np.allclose(leaf.node.center(refiner.grid), prom.xi_center, rtol=0, atol=1e-12):
                xi = z[: self.space.n_shapes]
                return holds(refiner.grid, leaf.node, xi) and leaf.answers(refiner.grid, xi)
        return prom is not None and bool(np.all(np.abs(z[: self.space.n_shapes] - prom.xi_center)
                                                <= prom.validity_radius))

    def on_own_basis(self, prom: ReducedModel) -> bool:
        """Whether ``prom``'s basis was built at its own centre (the atlas's PROMs all are), not reused from
        another PROM's: a reused basis misses the shape change between the two centres, so the PROM's
        slopes carry a projection error that its own basis does not."""
        return bool(self.scene.optimizer.atlas) or any(prom is own for own in self._own_basis)

    @staticmethod
    def shares_basis(prom: ReducedModel, other: ReducedModel) -> bool:
        """Whether two PROMs project on the same basis vectors V (a reused basis, or one PROM)."""
        return prom is other or (prom.basis.shape == other.basis.shape and np.array_equal(prom.basis, other.basis))

    def refuse_infeasible(self, prom: ReducedModel, z: np.ndarray) -> None:
        """The checks of a build at z without building: InputError if the design check refuses z
        or the PROM's gait at z is unstable."""
        try:
            self.fish.design(z[: self.space.n_shapes])
        except InputError as refused:
            raise InputError(f"design {self.space.as_dict(z)} is infeasible: {refused}") from None
        self._refuse_unstable(prom, z)

    def _refuse_unstable(self, prom: ReducedModel, z: np.ndarray) -> None:
        """A design whose PROM gait is unstable (Floquet multiplier |μ| > 1.01 over the last stroke,
        ``reduced_stability``) is refused like one the mesh check refuses: the optimisers step back.
        Judged only on horizons of two strokes or more (a start-up from rest is no periodic gait).
        With ``[optimizer] tail_screen`` and the thrust on, so is a design whose tail region the
        thrust destabilises (``prom_tail_stability``)."""
        if not judges_stability(self.scene):
            return
        amplitude, scene = amplitude_of(self.space, z), scene_at(self.scene, self.space, z)
        xi = z[: self.space.n_shapes]
        stable, reason = reduced_stability(prom, scene, xi, amplitude)
        if stable and screens_tail(self.scene):
            started = time.perf_counter()
            stable, reason = prom_tail_stability(prom, scene, self.fish, xi, amplitude)
            elapsed = time.perf_counter() - started
            self.screen_time += elapsed
            log.info("tail screen at %s: %s; %.1f s", self.space.as_dict(z), reason, elapsed)
        if not stable:
            raise InputError(f"design {self.space.as_dict(z)} is infeasible: its PROM is unstable ({reason})")

    def evaluate(self, prom, z, weights) -> Evaluation:
        """L, its gradient and d at z (:func:`evaluate`)."""
        return self._solved(evaluate, prom, z, weights)

    def cost(self, prom, z, weights) -> float:
        """L at z without its gradient (:func:`cost_value`)."""
        return self._solved(cost_value, prom, z, weights)

    def _solved(self, solve, prom, z, weights):
        """solve(prom, scene, space, z, weights), its time added to ``solve_time``."""
        started = time.perf_counter()
        try:
            return solve(prom, self.scene, self.space, z, weights)
        finally:
            self.solve_time += time.perf_counter() - started

    def meshes(self, z: np.ndarray) -> bool:
        """The design check of SPEC §4 (det F_1 > 0 everywhere) at the shapes of z."""
        try:
            self.fish.design(z[: self.space.n_shapes])
            return True
        except InputError:
            return False
