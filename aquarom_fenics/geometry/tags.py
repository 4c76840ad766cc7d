"""Regions and special nodes of the fish (SPEC §3): the mesh's tagged regions, nodes found from coordinates.

Nodes on the body axis (the spine) are needed only by the nodal thrust model (``[fluid] stations =
"nodes"``); with stations (the default) a body meshed without nodes on its axis is accepted, and its
spine and dorsal nodes are empty.

Every comparison uses a tolerance relative to the mesh size (`mesh_tolerance`), never exact
float equality. Positions are taken relative to the bounding box (`FishBox.relative`), so that
the reference fish has x ∈ [-L, 0], y ∈ [-W/2, W/2], z ∈ [-H/2, H/2] whatever its placement.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.mesh import (TETRAHEDRON_EDGES, FishMesh, LagrangeNodes, check_region_fractions,
                                           lagrange_nodes, mean_edge_length)

log = logging.getLogger("aquarom")

RELATIVE_TOLERANCE = 1e-4
"""Tolerance as a fraction of the mean edge length: far below any node spacing, far above the
rounding of coordinates written in single precision by other meshers."""

_OUTWARD_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
"""Local vertices of the four faces of a positively oriented tetrahedron, each ordered so that
its right-hand normal points out of the tetrahedron."""


@dataclass(frozen=True)
class FishBox:
    """Bounding box of the fish: head face at x_max, tail face at x_min, axis at the y/z centre."""

    x_head: float
    x_tail: float
    y_axis: float
    z_axis: float
    length: float
    width: float
    height: float

    @classmethod
    def of(cls, points) -> "FishBox":
        points = np.asarray(points, dtype=float)
        lower, upper = points.min(axis=0), points.max(axis=0)
        return cls(
            x_head=float(upper[0]),
            x_tail=float(lower[0]),
            y_axis=float((lower[1] + upper[1]) / 2),
            z_axis=float((lower[2] + upper[2]) / 2),
            length=float(upper[0] - lower[0]),
            width=float(upper[1] - lower[1]),
            height=float(upper[2] - lower[2]),
        )

    def relative(self, points) -> np.ndarray:
        """(n, 3) positions (x - x_head, y - y_axis, z - z_axis) in metres."""
        origin = np.array([self.x_head, self.y_axis, self.z_axis])
        return np.asarray(points, dtype=float).reshape(-1, 3) - origin


@dataclass(frozen=True)
class FishTags:
    """Regions and special nodes of a fish mesh; cell arrays index `FishMesh.cells`, node arrays
    the displacement nodes (`LagrangeNodes.points`: the vertices, and at degree 2 the edge
    midpoints as well, so that spine segments halve)."""

    box: FishBox
    tolerance: float  # metres
    head_cells: np.ndarray  # cell indices of the tagged head
    head_nodes: np.ndarray  # nodes of head cells
    left_muscle_cells: np.ndarray  # tagged left muscle (y > 0)
    right_muscle_cells: np.ndarray  # tagged right muscle (y < 0)
    skin_facets: np.ndarray  # (n_facets, 3) exterior boundary triangles, normals pointing out
    skin_nodes: np.ndarray
    spine_nodes: np.ndarray  # nodes with y_rel = z_rel = 0, sorted tail -> head; empty without axis nodes
    spine_segments: np.ndarray  # (n_spine - 1, 2): [rear, front] consecutive spine nodes
    tail_node: int | None  # spine node at x_rel = -L (None without axis nodes)
    head_spine_node: int | None  # spine node at x_rel = 0 (None without axis nodes)
    dorsal_nodes: np.ndarray  # (n_segments,) skin node on y_rel = 0, z_rel > 0, x nearest rear
    muscle_cells: tuple = ()  # cells of each driven muscle, in the order of the scene's muscles

    @property
    def has_spine(self) -> bool:
        """Whether the mesh has nodes on its axis from tail face to head face (the nodal model's spine)."""
        return self.spine_nodes.size >= 2


def mesh_tolerance(points, cells) -> float:
    """Length tolerance (m) for coordinate comparisons: RELATIVE_TOLERANCE × mean edge length."""
    return RELATIVE_TOLERANCE * mean_edge_length(points, cells)


def cell_centroids(points, cells) -> np.ndarray:
    """(n_cells, 3) centroids: the mean of the four vertices."""
    return np.asarray(points, dtype=float)[np.asarray(cells)].mean(axis=1)


def head_cell_mask(centroids, box: FishBox, tolerance: float, head_fraction=0.35) -> np.ndarray:
    """True for cells whose centroid has x_rel ≥ -head_fraction L (within the tolerance)."""
    x_rel = box.relative(centroids)[:, 0]
    return x_rel >= -head_fraction * box.length - tolerance


def muscle_cell_masks(
    centroids, box: FishBox, tolerance: float, muscle_range=(-0.95, -0.35)
) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) masks: muscle_range[0] L < x_rel < muscle_range[1] L, and y_rel > 0 (left)
    or y_rel < 0 (right). Centroids within the tolerance of a bound are outside the muscle."""
    relative = box.relative(centroids)
    rear, front = (bound * box.length for bound in muscle_range)
    along = (relative[:, 0] > rear + tolerance) & (relative[:, 0] < front - tolerance)
    return along & (relative[:, 1] > tolerance), along & (relative[:, 1] < -tolerance)


def skin_facets(cells) -> np.ndarray:
    """(n_facets, 3) faces that belong to exactly one tetrahedron, in the vertex order of that
    tetrahedron's outward face (right-hand normal pointing out for positively oriented cells)."""
    faces = np.asarray(cells, dtype=np.int64)[:, _OUTWARD_FACES].reshape(-1, 3)
    _, first, counts = np.unique(
        np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True
    )
    return faces[np.sort(first[counts == 1])]


