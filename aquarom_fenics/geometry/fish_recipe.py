"""The shipped fish: a tapered body of elliptic cross-section meshed with linear tetrahedra, its
regions as gmsh volume physical groups, written to ``meshes/fish_l<level>.msh``.

The recipe is ``meshes/fish.toml``: profile (NACA-like thickness law), regions (head, muscle pairs)
and levels by element size. gmsh's OpenCASCADE kernel lofts the profile's ellipses and meshes one
quarter of the body (y ≥ 0, z ≥ 0) cut by the region interface planes; the quarter is mirrored in
numpy about y = 0 and z = 0 (as the block is, ``block.py``), so the mesh is exactly symmetric, its
regions conform to it and it has nodes on the body axis y = z = 0 and skin nodes on y = 0 above it.
Its cross-sections are scaled about the axis so that it has the lofted body's volume (``volume_matched``).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.block import mirrored
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh import FishMesh, oriented_positively, signed_cell_volumes
from aquarom_fenics.io.paths import shipped_meshes


def load_recipe(path: Path | None = None) -> dict:
    """The fish recipe (default ``meshes/fish.toml``) as a dict."""
    return tomllib.loads((path or shipped_meshes() / "fish.toml").read_text(encoding="utf-8"))


FISH_RECIPE = load_recipe()
FISH_LEVELS = tuple(sorted(int(level) for level in FISH_RECIPE["levels"]))


def naca_thickness(sigma) -> np.ndarray:
    """NACA 4-digit half-thickness law per unit thickness, t(σ) = 0.2969 √σ - 0.1260 σ - 0.3516 σ²
    + 0.2843 σ³ - 0.1015 σ⁴ (σ ∈ [0, 1], the chord position; maximum 0.1 near σ = 0.30)."""
    sigma = np.asarray(sigma, dtype=float)
    return (0.2969 * np.sqrt(sigma) - 0.1260 * sigma - 0.3516 * sigma**2 + 0.2843 * sigma**3
            - 0.1015 * sigma**4)


_NACA_MAX = float(naca_thickness(np.linspace(0.0, 1.0, 100_001)).max())
"""max_σ t(σ), the normalisation of the thickness law."""


@dataclass(frozen=True)
class FishProfile:
    """The body x ∈ [-L, 0] (head face at x = 0) with elliptic cross-sections of semi-axes b(s) along
    y and c(s) along z, s = -x/L (``meshes/fish.toml`` [profile])."""

    length: float         # L [m]
    half_width: float     # b_max [m]
    half_height: float    # c_max [m]
    chord: tuple[float, float]   # σ at the head face and at the tail face
    width_taper: float
    height_taper: float
    sections: int         # ellipses lofted through

    def thickness(self, s) -> np.ndarray:
        """g(s) = t(σ)/max t, σ = chord[0] + s (chord[1] - chord[0]): 1 at the thickest section."""
        sigma = self.chord[0] + np.asarray(s, dtype=float) * (self.chord[1] - self.chord[0])
        return naca_thickness(sigma) / _NACA_MAX

    def semi_axes(self, s) -> tuple[np.ndarray, np.ndarray]:
        """(b, c) [m] at s: b = b_max (1 - width_taper (1 - g)), c = c_max (1 - height_taper (1 - g))."""
        g = self.thickness(s)
        return (self.half_width * (1.0 - self.width_taper * (1.0 - g)),
                self.half_height * (1.0 - self.height_taper * (1.0 - g)))


@dataclass(frozen=True)
class FishRegions:
    """Head x ≥ -head L, muscles over muscles[0] L < x < muscles[1] L in ``pairs`` equal segments
    (numbered from the tail, as the block's: segment 1 the rearmost, segment ``pairs`` on the head
    side), left y > 0 and right y < 0, and the passive rest "body"."""

    head: float
    muscles: tuple[float, float]
    pairs: int

    def segment_bounds(self) -> np.ndarray:
        """x/L of the muscle segments' ends, back (muscles[0]) to front (muscles[1]): pairs + 1 values;
        segment k spans bounds[k - 1] < x/L < bounds[k]."""
        return np.linspace(self.muscles[0], self.muscles[1], self.pairs + 1)

    def planes(self) -> np.ndarray:
        """Sorted x/L of the interfaces strictly inside the body (-1, 0)."""
        planes = {round(-self.head, 12), *(round(float(x), 12) for x in self.segment_bounds())}
        return np.array(sorted(x for x in planes if -1.0 < x < 0.0))

    def slab_name(self, centre: float) -> str:
        """"head", "muscle_<k>" (k = 1 at the tail … pairs on the head side) or "body" for a slab with
        centre x/L."""
        if centre >= -self.head:
            return "head"
        bounds = self.segment_bounds()
        for k in range(self.pairs):
            if bounds[k] < centre < bounds[k + 1]:
                return f"muscle_{k + 1}"
        return "body"


def _positive(section: str, values: dict, key: str) -> float:
    value = values.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise InputError(f"fish recipe [{section}] {key} = {value!r}; it must be a positive number")
    return float(value)


def fish_profile(recipe: dict = FISH_RECIPE) -> FishProfile:
    """The recipe's [profile], checked: c(s) > b(s) > 0 on the whole body (gmsh's ellipses)."""
    values = recipe["profile"]
    chord = tuple(float(x) for x in values["chord"])
    if not (len(chord) == 2 and 0.0 < chord[0] < chord[1] <= 1.0):
        raise InputError(f"fish recipe [profile] chord = {values['chord']!r}; it must be [head, tail] with "
                         "0 < head < tail <= 1")
    profile = FishProfile(
        length=_positive("profile", values, "length"), half_width=_positive("profile", values, "half_width"),
        half_height=_positive("profile", values, "half_height"), chord=chord,
        width_taper=float(values["width_taper"]), height_taper=float(values["height_taper"]),
        sections=int(values["sections"]))
    b, c = profile.semi_axes(np.linspace(0.0, 1.0, 1001))
    if not (np.all(b > 0.0) and np.all(c > b)) or profile.sections < 3:
        raise InputError("fish recipe [profile]: the half-height must exceed the half-width, both positive, at "
                         "every section, with sections >= 3")
    return profile


def fish_regions(recipe: dict = FISH_RECIPE) -> FishRegions:
    """The recipe's [regions], checked: 0 < head < 1, -1 ≤ rear < front ≤ -head, pairs ≥ 1."""
    values = recipe["regions"]
    regions = FishRegions(head=float(values["head"]), muscles=tuple(float(x) for x in values["muscles"]),
                          pairs=int(values["pairs"]))
    rear, front = regions.muscles
    if not (0.0 < regions.head < 1.0 and -1.0 <= rear < front <= -regions.head and regions.pairs >= 1):
        raise InputError(f"fish recipe [regions]: head = {regions.head}, muscles = {list(regions.muscles)}, "
                         f"pairs = {regions.pairs}; need 0 < head < 1, -1 <= rear < front <= -head, pairs >= 1")
    return regions


