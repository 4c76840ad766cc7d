"""Checks of a body mesh read from a file (``mesh_files.read_mesh``) before it becomes the toolkit's mesh:
only tetrahedra, sane coordinates, one solid, no inverted or tangled cells. Each refuses with one line
(InputError) that says what is wrong, where (a node's coordinates in the file, a tetrahedron's number in
the file: its position among the file's tetrahedra, from 1) and what to do. All are vectorised numpy.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.body import AXES, check_body_length
from aquarom_fenics.geometry.mesh import cell_quality, signed_cell_volumes

FAR_NODE = 10.0
"""A node lies far from the rest of the body when it is farther outside the box of the others (the box
of the nodes without the 1 % outermost on each side, along each axis) than FAR_NODE times that box's
size: no tail or fin reaches so far beyond a body; a wrong coordinate, or one in other units, does."""

MAX_OFFSET = 1e5
"""Largest distance of a node from the origin, in units of the body's size (its largest extent): at
10⁵ sizes the coordinates' rounding (2.2e-16 of their magnitude) is 2e-11 of the body."""

_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
"""Local vertices of the four faces of a tetrahedron, each ordered so that its right-hand normal points
out when the tetrahedron's signed volume is positive (``tags._OUTWARD_FACES``)."""


# ---------------------------------------------------------------------------------------------
# Cells other than tetrahedra


def other_volume_cells(path, tetrahedra: int, others: dict[str, int]) -> InputError | None:
    """The one line for a file that holds volume cells other than first-order tetrahedra (``others``:
    {kind: count}) beside its ``tetrahedra``, or None. They are refused, not dropped: without them the
    body has holes or is missing parts, and would swim as another body."""
    others = {kind: count for kind, count in others.items() if count}
    if not others:
        return None
    listed = ", ".join(f"{count} {kind} cells" for kind, count in others.items())
    return InputError(f"mesh file {path}: besides its {tetrahedra} tetrahedra it holds {listed}; only first-order "
                      "tetrahedra are read, and dropping the others would leave holes in the body: mesh the whole "
                      "volume with 4-node tetrahedra (gmsh: no recombination, Mesh.ElementOrder = 1)")


# ---------------------------------------------------------------------------------------------
# Coordinates


def _node_in_file(raw: np.ndarray, cells: np.ndarray, node: int) -> str:
    """"the node at (x, y, z) (of tetrahedron number t of the file)", in the file's coordinates."""
    cell = int(np.flatnonzero((cells == node).any(axis=1))[0]) + 1
    x, y, z = raw[node]
    return f"the node at ({x:.6g}, {y:.6g}, {z:.6g}) (of tetrahedron number {cell} of the file)"