def _spine(mesh: FishMesh, nodes: LagrangeNodes, box: FishBox, tolerance: float) -> np.ndarray:
    """Nodes on the body axis y_rel = z_rel = 0 sorted tail → head, checked to span [-L, 0]."""
    relative = box.relative(nodes.points)
    on_axis = np.flatnonzero(
        (np.abs(relative[:, 1]) <= tolerance) & (np.abs(relative[:, 2]) <= tolerance)
    )
    spine_nodes = on_axis[np.argsort(relative[on_axis, 0], kind="stable")]
    remedy = "mesh the body cut by both planes y = 0 and z = 0, so that its axis is a line of mesh edges"
    if len(spine_nodes) < 2:
        raise InputError(
            f"mesh {mesh.source}: no nodes on the body axis y = 0, z = 0 (within {tolerance:.3g}"
            f" m); {remedy}"
        )
    ends = (("tail", spine_nodes[0], -box.length), ("head", spine_nodes[-1], 0.0))
    for end, node, x_rel in ends:
        if abs(relative[node, 0] - x_rel) > tolerance:
            raise InputError(
                f"mesh {mesh.source}: no node on the body axis y = 0, z = 0 at the {end} face "
                f"x = {box.x_head + x_rel:.6g} m (within {tolerance:.3g} m); {remedy}"
            )
    _check_axis_edges(mesh, spine_nodes[spine_nodes < nodes.n_vertices], remedy)
    return spine_nodes


def _check_axis_edges(mesh: FishMesh, axis_vertices: np.ndarray, remedy: str) -> None:
    """InputError unless consecutive vertices on the body axis (sorted along x) are joined by edges of the mesh.

    On a body cut by the planes y = 0 and z = 0 the axis is a line of mesh edges; on a body cut by
    one plane only, a few vertices fall on the axis by chance with gaps between them that no edge
    spans (the spine would then be a few long segments).
    """
    edges = np.sort(np.asarray(mesh.cells, dtype=np.int64)[:, TETRAHEDRON_EDGES].reshape(-1, 2), axis=1)
    keys = set((edges[:, 0] * len(mesh.points) + edges[:, 1]).tolist())
    pairs = np.sort(np.column_stack([axis_vertices[:-1], axis_vertices[1:]]), axis=1)
    joined = np.array([a * len(mesh.points) + b in keys for a, b in pairs], dtype=bool)
    if not joined.all():
        gaps = np.diff(mesh.points[axis_vertices, 0])
        raise InputError(
            f"mesh {mesh.source}: the body axis y = 0, z = 0 is not a line of mesh edges ({len(axis_vertices)} "
            f"vertices on it, {int((~joined).sum())} of the {len(pairs)} gaps between them spanned by no edge, the "
            f"longest {gaps.max():.3g} m); {remedy}"
        )


def _dorsal_nodes(
    mesh: FishMesh, nodes: LagrangeNodes, box: FishBox, tolerance: float, skin_nodes, rear_nodes
) -> np.ndarray:
    """Per rear node: the skin node on y_rel = 0 with z_rel > 0 whose x is nearest (ties within
    the tolerance: the largest z)."""
    relative = box.relative(nodes.points)
    candidates = skin_nodes[
        (np.abs(relative[skin_nodes, 1]) <= tolerance) & (relative[skin_nodes, 2] > tolerance)
    ]
    if len(candidates) == 0:
        raise InputError(
            f"mesh {mesh.source}: no skin nodes on the plane y = 0 above the axis; mesh the box "
            "cut by the planes y = 0 and z = 0"
        )
    distance = np.abs(relative[candidates, 0][None, :] - relative[rear_nodes, 0][:, None])
    nearest = distance <= distance.min(axis=1, keepdims=True) + tolerance
    height = np.where(nearest, relative[candidates, 2][None, :], -np.inf)
    return candidates[np.argmax(height, axis=1)]


