"""The fish of a scene: nominal mesh, tags and shape-variation matrix U (SPEC §3–§4).

Rank 0 reads or generates the mesh (the mesh cache is written once) and broadcasts it, so every
rank holds the same small numpy description; dolfinx distributes the cells afterwards.
"""
from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.geometry.block import LEVEL_TARGET_CELLS, block_cache_path, block_mesh, block_region_names
from aquarom_fenics.geometry.body import (AXES, block_lines, body_lines, check_block_sides, check_body_length,
                                          in_swimming_frame)
from aquarom_fenics.geometry.mesh import FishMesh, LagrangeNodes, lagrange_nodes
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.geometry.design_check import check_exact_design
from aquarom_fenics.geometry.shape_registry import use_mesh_points
from aquarom_fenics.geometry.shapes import REGISTERED, design_points, reference_to_cells, shape_gradients, shape_matrix
from aquarom_fenics.geometry.tags import FishBox, FishTags, is_tagged, tag_fish


log = logging.getLogger("aquarom")

_WARNED: set[str] = set()
"""Design-check warnings already logged in this process (an optimiser meets a design many times)."""
CHECKED_DESIGNS = 16
"""Designs whose design-check verdict (None, a warning, or the refusal) a fish keeps (``Fish.design``)."""
_CHECKED_LOCK = threading.Lock()

MASS_QUADRATURE_DEGREE = {1: 2, 2: 6}
"""Per element degree k: the lowest rule degree ≥ 2k (exact for φ_i·φ_j) whose default rule has
only interior points and positive weights; the degree-4 and -5 rules of the tetrahedron have
points on its edges, where the √ profiles of SPEC §4 have an infinite slope on the end faces."""


def quadrature_degrees(degree: int) -> dict[str, int]:
    """Quadrature degree of the volume forms per element degree k (one rule per family).

    "stiffness" (elastic and muscle energies): 2(k - 1), at least 1: the centroid for linear
    elements (∇u constant per cell), the 4-point interior rule for quadratic ones (exact for the
    tangent at rest). "mass" (mass, centre of mass, total mass, drag): MASS_QUADRATURE_DEGREE.
    """
    return {"stiffness": max(1, 2 * (degree - 1)), "mass": MASS_QUADRATURE_DEGREE[degree]}


def integration_points(mesh: FishMesh, degree: int) -> np.ndarray:
    """(n_cells, n_q, 3) nominal positions of every quadrature point of the forms of degree ``degree``."""
    reference = np.vstack([fx.quadrature_rule(q)[0] for q in quadrature_degrees(degree).values()])
    return reference_to_cells(mesh.points, mesh.cells, reference)


