"""Closed triangulated surfaces of tetrahedral meshes: the boundary of a set of cells and its checks.

The boundary of a set of tetrahedra is the faces that belong to exactly one of them, each ordered
so that its right-hand normal points away from the fourth vertex of its tetrahedron (outward).
Before a surface is written it is checked (:func:`surface_problem`):

- closed: every edge is shared by exactly two triangles;
- manifold: the two triangles of an edge run along it in opposite directions (one orientation),
  and the triangles around every vertex form one fan (no two surfaces touching at a vertex);
- outward: the enclosed volume V = Σ_t x_0 · (x_1 × x_2) / 6 (divergence theorem) is positive;
- no self-intersection: no edge of a triangle crosses the interior of a triangle that shares no
  vertex with it (candidates found on a uniform grid of cells as large as the largest triangle).
  The test is for transversal crossings; two coplanar triangles that overlap, or triangles that
  only touch along a boundary, are not reported by it (the closed and manifold checks cover the
  surfaces of a valid tetrahedral mesh, whose boundary faces meet only at shared vertices and edges);
- the volume equals the sum of the tetrahedra's volumes to :data:`VOLUME_TOLERANCE` relative.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from aquarom_fenics.geometry.mesh import signed_cell_volumes

VOLUME_TOLERANCE = 1e-9
"""Relative tolerance of the enclosed volume against the sum of the tetrahedra's volumes."""

_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
"""Local vertices of the four faces of a tetrahedron; face f is opposite local vertex f."""


@dataclass(frozen=True)
class Surface:
    """A triangulated surface: ``points`` (n, 3) [any length unit], ``triangles`` (m, 3) indices."""

    points: np.ndarray
    triangles: np.ndarray

    @property
    def volume(self) -> float:
        """Enclosed volume by the divergence theorem, V = Σ_t (x_0 - c) · ((x_1 - c) × (x_2 - c)) / 6,
        about the centre c of the bounding box (the same V for a closed surface, fewer rounding errors)."""
        centre = 0.5 * (self.points.min(axis=0) + self.points.max(axis=0))
        x = self.points[self.triangles] - centre
        return float(np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0)

    @property
    def normals(self) -> np.ndarray:
        """(m, 3) unit normals by the right-hand rule of each triangle's vertex order."""
        x = self.points[self.triangles]
        normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
        return normal / np.linalg.norm(normal, axis=1, keepdims=True)

    def scaled(self, factor: float) -> "Surface":
        return Surface(self.points * factor, self.triangles)


def boundary_surface(points: np.ndarray, cells: np.ndarray) -> Surface:
    """The boundary of the tetrahedra ``cells`` on ``points``: faces of exactly one of them, oriented
    away from that tetrahedron's fourth vertex; only the vertices the faces use are kept."""
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells, dtype=np.int64)
    faces = cells[:, _FACES].reshape(-1, 3)
    opposite = cells.reshape(-1)                 # face 4c + f is opposite vertex cells[c, f]
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    keep = np.sort(first[counts == 1])
    faces, opposite = faces[keep], opposite[keep]
    x = points[faces]
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    inward = np.einsum("ij,ij->i", normal, x[:, 0] - points[opposite]) < 0.0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    used, triangles = np.unique(faces, return_inverse=True)
    return Surface(points[used], triangles.reshape(-1, 3))


def tetrahedra_volume(points: np.ndarray, cells: np.ndarray) -> float:
    """Σ of the signed volumes of the tetrahedra (``signed_cell_volumes``)."""
    return float(signed_cell_volumes(points, cells).sum())


def _directed_edges(triangles: np.ndarray) -> np.ndarray:
    """(3m, 2) directed edges (a → b) of the triangles, edge k of triangle t at row 3t + k."""
    return triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)