def _nonempty(mesh: FishMesh, name: str, cells: np.ndarray, rule: str) -> np.ndarray:
    if len(cells) == 0:
        raise InputError(
            f"mesh {mesh.source}: the {name} is empty (no cell centroid with {rule}); refine "
            "the mesh or widen the region"
        )
    return cells


TAGGED_REGIONS = ("head", "left_muscle", "right_muscle")
"""The regions a tagged mesh names by default (``FishMesh.regions``, scene keys ``[regions] head`` and
``muscles``): cell sets the mesh conforms to."""

_CENTROID_WARNED: set[str] = set()
"""Meshes already warned about (a study loads one mesh many times)."""


def is_tagged(mesh: FishMesh, names=TAGGED_REGIONS) -> bool:
    """True when the mesh has a region of any of the ``names`` (head, left, right): it must then have
    all three; False sends a mesh to the centroid rule."""
    return any(len(mesh.regions.get(name, ())) for name in names)


def tagged_regions(mesh: FishMesh, names=TAGGED_REGIONS, muscle_key="[regions] muscles") -> tuple[np.ndarray, ...]:
    """(head, muscle 1, muscle 2, …) cells of a tagged mesh: its regions ``names`` = (head, muscles…),
    checked; InputError naming the missing region (``muscle_key``: the scene key that names the
    muscles, "{}" replaced by the muscle's number) and the regions the mesh has, or two that overlap."""
    names = tuple(names)
    keys = ["[regions] head"] + [muscle_key.format(number) for number in range(1, len(names))]
    for name, key in zip(names, keys):
        if len(mesh.regions.get(name, ())) == 0:
            present = ", ".join(f"'{region}'" for region in mesh.regions if len(mesh.regions[region])) or "none"
            raise InputError(f"mesh {mesh.source}: no region '{name}' ({key}); its regions are {present}")
    regions = [np.unique(np.asarray(mesh.regions[name], dtype=np.int64)) for name in names]
    for name, cells in zip(names, regions):
        if cells.min() < 0 or cells.max() >= len(mesh.cells):
            raise InputError(f"mesh {mesh.source}: region {name} names cells outside the mesh")
    for i, j in ((i, j) for j in range(len(names)) for i in range(j)):
        if names[i] == names[j]:
            raise InputError(f"mesh {mesh.source}: {keys[i]} and {keys[j]} both name region '{names[i]}'; head "
                             "and muscles must be different regions (disjoint sets of cells)")
        if len(np.intersect1d(regions[i], regions[j])):
            raise InputError(f"mesh {mesh.source}: the regions {names[i]} and {names[j]} overlap; head and muscles "
                             "must be disjoint sets of cells")
    return tuple(regions)


def muscle_sides(box: FishBox, centroids, muscles) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) cells of the muscles (pictures and messages): a pair is (left, right) in its order;
    of any other number, each muscle whose cells' mean y_rel is ≥ 0 is on the left, the others on the right."""
    if len(muscles) == 2:
        return muscles[0], muscles[1]
    left = [cells for cells in muscles if box.relative(centroids[cells])[:, 1].mean() >= 0.0]
    right = [cells for cells in muscles if box.relative(centroids[cells])[:, 1].mean() < 0.0]
    joined = (np.unique(np.concatenate(side)) if side else np.zeros(0, dtype=np.int64) for side in (left, right))
    return tuple(joined)


def centroid_regions(mesh: FishMesh, box: FishBox, tolerance: float, head_fraction, muscle_range,
                     names=TAGGED_REGIONS):
    """(head, left muscle, right muscle) cells chosen by cell centroid: the fallback for a mesh
    without the regions ``names``, warned about once per mesh (a mesh that does not conform to the
    regions has a zig-zag interface that moves with the mesh, SPEC §3)."""
    if mesh.source not in _CENTROID_WARNED:
        _CENTROID_WARNED.add(mesh.source)
        present = (f"its regions are {', '.join(repr(name) for name in mesh.regions)}, none named in [regions] "
                   "head or muscles" if mesh.regions else "it has no regions")
        log.warning("mesh %s has no tagged regions (%s): head and muscles chosen by cell centroid (%s); their "
                    "interfaces then zig-zag through the cells and move with the mesh, so tag the regions "
                    "(gmsh volume physical groups, Abaqus element sets) for results that converge",
                    mesh.source, ", ".join(names), present)
    centroids = cell_centroids(mesh.points, mesh.cells)
    head = _nonempty(mesh, "head", np.flatnonzero(head_cell_mask(centroids, box, tolerance, head_fraction)),
                     f"x >= {-head_fraction:g} L")
    left_mask, right_mask = muscle_cell_masks(centroids, box, tolerance, muscle_range)
    rule = f"{muscle_range[0]:g} L < x < {muscle_range[1]:g} L and y"
    left = _nonempty(mesh, "left muscle", np.flatnonzero(left_mask), rule + " > 0")
    right = _nonempty(mesh, "right muscle", np.flatnonzero(right_mask), rule + " < 0")
    return head, left, right