@dataclass(frozen=True)
class Fish:
    mesh: FishMesh
    tags: FishTags
    shape_names: tuple[str, ...]
    shape_matrix: np.ndarray     # U, (3 n_nodes, p), node-major, at the displacement nodes
    nodes: LagrangeNodes         # displacement nodes (vertices first, then edge midpoints at degree 2)
    derived: dict = field(default_factory=dict, compare=False, repr=False)
    """Quantities of this fish's nominal mesh that the layers above compute once and keep with it
    (e.g. the FOM's station averages), keyed by what they are and their arguments."""

    @property
    def degree(self) -> int:
        return self.nodes.degree

    def parameter_vector(self, xi: dict[str, float] | np.ndarray | None) -> np.ndarray:
        """ξ as an array ordered like ``shape_names`` (a dict may give a subset; missing = 0)."""
        if xi is None:
            return np.zeros(len(self.shape_names))
        if isinstance(xi, dict):
            unknown = set(xi) - set(self.shape_names)
            if unknown:
                raise InputError(f"design: {', '.join(sorted(unknown))} not among the scene's shape variations "
                                 f"({', '.join(self.shape_names) or 'none'})")
            return np.array([float(xi.get(name, 0.0)) for name in self.shape_names])
        xi = np.asarray(xi, dtype=float)
        if xi.shape != (len(self.shape_names),):
            raise InputError(f"design: expected {len(self.shape_names)} parameters, got {xi.shape}")
        return xi

    def shape_displacement(self, xi) -> np.ndarray:
        """u_ξ = U ξ as an (n_nodes, 3) array [m]."""
        return (self.shape_matrix @ self.parameter_vector(xi)).reshape(-1, 3)

    def shape_gradient(self, xi, points: np.ndarray, direction_gradient=None) -> np.ndarray:
        """∇u_ξ = Σ_k ξ_k ∇U_k, exact, at (n, 3) nominal positions: (n, 3, 3). ``direction_gradient(k)``,
        where given, is ∇U_k at those points already computed (``shape_direction_gradient``)."""
        xi = self.parameter_vector(xi)
        gradient = np.zeros((len(points), 3, 3))
        active = [k for k in range(len(xi)) if xi[k] != 0.0]
        if active:
            if direction_gradient is None:
                names = [self.shape_names[k] for k in active]
                fields = shape_gradients(names, self.tags.box.relative(points), self.tags.box)
            else:
                fields = np.stack([direction_gradient(k) for k in active])
            gradient += np.einsum("k,knij->nij", xi[active], fields)
        return gradient

    def shape_direction_gradient(self, k: int, points: np.ndarray) -> np.ndarray:
        """∇U_k at (n, 3) nominal positions: (n, 3, 3)."""
        return shape_gradients([self.shape_names[k]], self.tags.box.relative(points), self.tags.box)[0]

    def integration_points(self) -> np.ndarray:
        """(n_cells, n_q, 3) nominal positions of every quadrature point the forms use.

        The rules used (degrees 1, 2, 6) are symmetric under permutations of the vertices, so these
        are the FOM's points whatever vertex order dolfinx keeps per cell.
        """
        key = ("integration_points", self.degree)
        if key not in self.derived:       # the nominal mesh's: one set per fish (each design check reads them)
            self.derived[key] = integration_points(self.mesh, self.degree)
            self.derived[key].flags.writeable = False
        return self.derived[key]

    def design(self, xi) -> np.ndarray:
        """Checked nodal positions x_0 + U ξ of the design.

        InputError unless det F_1 = det(I + ∇u_ξ) > 0 at every quadrature point of the forms, with
        ∇u_ξ of the exact shape fields (SPEC §4); a warning (logged once per design) where it falls
        below 0.1.
        """
        xi = self.parameter_vector(xi)
        moved = design_points(self.nodes.points, self.shape_matrix, xi)
        # the last designs' verdicts are kept: an optimiser checks a design, then builds there (a new check)
        key = (xi.tobytes(), tuple(REGISTERED.get(name, (None,))[0] for name in self.shape_names))
        with _CHECKED_LOCK:
            checked = self.derived.setdefault("checked_designs", {})
            verdict = checked.get(key, False)
        if verdict is False:
            try:
                verdict = check_exact_design(self.mesh.points, self.mesh.cells,
                                             lambda points: self.shape_gradient(xi, points), self.integration_points(),
                                             dict(zip(self.shape_names, xi)), regions=self.tags)
            except InputError as refused:
                verdict = refused
            with _CHECKED_LOCK:
                checked[key] = verdict
                while len(checked) > CHECKED_DESIGNS:
                    checked.pop(next(iter(checked)))
        if isinstance(verdict, InputError):
            raise InputError(str(verdict))
        if verdict and verdict not in _WARNED:
            _WARNED.add(verdict)
            log.warning("%s", verdict)
        return moved


