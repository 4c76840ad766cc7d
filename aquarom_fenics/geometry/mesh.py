"""Linear tetrahedral meshes as plain numpy arrays: `FishMesh`, Lagrange nodes, cell geometry.

A mesh is a `FishMesh`: node coordinates in metres and positively oriented linear tetrahedra.
The reference block is generated in ``block.py``, mesh files are read in ``mesh_files.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aquarom_fenics.errors import InputError


@dataclass(frozen=True)
class FishMesh:
    """A linear tetrahedral mesh and its tagged regions."""

    points: np.ndarray  # (n_nodes, 3) float64, metres
    cells: np.ndarray  # (n_cells, 4) int64, positively oriented tetrahedra
    source: str  # where it came from, e.g. "block level 1" or the file path
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    """Tagged cell sets by name (sorted cell indices), e.g. "head", "left_muscle", "right_muscle";
    empty for a mesh without tags."""


def check_region_fractions(source: str, head_fraction: float, muscle_range) -> None:
    """InputError unless 0 < head_fraction < 1 and -1 ≤ rear < front ≤ 0 (units of L from the head)."""
    if not 0.0 < head_fraction < 1.0:
        raise InputError(
            f"mesh {source}: head_fraction = {head_fraction!r}; it must lie between 0 and 1"
        )
    rear, front = muscle_range
    if not -1.0 <= rear < front <= 0.0:
        raise InputError(
            f"mesh {source}: muscle_range = {tuple(muscle_range)!r}; it must be (rear, front) "
            "with -1 <= rear < front <= 0 (units of L from the head face)"
        )


TETRAHEDRON_EDGES = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]])
"""Local vertices of the six edges of a tetrahedron, in the reference (basix/UFC) edge order."""


@dataclass(frozen=True)
class LagrangeNodes:
    """The displacement nodes of a degree-1 or degree-2 Lagrange space on a `FishMesh`.

    Degree 1: the vertices. Degree 2: the vertices, then one node at the midpoint of every edge
    (``edges[e]`` its two vertices, node ``n_vertices + e``). ``cell_nodes`` lists each cell's
    nodes, vertices first, then its edges in the order of ``TETRAHEDRON_EDGES``.
    """

    degree: int
    points: np.ndarray  # (n_nodes, 3) metres; the first n_vertices rows are the mesh points
    cell_nodes: np.ndarray  # (n_cells, 4) or (n_cells, 10)
    edges: np.ndarray  # (n_edges, 2) vertex pairs, smaller index first (empty at degree 1)
    n_vertices: int

    def nodes_of_pairs(self, pairs: np.ndarray) -> np.ndarray:
        """Node index of each vertex pair (a, b): the vertex a if a = b, else the edge's midpoint."""
        pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
        nodes = pairs[:, 0].copy()
        on_edge = pairs[:, 0] != pairs[:, 1]
        if on_edge.any():
            keys = self.edges[:, 0] * self.n_vertices + self.edges[:, 1]
            wanted = pairs[on_edge, 0] * self.n_vertices + pairs[on_edge, 1]
            nodes[on_edge] = self.n_vertices + np.searchsorted(keys, wanted)
        return nodes

    def facet_nodes(self, facets: np.ndarray) -> np.ndarray:
        """All nodes of the given (n, 3) vertex triangles (their vertices and edge midpoints)."""
        facets = np.asarray(facets, dtype=np.int64)
        if self.degree == 1:
            return np.unique(facets)
        pairs = facets[:, [[0, 0], [1, 1], [2, 2], [0, 1], [1, 2], [0, 2]]].reshape(-1, 2)
        return np.unique(self.nodes_of_pairs(pairs))


def lagrange_nodes(mesh: FishMesh, degree: int) -> LagrangeNodes:
    """The nodes of the degree-``degree`` Lagrange space on ``mesh`` (SPEC §3: vertices and, at
    degree 2, edge midpoints x_m = (x_a + x_b)/2)."""
    cells = np.asarray(mesh.cells, dtype=np.int64)
    n_vertices = mesh.points.shape[0]
    if degree == 1:
        return LagrangeNodes(1, mesh.points, cells, np.empty((0, 2), dtype=np.int64), n_vertices)
    cell_edges = np.sort(cells[:, TETRAHEDRON_EDGES], axis=2).reshape(-1, 2)
    edges, edge_of = np.unique(cell_edges, axis=0, return_inverse=True)
    midpoints = 0.5 * (mesh.points[edges[:, 0]] + mesh.points[edges[:, 1]])
    cell_nodes = np.hstack([cells, n_vertices + edge_of.reshape(-1, 6)])
    return LagrangeNodes(degree, np.vstack([mesh.points, midpoints]), cell_nodes, edges, n_vertices)


# ---------------------------------------------------------------------------------------------
# Geometry of tetrahedra


def signed_cell_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volumes (m³) of tetrahedra: V = det[x1 - x0, x2 - x0, x3 - x0] / 6.

    Positive when (x1 - x0, x2 - x0, x3 - x0) is a right-handed triple.
    """
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    edges = vertices[:, 1:, :] - vertices[:, :1, :]
    return np.linalg.det(edges) / 6.0


def cell_quality(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Volume-to-edge shape measure q = 6√2 V / ℓ_rms³ per tetrahedron (dimensionless).

    ℓ_rms is the root mean square of the six edge lengths and V the signed volume, so q = 1 for
    the regular tetrahedron, q → 0 for a degenerate (flat) one and q < 0 for an inverted one.
    """
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    first, second = np.triu_indices(4, k=1)
    edge_vectors = vertices[:, second, :] - vertices[:, first, :]
    edge_rms = np.sqrt(np.mean(np.sum(edge_vectors**2, axis=2), axis=1))
    volumes = signed_cell_volumes(points, cells)
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = 6.0 * np.sqrt(2.0) * volumes / edge_rms**3
    return np.where(edge_rms > 0.0, quality, 0.0)


def mean_edge_length(points: np.ndarray, cells: np.ndarray) -> float:
    """Mean length (m) of the six edges of all tetrahedra (shared edges counted per cell)."""
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    first, second = np.triu_indices(4, k=1)
    edge_vectors = vertices[:, second, :] - vertices[:, first, :]
    return float(np.mean(np.linalg.norm(edge_vectors, axis=2)))


def oriented_positively(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The cells with vertices 2 and 3 swapped wherever the signed volume is negative."""
    cells = np.array(cells, dtype=np.int64)
    negative = signed_cell_volumes(points, cells) < 0.0
    cells[negative] = cells[negative][:, [0, 1, 3, 2]]
    return cells


def used_nodes_only(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop nodes no cell uses and renumber the cells (node order kept)."""
    used = np.unique(cells)
    new_index = np.full(len(points), -1, dtype=np.int64)
    new_index[used] = np.arange(len(used), dtype=np.int64)
    return points[used], new_index[cells]