def _optional_spine(mesh: FishMesh, nodes: LagrangeNodes, box: FishBox, tolerance: float, skin_nodes,
                    require_axis: bool) -> tuple[np.ndarray, np.ndarray]:
    """(spine nodes, dorsal nodes): the spine (``_spine``) and one dorsal node per segment. With
    ``require_axis`` (the nodal thrust model) a mesh without them is refused; otherwise both are
    empty for such a mesh (the stations need neither)."""
    try:
        spine_nodes = _spine(mesh, nodes, box, tolerance)
        dorsal = _dorsal_nodes(mesh, nodes, box, tolerance, skin_nodes, spine_nodes[:-1])
    except InputError as error:
        if require_axis:
            raise InputError(f"{error} (needed by [fluid] stations = \"nodes\", the nodal thrust model; "
                             "the default stations need no nodes on the axis)") from None
        log.debug("mesh %s: no spine (%s); the stations need none", mesh.source, error)
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return spine_nodes, dorsal


def tag_fish(mesh: FishMesh, head_fraction=0.35, muscle_range=(-0.95, -0.35),
             nodes: LagrangeNodes | None = None, head: str = TAGGED_REGIONS[0],
             muscles=TAGGED_REGIONS[1:], muscle_key="[regions] muscles", fallback: bool = True,
             require_axis: bool = False) -> FishTags:
    """All tags of SPEC §3 for a fish mesh (head, muscles, skin, and where the mesh has nodes on its
    axis the spine, tail, head spine and dorsal nodes).

    Head and muscles are the mesh's tagged regions (``FishMesh.regions``) named ``head`` and
    ``muscles`` (a pair (left, right), or any number named by ``[[muscles]]``, ``muscle_key``): a
    mesh with one of them must have all. A mesh with none of them falls back, for a pair and with
    ``fallback``, to cell centroids and the fractions, with a warning. Node tags refer to ``nodes``
    (default: the vertices, i.e. linear elements). ``require_axis``: refuse a mesh without a spine
    (``[fluid] stations = "nodes"``); otherwise its spine and dorsal nodes are empty.
    """
    check_region_fractions(mesh.source, head_fraction, muscle_range)
    nodes = nodes or lagrange_nodes(mesh, 1)
    box = FishBox.of(mesh.points)
    tolerance = mesh_tolerance(mesh.points, mesh.cells)
    facets = skin_facets(mesh.cells)
    skin_nodes = nodes.facet_nodes(facets)
    spine_nodes, dorsal_nodes = _optional_spine(mesh, nodes, box, tolerance, skin_nodes, require_axis)
    spine_segments = np.column_stack([spine_nodes[:-1], spine_nodes[1:]])
    names = (head, *muscles)
    if is_tagged(mesh, names) or len(muscles) != 2 or not fallback:
        head_cells, *muscle_cells = tagged_regions(mesh, names, muscle_key)
    else:
        head_cells, *muscle_cells = centroid_regions(mesh, box, tolerance, head_fraction, muscle_range, names)
    left_muscle_cells, right_muscle_cells = muscle_sides(box, cell_centroids(mesh.points, mesh.cells), muscle_cells)
    return FishTags(
        box=box,
        tolerance=tolerance,
        head_cells=head_cells,
        head_nodes=np.unique(nodes.cell_nodes[head_cells]),
        left_muscle_cells=left_muscle_cells,
        right_muscle_cells=right_muscle_cells,
        skin_facets=facets,
        skin_nodes=skin_nodes,
        spine_nodes=spine_nodes,
        spine_segments=spine_segments,
        tail_node=int(spine_nodes[0]) if spine_nodes.size else None,
        head_spine_node=int(spine_nodes[-1]) if spine_nodes.size else None,
        dorsal_nodes=dorsal_nodes,
        muscle_cells=tuple(muscle_cells),
    )