def load_mesh(scene: Scene) -> FishMesh:
    """The scene's mesh in the swimming frame (along x, head at the largest x): the block, or the file's
    mesh scaled, translated and turned from its ``[mesh] axis`` and head end (``in_swimming_frame``:
    declared, or inferred from the head region); InputError for a body outside 1 mm–5 m along its
    axis or longer along another axis, a head region that does not reach exactly one end of the body,
    or reaches the other end than the declared one (and for the file checks of ``read_mesh``)."""
    axis, head_end = scene.mesh.axis, scene.mesh.head_end
    if scene.mesh_file is not None and scene.regions.muscle_pairs > 1:
        raise InputError(f"scene {scene.source}: [regions] muscle_pairs = {scene.regions.muscle_pairs} splits the "
                         "built-in block's muscles; a mesh file has its own regions: name them in [[muscles]] tables")
    if scene.mesh_file is not None:
        mesh = read_mesh(scene.mesh_file, scale=scene.mesh.scale, translate=scene.mesh.translate)
    else:
        if axis != "x" or head_end not in ("", "+x", "-x"):
            raise InputError(f"scene {scene.source}: [mesh] axis = \"{axis}\", head_end = \"{head_end}\": the "
                             "built-in block lies along x with its head at +x; axis and head_end describe a mesh file")
        check_body_length(scene.mesh.length, "block", block=True)
        check_block_sides(scene.mesh.length, scene.mesh.width, scene.mesh.height)
        mesh = block_mesh(scene.mesh.level, scene.mesh.length, scene.mesh.width, scene.mesh.height,
                          head_fraction=scene.regions.head_fraction, muscle_range=scene.regions.muscle_range,
                          pairs=scene.regions.muscle_pairs)
        head_end = head_end or "+x"
    check_body_length(float(np.ptp(mesh.points[:, AXES.index(axis)])), mesh.source, axis=axis)
    return in_swimming_frame(mesh, axis, head_end, scene.regions.head)


def tag_scene_fish(scene: Scene, mesh: FishMesh, nodes: LagrangeNodes) -> FishTags:
    """The tags of the scene's mesh: its regions named in ``[regions]`` and ``[[muscles]]``, or the fractions' cells."""
    return tag_fish(mesh, head_fraction=scene.regions.head_fraction, muscle_range=scene.regions.muscle_range,
                    nodes=nodes, head=scene.regions.head, muscles=muscle_regions(scene),
                    muscle_key="[[muscles]] {} region" if scene.muscles else "[regions] muscles",
                    fallback=not scene.muscles,      # regions named in tables must exist
                    require_axis=scene.fluid.stations == "nodes")


def muscle_regions(scene: Scene) -> tuple[str, ...]:
    """The region names of the muscles the scene drives, in their order."""
    return tuple(muscle.region for muscle in scene.actuated_muscles)


def body_summary(scene: Scene, mesh: FishMesh, tags: FishTags) -> list[str]:
    """Length, volume, element count and region volumes of the scene's body (``aquarom mesh``, dry runs)."""
    head, muscles = scene.regions.head, muscle_regions(scene)
    regions = {head: tags.head_cells} | dict(zip(muscles, tags.muscle_cells))
    regions |= {name: cells for name, cells in mesh.regions.items() if name not in regions}
    how = ("tagged" if is_tagged(mesh, (head, *muscles))
           else f"head and muscles chosen by cell centroid: the mesh has no region {head}, {', '.join(muscles)}")
    return body_lines(mesh, regions, how)


def planned_body(scene: Scene) -> tuple[list[str], int]:
    """``body_summary`` and the number of cells for a dry run, which writes nothing: a mesh file or
    a cached block is read and checked like the run would; a block not yet meshed is described
    from its box and its level's advertised number of cells."""
    if scene.mesh_file is None:
        mesh = scene.mesh
        cached = block_cache_path(mesh.level, mesh.length, mesh.width, mesh.height,
                                  head_fraction=scene.regions.head_fraction,
                                  muscle_range=scene.regions.muscle_range, pairs=scene.regions.muscle_pairs).exists()
        if not cached:
            check_block_muscles(scene)
            check_body_length(mesh.length, "block", block=True)
            check_block_sides(mesh.length, mesh.width, mesh.height)
            cells = LEVEL_TARGET_CELLS[mesh.level]
            return block_lines(mesh.length, mesh.width, mesh.height, scene.regions.head_fraction,
                               scene.regions.muscle_range, cells, mesh.level), cells
    body = load_mesh(scene)
    tags = tag_scene_fish(scene, body, lagrange_nodes(body, scene.mesh.degree))
    return body_summary(scene, body, tags), len(body.cells)