def level_size(level: int, recipe: dict = FISH_RECIPE) -> float:
    """gmsh element size [m] of a level; InputError for a level the recipe does not have."""
    levels = {int(key): entry for key, entry in recipe["levels"].items()}
    if isinstance(level, bool) or level not in levels:
        raise InputError(f"fish mesh: level {level!r} does not exist; use one of "
                         f"{', '.join(str(key) for key in sorted(levels))}")
    return float(levels[level]["size"])


def _quarter_fish(profile: FishProfile, regions: FishRegions, size: float, options: dict):
    """gmsh mesh of the quarter y ≥ 0, z ≥ 0 of the body, cut by the interface planes.

    gmsh works in a frame (X, Y, Z) = (z, y, -x): the ellipses lie in the planes Z = s L with their
    major semi-axis c along X (gmsh's ellipses have their major axis along X); the points are mapped
    back exactly, x = -Z, y = Y, z = X. Returns (points, cells, slab name of each cell, the
    quarter's volume [m³] in the CAD model).
    """
    length = profile.length
    cuts = np.concatenate([[0.0], -regions.planes() * length, [length]])      # Z of the slab ends
    reach = 2.0 * max(profile.half_width, profile.half_height)
    with gmsh_model("aquarom_fish_quarter", {**options, "Mesh.MeshSizeMin": size, "Mesh.MeshSizeMax": size}) as gmsh:
        occ = gmsh.model.occ
        wires = []
        for s in np.linspace(0.0, 1.0, profile.sections):
            b, c = profile.semi_axes(s)
            wires.append(occ.addWire([occ.addEllipse(0.0, 0.0, float(s * length), float(c), float(b))]))
        loft = occ.addThruSections(wires, makeSolid=True, makeRuled=False)
        slabs = []
        for front, rear in zip(cuts[:-1], cuts[1:]):
            box = occ.addBox(0.0, 0.0, front, reach, reach, rear - front)
            pieces, _ = occ.intersect(loft, [(3, box)], removeObject=False, removeTool=True)
            slabs += pieces
        occ.remove(loft, recursive=True)
        if len(slabs) > 1:
            occ.fragment(slabs[:1], slabs[1:])
        occ.synchronize()
        cad_volume = sum(occ.getMass(3, tag) for _, tag in gmsh.model.getEntities(3))
        gmsh.model.mesh.generate(3)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        element_nodes, volume_of_cell = [], []
        for _, volume in gmsh.model.getEntities(3):
            _, nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON, volume)
            element_nodes.append(nodes)
            volume_of_cell.append(np.full(len(nodes) // 4, len(element_nodes) - 1))
    points, cells = points_and_cells_from_gmsh(node_tags, coordinates, np.concatenate(element_nodes))
    points = np.column_stack([-points[:, 2], points[:, 1], points[:, 0]])
    volume_of_cell = np.concatenate(volume_of_cell)
    # each volume lies in one slab: named by its cells' mean x (OpenCASCADE's bounding boxes are loose)
    centre_x = points[cells].mean(axis=1)[:, 0]
    names = np.empty(len(cells), dtype=object)
    for volume in np.unique(volume_of_cell):
        mine = volume_of_cell == volume
        names[mine] = regions.slab_name(float(centre_x[mine].mean()) / length)
    return points, cells, names.astype(str), cad_volume


def _snapped(points: np.ndarray, x_planes: np.ndarray, scale: float) -> np.ndarray:
    """y and z within 1e-9 scale of 0 set to 0, x within it of a plane (end faces, interfaces) set
    to the plane: the mirror planes and interfaces then hold their nodes exactly."""
    tolerance = 1e-9 * scale
    snapped = points.copy()
    for axis in (1, 2):
        snapped[np.abs(snapped[:, axis]) <= tolerance, axis] = 0.0
    for x in x_planes:
        snapped[np.abs(snapped[:, 0] - x) <= tolerance, 0] = x
    return snapped


def volume_matched(points: np.ndarray, cells: np.ndarray, volume: float) -> np.ndarray:
    """The points with y and z scaled by λ = √(V / V_h), V the CAD body's volume and V_h the mesh's.

    The skin's triangles are chords of the curved skin, so the mesh lies inside the body and its
    volume falls short by O(h²) (-3.3 % to -0.7 % on levels 1–4); the mass and the muscles' volume
    would carry that error into the distance. Scaling the cross-sections about the axis (x, the
    interfaces, the axis and the symmetry planes stay put) gives every level the body's volume.
    """
    meshed = float(np.abs(signed_cell_volumes(points, cells)).sum())
    scaled = points.copy()
    scaled[:, 1:] *= np.sqrt(volume / meshed)
    return scaled


def as_written(points: np.ndarray) -> np.ndarray:
    """Coordinates rounded to 16 significant digits, as gmsh writes them to an ASCII .msh (%.16g), so
    that a mesh and its file read back are equal (within 1 ulp otherwise)."""
    return np.char.mod("%.16g", points).astype(float)


def fish_atoms(regions: FishRegions) -> tuple[str, ...]:
    """Names of the disjoint regions, in file order: head, left_1 … left_n, right_1 … right_n, body
    (segment 1 at the tail, n on the head side)."""
    pairs = range(1, regions.pairs + 1)
    return ("head", *(f"left_{k}" for k in pairs), *(f"right_{k}" for k in pairs), "body")


def fish_unions(regions: FishRegions) -> dict[str, tuple[str, ...]]:
    """Groups made of several regions: "left_muscle" and "right_muscle", all pairs of a side."""
    pairs = range(1, regions.pairs + 1)
    return {side + "_muscle": tuple(f"{side}_{k}" for k in pairs) for side in ("left", "right")}


def generate_fish(level: int, recipe: dict = FISH_RECIPE) -> FishMesh:
    """The fish of a level: the gmsh quarter ``volume_matched``, mirrored in y, then in z, coordinates ``as_written``,
    with its regions (``fish_atoms`` and ``fish_unions``) as sorted cell indices."""
    size = level_size(level, recipe)
    profile, regions = fish_profile(recipe), fish_regions(recipe)
    points, cells, names, volume = _quarter_fish(profile, regions, size, recipe["gmsh"])
    planes = np.concatenate([[-profile.length], regions.planes() * profile.length, [0.0]])
    points = _snapped(points, planes, profile.length)
    cells = oriented_positively(points, cells)
    points = volume_matched(points, cells, volume)
    n_quarter = len(cells)
    points, cells = mirrored(points, cells, axis=1)
    points, cells = mirrored(points, cells, axis=2)
    points = as_written(points)
    names = np.tile(names, 4)
    left = np.tile(np.arange(2 * n_quarter) < n_quarter, 2)
    by_name = {"head": names == "head", "body": names == "body"}
    for k in range(1, regions.pairs + 1):
        muscle = names == f"muscle_{k}"
        by_name[f"left_{k}"], by_name[f"right_{k}"] = muscle & left, muscle & ~left
    cell_sets = {name: np.flatnonzero(by_name[name]) for name in fish_atoms(regions)}
    for union, parts in fish_unions(regions).items():
        cell_sets[union] = np.sort(np.concatenate([cell_sets[part] for part in parts]))
    return FishMesh(points=points, cells=cells, source=f"fish level {level}", regions=cell_sets)


def shipped_fish_path(level: int) -> Path:
    """Where the shipped mesh of a level lives: ``meshes/fish_l<level>.msh``."""
    return shipped_meshes() / f"fish_l{level}.msh"


_MSH_OPTIONS = {"General.Terminal": 0, "Mesh.MshFileVersion": 4.1, "Mesh.Binary": 0}


def write_msh(mesh: FishMesh, path: Path, atoms, unions: dict) -> None:
    """Write the mesh as a gmsh .msh (format 4.1, ASCII): one discrete volume per region of
    ``atoms`` (they must partition the cells), each its own physical group, and a physical group per
    union of ``unions`` over the volumes it names. Node and element tags are the 1-based indices of
    ``mesh.points`` and ``mesh.cells``, so that the file reads back to the same arrays."""
    covered = np.concatenate([mesh.regions[name] for name in atoms])
    if len(covered) != len(mesh.cells) or len(np.unique(covered)) != len(mesh.cells):
        raise ValueError("the regions written as volumes must partition the cells")
    volume_of = {name: index + 1 for index, name in enumerate(atoms)}
    with gmsh_model("aquarom_fish_write", _MSH_OPTIONS) as gmsh:
        for name, volume in volume_of.items():
            gmsh.model.addDiscreteEntity(3, volume)
        gmsh.model.mesh.addNodes(3, 1, np.arange(1, len(mesh.points) + 1), mesh.points.ravel())
        for name, volume in volume_of.items():
            cells = mesh.regions[name]
            gmsh.model.mesh.addElementsByType(volume, GMSH_TETRAHEDRON, cells + 1, (mesh.cells[cells] + 1).ravel())
        for name, volume in volume_of.items():
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume]), name)
        for name, parts in unions.items():
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume_of[part] for part in parts]), name)
        gmsh.write(str(path))