def _far_nodes(raw: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(distance of each node outside the box of the others, that box's size, FAR_NODE × size)."""
    trim = max(1, len(raw) // 100)
    ordered = np.sort(raw, axis=0)
    low, high = ordered[min(trim, len(raw) - 1)], ordered[max(len(raw) - 1 - trim, 0)]
    size = float(np.max(high - low))
    outside = np.maximum(np.maximum(low - raw, raw - high), 0.0).max(axis=1)
    return outside, size, FAR_NODE * size


def transformed_points(path, raw: np.ndarray, cells: np.ndarray, factor: float, shift: np.ndarray) -> np.ndarray:
    """``raw * factor + shift`` (m), after checking, in this order (the volumes are not yet computed):
    finite coordinates; no node far from the rest (``FAR_NODE``); a body between 1 mm and 5 m in its
    largest extent (``check_body_length``); no coordinate swamping the body (``MAX_OFFSET``)."""
    finite = np.isfinite(raw).all(axis=1)
    if not finite.all():
        node = int(np.flatnonzero(~finite)[0])
        raise InputError(f"mesh file {path}: non-finite node coordinates, e.g. {_node_in_file(raw, cells, node)} "
                         f"(nodes so affected: {int((~finite).sum())})")
    outside, size, far = _far_nodes(raw)
    if size > 0.0 and outside.max() > far:
        node = int(np.argmax(outside))
        raise InputError(f"mesh file {path}: {_node_in_file(raw, cells, node)} lies far from the rest of the body: "
                         f"{outside[node]:.3g} beyond the box of the other nodes, which is {size:.3g} across (in the "
                         f"file's units; nodes so far out: {int((outside > far).sum())}); correct the file's "
                         "coordinates")
    extents = np.ptp(raw, axis=0) * factor
    body = float(extents.max())
    check_body_length(body, f"file {path}", axis=AXES[int(np.argmax(extents))])
    points = raw * factor + shift
    offset = np.abs(points).max(axis=1)
    if not np.all(np.isfinite(points)) or offset.max() > MAX_OFFSET * body:
        _swamped(path, raw, cells, shift, body, offset)
    return points


def _swamped(path, raw, cells, shift, body: float, offset: np.ndarray) -> None:
    """InputError for nodes so far from the origin that their rounding swamps the body."""
    node = int(np.argmax(np.where(np.isfinite(offset), offset, np.inf)))
    far = float(offset[node])
    ratio = far / body if body > 0.0 else np.inf
    if np.abs(shift).max() > MAX_OFFSET * body:
        shown = ", ".join(f"{value:g}" for value in shift)
        raise InputError(f"mesh file {path}: translate = [{shown}] moves the body {far:.3g} m from the origin, "
                         f"{ratio:.3g} times its size ({body:.3g} m): its coordinates would lose their precision; "
                         f"translate it to within {MAX_OFFSET:g} times its size of the origin")
    raise InputError(f"mesh file {path}: {_node_in_file(raw, cells, node)} lies {far:.3g} m from the origin, "
                     f"{ratio:.3g} times the body's size ({body:.3g} m): the coordinates lose their precision; "
                     "move the body to the origin with [mesh] translate")


# ---------------------------------------------------------------------------------------------
# One solid, no inverted or tangled cells


def _face_pairs(path, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(faces, first, second): every face of the cells as (4 n, 3) vertices in the order of ``_FACES``,
    and the indices into it of the two occurrences of each interior face. InputError for a face of
    three tetrahedra or more (cells overlapping there)."""
    faces = cells[:, _FACES].reshape(-1, 3)
    keys = np.sort(faces, axis=1)
    order = np.lexsort(keys.T[::-1])
    same = np.all(keys[order][1:] == keys[order][:-1], axis=1)
    crowded = same[1:] & same[:-1]
    if crowded.any():
        cell = int(order[int(np.flatnonzero(crowded)[0])] // 4) + 1
        raise InputError(f"mesh file {path}: {int(crowded.sum())} faces are shared by three tetrahedra or more "
                         f"(overlapping cells), e.g. a face of tetrahedron number {cell} of the file; remesh the body")
    shared = np.flatnonzero(same)
    return faces, order[shared], order[shared + 1]


def _components(count: int, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The connected component of each of ``count`` cells, joined where (first, second) say."""
    graph = coo_matrix((np.ones(len(first)), (first, second)), shape=(count, count))
    return connected_components(graph, directed=False)[1]


def check_solid(path, points: np.ndarray, cells: np.ndarray) -> None:
    """InputError unless the tetrahedra (as in the file, any orientation, none flat) make one solid:

    - connected through shared faces (pieces meshed separately, with their own nodes on a common
      interface, share no face: they are several solids however they touch);
    - neither inverted nor tangled: the two tetrahedra of an interior face lie on either side of it.
      Each cell's signed volume gives its orientation; a face's vertex order in ``_FACES`` then points
      out of the cell or into it, and a valid pair of neighbours sees their shared face in opposite
      directions. The inverted cells are those outside the largest set of cells joined through valid
      faces (a node moved or swapped into another cell inverts the cells around it).
    """
    faces, first, second = _face_pairs(path, cells)
    cell_of_first, cell_of_second = first // 4, second // 4
    solids = _components(len(cells), cell_of_first, cell_of_second)
    sizes = np.bincount(solids)
    if len(sizes) > 1:
        listed = ", ".join(str(size) for size in np.sort(sizes)[::-1][:5]) + (", …" if len(sizes) > 5 else "")
        raise InputError(f"mesh file {path}: the body is {len(sizes)} separate solids that share no face "
                         f"(tetrahedra: {listed}); pieces meshed with their own nodes on a common interface touch "
                         "but are not joined: fragment the gmsh pieces (gmsh.model.occ.fragment) before meshing, so "
                         "that they share faces")
    flipped = signed_cell_volumes(points, cells) < 0.0
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    even = (((a > b).astype(int) + (a > c) + (b > c)) % 2 == 0) ^ np.repeat(flipped, 4)   # order parity, outward
    valid = even[first] != even[second]
    if valid.all():
        return
    parts = _components(len(cells), cell_of_first[valid], cell_of_second[valid])
    inverted = parts != np.argmax(np.bincount(parts))
    if not inverted.any():      # a tangle within one set of cells: those at its faces
        inverted[np.concatenate([cell_of_first[~valid], cell_of_second[~valid]])] = True
    oriented = np.where(flipped[:, None], cells[:, [0, 1, 3, 2]], cells)
    quality = cell_quality(points, oriented) * np.where(inverted, -1.0, 1.0)
    cell = int(np.flatnonzero(inverted)[0])
    x, y, z = points[cells[cell]].mean(axis=0)
    raise InputError(f"mesh file {path}: {int(inverted.sum())} tetrahedra are inverted or tangled (each lies on the "
                     f"same side of a face as the neighbour it shares it with), e.g. tetrahedron number {cell + 1} of "
                     f"the file, centred at ({x:.4g}, {y:.4g}, {z:.4g}) m; minimum cell quality {quality.min():.3g} "
                     "(1 a regular tetrahedron, < 0 inverted): correct the moved or swapped nodes, or remesh")