def check_block_muscles(scene: Scene) -> None:
    """InputError naming a ``[[muscles]]`` region the block has not (the block's regions are known
    before it is meshed: :func:`block_region_names`)."""
    names = block_region_names(scene.regions.muscle_pairs)
    for number, muscle in enumerate(scene.muscles, start=1):
        if muscle.region not in names:
            raise InputError(f"scene {scene.source}: [[muscles]] {number} region '{muscle.region}' is no region of "
                             f"the block (with [regions] muscle_pairs = {scene.regions.muscle_pairs}: "
                             f"{', '.join(names[1:])})")
    named = [muscle.region for muscle in scene.muscles]
    for side in ("left", "right"):          # a side's muscle is the union of its segments
        segments = [name for name in named if name.startswith(f"{side}_") and name != f"{side}_muscle"]
        if f"{side}_muscle" in named and segments:
            raise InputError(f"block: the regions {side}_muscle and {segments[0]} overlap; head and muscles must "
                             "be disjoint sets of cells (name the segments or their union)")


def load_fish(scene: Scene, comm: MPI.Comm = MPI.COMM_WORLD) -> Fish:
    """Mesh (rank 0, broadcast), tags and U of a scene."""
    mesh_or_error = None
    if comm.rank == 0:
        try:
            mesh_or_error = load_mesh(scene)
        except InputError as error:
            mesh_or_error = error
    mesh = comm.bcast(mesh_or_error, root=0)
    if isinstance(mesh, InputError):
        raise mesh
    nodes = lagrange_nodes(mesh, scene.mesh.degree)
    tags = tag_scene_fish(scene, mesh, nodes)
    names = tuple(scene.shape_names)
    relative = tags.box.relative(nodes.points)
    matrix = shape_matrix(names, relative, tags.box) if names else np.zeros((nodes.points.size, 0))
    return Fish(mesh, tags, names, matrix, nodes)


_MESH_POINTS: dict[str, tuple[np.ndarray, np.ndarray]] = {}
MESH_POINTS_KEPT = 4
"""Meshes whose points :func:`mesh_points` keeps in this process (the last ones asked for)."""


def mesh_points(scene: Scene) -> tuple[str, np.ndarray, np.ndarray]:
    """(key, nodes, points) of the scene's mesh, relative to its box: the displacement nodes of
    ``[mesh] degree`` (n, 3) and the quadrature points of the forms (m, 3), where the FOM reads a
    shape field's value and its gradient; the key names the mesh (its sections, the file's size and
    time). Every MPI rank reads the mesh (cached block or file) itself: a hash is no collective call."""
    data = scene.to_dict()
    stamp = None
    if scene.mesh_file is not None and scene.mesh_file.exists():
        status = scene.mesh_file.stat()
        stamp = [status.st_size, status.st_mtime_ns]
    key = json.dumps([data["mesh"], data["regions"], stamp], sort_keys=True, default=str)
    if key not in _MESH_POINTS:
        mesh = load_mesh(scene)
        box = FishBox.of(mesh.points)
        while len(_MESH_POINTS) >= MESH_POINTS_KEPT:
            del _MESH_POINTS[next(iter(_MESH_POINTS))]
        _MESH_POINTS[key] = (box.relative(lagrange_nodes(mesh, scene.mesh.degree).points),
                             box.relative(integration_points(mesh, scene.mesh.degree).reshape(-1, 3)))
    return (key, *_MESH_POINTS[key])


use_mesh_points(mesh_points)