def open_edges(surface: Surface) -> int:
    """Number of edges not shared by exactly two triangles (0 for a closed surface)."""
    edges = np.sort(_directed_edges(surface.triangles), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return int((counts != 2).sum())


def manifold_problem(surface: Surface) -> str | None:
    """Why a closed surface is not an oriented manifold, or None: an edge run twice in one direction
    (the neighbours disagree on the orientation), or a vertex whose triangles form several fans."""
    edges = _directed_edges(surface.triangles)
    n = len(surface.points)
    keys = edges[:, 0] * n + edges[:, 1]
    unique_keys, counts = np.unique(keys, return_counts=True)
    if (counts > 1).any():
        return f"{int((counts > 1).sum())} edge(s) run twice in one direction (inconsistent orientation)"
    partner = np.searchsorted(unique_keys, edges[:, 1] * n + edges[:, 0])
    partner = np.minimum(partner, len(unique_keys) - 1)
    if (unique_keys[partner] != edges[:, 1] * n + edges[:, 0]).any():
        return "an edge has no opposite edge (the surface is not closed)"
    order = np.argsort(keys)
    across = order[partner]                                  # row of the opposite edge b → a
    # corner (t, at a) of edge a → b joins the corner at a of the triangle across, whose edge is b → a:
    # in that triangle a is the edge's end, so its corner is the next row's start
    triangle, local = across // 3, across % 3
    corner_across = 3 * triangle + (local + 1) % 3
    rows = np.arange(len(edges))                             # corner 3t + k sits at vertex edges[3t + k, 0]
    graph = coo_matrix((np.ones(len(rows)), (rows, corner_across)), shape=(len(rows), len(rows)))
    fans, _ = connected_components(graph, directed=False)
    vertices = len(np.unique(surface.triangles))
    if fans != vertices:
        return f"{fans - vertices} vertex/vertices where separate parts of the surface touch"
    return None


def _grid_pairs(boxes_low: np.ndarray, boxes_high: np.ndarray, size: float) -> np.ndarray:
    """(k, 2) pairs i < j of boxes that share a cell of a uniform grid of spacing ``size`` (every box
    is at most ``size`` wide, so it covers at most 2 × 2 × 2 cells)."""
    low = np.floor(boxes_low / size).astype(np.int64)
    high = np.floor(boxes_high / size).astype(np.int64)
    entries, owners = [], []
    for shift in np.ndindex(2, 2, 2):
        cell = low + np.array(shift)
        inside = (cell <= high).all(axis=1)
        entries.append(cell[inside])
        owners.append(np.flatnonzero(inside))
    cells, owners = np.vstack(entries), np.concatenate(owners)
    _, key = np.unique(cells, axis=0, return_inverse=True)
    order = np.lexsort((owners, key.ravel()))
    key, owners = key.ravel()[order], owners[order]
    pairs = []
    for step in range(1, len(key)):
        same = key[step:] == key[:-step]
        if not same.any():
            break
        pairs.append(np.column_stack([owners[:-step][same], owners[step:][same]]))
    if not pairs:
        return np.zeros((0, 2), dtype=np.int64)
    return np.unique(np.sort(np.vstack(pairs), axis=1), axis=0)


def _orientation(a, b, c, d) -> np.ndarray:
    """6 × signed volume of the tetrahedra (a, b, c, d), row by row."""
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))


def _edges_cross(x: np.ndarray, y: np.ndarray, tolerance: float) -> np.ndarray:
    """Per pair: whether an edge of triangle x (k, 3, 3) crosses the interior of triangle y."""
    crossing = np.zeros(len(x), dtype=bool)
    for start, end in ((0, 1), (1, 2), (2, 0)):
        p, q = x[:, start], x[:, end]
        side_p = _orientation(y[:, 0], y[:, 1], y[:, 2], p)
        side_q = _orientation(y[:, 0], y[:, 1], y[:, 2], q)
        through = ((side_p > tolerance) & (side_q < -tolerance)) | ((side_p < -tolerance) & (side_q > tolerance))
        around = [_orientation(p, q, y[:, i], y[:, (i + 1) % 3]) for i in range(3)]
        inside = (((around[0] > tolerance) & (around[1] > tolerance) & (around[2] > tolerance))
                  | ((around[0] < -tolerance) & (around[1] < -tolerance) & (around[2] < -tolerance)))
        crossing |= through & inside
    return crossing


def self_intersections(surface: Surface) -> int:
    """Number of pairs of triangles sharing no vertex where an edge of one crosses the other."""
    x = surface.points[surface.triangles]
    low, high = x.min(axis=1), x.max(axis=1)
    size = float((high - low).max())
    if size <= 0.0:
        return 0
    pairs = _grid_pairs(low, high, size)
    first, second = surface.triangles[pairs[:, 0]], surface.triangles[pairs[:, 1]]
    shares = (first[:, :, None] == second[:, None, :]).any(axis=(1, 2))
    overlap = ((low[pairs[:, 0]] <= high[pairs[:, 1]]) & (low[pairs[:, 1]] <= high[pairs[:, 0]])).all(axis=1)
    pairs = pairs[~shares & overlap]
    edge = float(np.linalg.norm(x[:, 1] - x[:, 0], axis=1).mean())
    tolerance = 1e-10 * edge ** 3
    a, b = x[pairs[:, 0]], x[pairs[:, 1]]
    return int((_edges_cross(a, b, tolerance) | _edges_cross(b, a, tolerance)).sum())


def surface_problem(surface: Surface, expected_volume: float) -> tuple[str, str] | None:
    """("input" or "volume", why) when the surface fails a check of the module docstring, else None.

    "input": not closed, not manifold, inward or self-intersecting (the mesh or design is at fault);
    "volume": the enclosed volume differs from ``expected_volume`` (the tetrahedra's) by more than
    VOLUME_TOLERANCE relative (the computation is at fault).
    """
    if len(surface.triangles) == 0:
        return "input", "no boundary triangles"
    opened = open_edges(surface)
    if opened:
        return "input", f"not closed: {opened} edge(s) not shared by exactly two triangles"
    problem = manifold_problem(surface)
    if problem:
        return "input", f"not manifold: {problem}"
    volume = surface.volume
    if not volume > 0.0:
        return "input", f"not outward: enclosed volume {volume:.6g} ≤ 0"
    crossings = self_intersections(surface)
    if crossings:
        return "input", f"self-intersecting: {crossings} pair(s) of triangles cross"
    if abs(volume - expected_volume) > VOLUME_TOLERANCE * abs(expected_volume):
        return "volume", (f"enclosed volume {volume:.12g} differs from the tetrahedra's {expected_volume:.12g} "
                          f"by {abs(volume / expected_volume - 1):.2e} relative (> {VOLUME_TOLERANCE:g})")
    return None
