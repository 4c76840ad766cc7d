"""Cross-section stations: averages of the body's motion over slabs of fixed size (SPEC §5).

N_s + 1 stations at nominal X_i = -L + i L / N_s (i = 0 at the tail face, N_s at the head face).
Station i averages a nodal field w over the hat h_i of the station grid in nominal x, with the
nominal volume:

    B_i(w) = ∫ h_i(X) w dV_0 / ∫ h_i(X) dV_0 = Σ_j b_ij w_j,   b_ij = ∫ h_i φ_j dV_0 / ∫ h_i dV_0

(φ_j the Lagrange basis, Σ_j φ_j = 1, so Σ_j b_ij = 1: a rigid motion moves every station with it).
The hats form a partition of unity; the end stations' half-hats cover the first and last slab.
B is one linear map for every design (the nominal volume), so reduced station kinematics B V η
are exact in ξ. The head average (the drag's reference velocity) is the same average with the
head cells' indicator in place of h_i.

Everything here is plain numpy on the nominal mesh (every rank holds it); integrals use a
quadrature rule of degree ``STATION_QUADRATURE_DEGREE`` per cell (the hats have kinks inside
cells: the rule converges with the mesh, like the rest of the discretisation).
"""
from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from aquarom_fenics.geometry.mesh import TETRAHEDRON_EDGES, LagrangeNodes, signed_cell_volumes
from aquarom_fenics.geometry.shapes import reference_to_cells

log = logging.getLogger("aquarom")

STATION_QUADRATURE_DEGREE = 8
"""Degree of the per-cell rule for ∫ h_i φ_j dV_0 (φ_j of degree ≤ 2 times a kinked hat)."""


def station_positions(length: float, x_tail: float, n_stations: int) -> np.ndarray:
    """(N_s + 1,) nominal x [m] of the stations, tail -> head: X_i = x_tail + i L / N_s."""
    return x_tail + length * np.arange(n_stations + 1) / n_stations


def hat_functions(x: np.ndarray, stations: np.ndarray) -> np.ndarray:
    """(N_s + 1, n) values of the hats h_i at nominal x: piecewise linear, h_i(X_j) = δ_ij."""
    spacing = np.diff(stations)
    x = np.clip(np.asarray(x, dtype=float), stations[0], stations[-1])
    values = np.zeros((stations.size, x.size))
    slab = np.clip(np.searchsorted(stations, x, side="right") - 1, 0, spacing.size - 1)
    # h_{slab+1} = (x - X_slab)/Δ, h_slab = 1 - h_{slab+1} on [X_slab, X_slab+1]
    fraction = (x - stations[slab]) / spacing[slab]
    columns = np.arange(x.size)
    values[slab, columns] = 1.0 - fraction
    values[slab + 1, columns] += fraction
    return values


def simplex_lagrange_basis(reference_points: np.ndarray, edges: np.ndarray, degree: int) -> np.ndarray:
    """(n_q, n_vertices [+ n_edges]) Lagrange basis of degree 1 or 2 on a reference simplex at
    ``reference_points`` (n_q, dimension): the vertices, then the ``edges`` (pairs of local vertices)."""
    reference_points = np.asarray(reference_points, dtype=float)
    barycentric = np.column_stack([1.0 - reference_points.sum(axis=1), reference_points])
    if degree == 1:
        return barycentric
    # vertex a: λ_a (2 λ_a - 1); edge (a, b): 4 λ_a λ_b
    vertices = barycentric * (2.0 * barycentric - 1.0)
    return np.hstack([vertices, 4.0 * barycentric[:, edges[:, 0]] * barycentric[:, edges[:, 1]]])


def lagrange_basis(reference_points: np.ndarray, degree: int) -> np.ndarray:
    """(n_q, 4 or 10) values of the Lagrange basis at reference points, in the node order of
    ``LagrangeNodes.cell_nodes`` (vertices, then the edges of ``TETRAHEDRON_EDGES``)."""
    return simplex_lagrange_basis(reference_points, TETRAHEDRON_EDGES, degree)


def weighted_node_integrals(points: np.ndarray, cells: np.ndarray, nodes: LagrangeNodes, weight) -> np.ndarray:
    """(n_weights, n_nodes) ∫ w_i(X) φ_j dV_0 for the weights ``weight(X) -> (n_weights, n)`` over the
    nominal mesh (``points``, ``cells``), one quadrature rule per cell."""
    import basix

    reference, quadrature_weights = basix.make_quadrature(basix.CellType.tetrahedron, STATION_QUADRATURE_DEGREE)
    basis = lagrange_basis(reference, nodes.degree)                         # (n_q, n_local)
    positions = reference_to_cells(points, cells, reference)                # (n_cells, n_q, 3)
    jacobian = 6.0 * np.abs(signed_cell_volumes(points, cells))             # |det J| per cell
    weights = weight(positions.reshape(-1, 3)).reshape(-1, *positions.shape[:2])   # (n_w, n_cells, n_q)
    # ∫_cell w φ_a dV = Σ_q w(x_q) φ_a(X_q) ω_q |det J|
    local = np.einsum("wcq,qa,q,c->wca", weights, basis, quadrature_weights, jacobian)
    n_weights, n_nodes = weights.shape[0], nodes.points.shape[0]
    rows = np.repeat(np.arange(n_weights), local.shape[1] * local.shape[2])
    columns = np.tile(nodes.cell_nodes.ravel(), n_weights)
    return sparse.coo_matrix((local.ravel(), (rows, columns)), shape=(n_weights, n_nodes)).toarray()


@dataclass(frozen=True)
class StationAverages:
    """The averaging maps of one nominal mesh: rows b_i over the nodes (Σ_j b_ij = 1).

    stations: (N_s + 1,) nominal x [m], tail -> head.
    weights: (N_s + 1, n_nodes) b_ij of the station averages B_i (applied to each component).
    head_weights: (n_nodes,) the head-volume average (the drag's reference velocity).
    """

    stations: np.ndarray
    weights: sparse.csr_matrix
    head_weights: np.ndarray

    @property
    def n_stations(self) -> int:
        return self.stations.size

    def average(self, nodal: np.ndarray) -> np.ndarray:
        """(N_s + 1, k) averages of an (n_nodes, k) nodal field."""
        return self.weights @ nodal


TRIANGLE_EDGES = np.array([[0, 1], [1, 2], [0, 2]])
"""Local vertices of a triangle's edges, in the order of the degree-2 face basis below."""


def triangle_basis(reference_points: np.ndarray, degree: int) -> np.ndarray:
    """(n_q, 3 or 6) Lagrange basis on the reference triangle: vertices, then the edges of TRIANGLE_EDGES."""
    return simplex_lagrange_basis(reference_points, TRIANGLE_EDGES, degree)


def face_average_weights(mesh_points: np.ndarray, facets: np.ndarray, nodes: LagrangeNodes) -> np.ndarray:
    """(n_nodes,) b_j = ∫_face φ_j dA / area over the triangles ``facets`` (vertex indices)."""
    import basix

    reference, quadrature_weights = basix.make_quadrature(basix.CellType.triangle, 2 * nodes.degree)
    basis = triangle_basis(reference, nodes.degree)
    corners = np.asarray(mesh_points, dtype=float)[facets]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    facet_nodes = facets if nodes.degree == 1 else np.hstack(
        [facets, nodes.nodes_of_pairs(facets[:, TRIANGLE_EDGES].reshape(-1, 2)).reshape(-1, 3)])
    # ∫_facet φ_a dA = 2 A Σ_q φ_a(X_q) ω_q
    local = 2.0 * areas[:, None] * (quadrature_weights @ basis)[None, :]
    weights = np.bincount(facet_nodes.ravel(), local.ravel(), minlength=nodes.points.shape[0])
    return weights / areas.sum()


_COMPUTED: OrderedDict[bytes, StationAverages] = OrderedDict()
"""The last few station averages computed in this process, by a digest of their inputs: a fish read
again from the same mesh (every run loads its own) gets the same maps without the integrals."""
_COMPUTED_KEPT = 8


def _digest(arrays, numbers) -> bytes:
    digest = hashlib.blake2b(repr(numbers).encode(), digest_size=32)
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(repr((array.dtype.str, array.shape)).encode())
        digest.update(array.tobytes())
    return digest.digest()


def station_averages(mesh_points: np.ndarray, mesh_cells: np.ndarray, nodes: LagrangeNodes, box, n_stations: int,
                     head_cells: np.ndarray, tail_face: np.ndarray | None = None) -> StationAverages:
    """B and the head average on the nominal mesh (``box``: the fish's bounding box). With ``tail_face``
    (the triangles of the end face x = -L) the tail station averages that face instead of its half-hat.
    The maps are read-only: the same inputs in the same process give the same (shared) maps."""
    if n_stations < 2:
        raise ValueError(f"need at least 2 station intervals, got {n_stations}")
    key = _digest((mesh_points, mesh_cells, nodes.points, nodes.cell_nodes, head_cells,
                   np.empty((0, 3), dtype=np.int64) if tail_face is None else tail_face),
                  (float(box.length), float(box.x_tail), n_stations, nodes.degree, tail_face is None))
    if key not in _COMPUTED:
        _COMPUTED[key] = _station_averages(mesh_points, mesh_cells, nodes, box, n_stations, head_cells, tail_face)
        while len(_COMPUTED) > _COMPUTED_KEPT:
            _COMPUTED.popitem(last=False)
    _COMPUTED.move_to_end(key)
    return _COMPUTED[key]


def _station_averages(mesh_points, mesh_cells, nodes: LagrangeNodes, box, n_stations: int, head_cells,
                      tail_face) -> StationAverages:
    stations = station_positions(box.length, box.x_tail, n_stations)
    hat_integrals = weighted_node_integrals(mesh_points, mesh_cells, nodes,
                                            lambda x: hat_functions(x[:, 0], stations))
    weights = hat_integrals / hat_integrals.sum(axis=1, keepdims=True)
    if tail_face is not None:
        weights[0] = face_average_weights(mesh_points, tail_face, nodes)
    head_integrals = weighted_node_integrals(mesh_points, mesh_cells[head_cells], _cell_subset(nodes, head_cells),
                                             lambda x: np.ones((1, x.shape[0])))[0]
    averages = StationAverages(stations, sparse.csr_matrix(weights), head_integrals / head_integrals.sum())
    for array in (averages.stations, averages.weights.data, averages.weights.indices, averages.weights.indptr,
                  averages.head_weights):
        array.flags.writeable = False
    return averages


def averages_of(fish, n_stations: int, tail_station: str = "face") -> StationAverages:
    """The station averages of a fish's nominal mesh, computed once per fish (kept in ``fish.derived``),
    station count and tail station ("slab": the half-hat over the last slab; "face": the end face x = -L)."""
    key = ("station_averages", n_stations, tail_station)
    if key not in fish.derived:
        tags = fish.tags
        face = None
        if tail_station == "face":
            on_tail = np.abs(tags.box.relative(fish.mesh.points)[:, 0] + tags.box.length) <= tags.tolerance
            face = tags.skin_facets[on_tail[tags.skin_facets].all(axis=1)]
            if face.size == 0:
                face = None
                log.info("mesh %s has no end face at x = %.6g m (its tail tapers): the tail station averages the "
                         "last slab's half-hat (as [fluid] tail_station = \"slab\")", fish.mesh.source, tags.box.x_tail)
        fish.derived[key] = station_averages(fish.mesh.points, fish.mesh.cells, fish.nodes, tags.box, n_stations,
                                             tags.head_cells, face)
    return fish.derived[key]


def _cell_subset(nodes: LagrangeNodes, cells: np.ndarray) -> LagrangeNodes:
    return LagrangeNodes(nodes.degree, nodes.points, nodes.cell_nodes[cells], nodes.edges, nodes.n_vertices)


def skin_line_heights(points: np.ndarray, facets: np.ndarray, x: np.ndarray, y: float,
                      relative_tolerance: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """(top, bottom), each (n,): the largest and smallest z [m] where the vertical line through (x_i, y)
    meets the skin triangles ``facets`` (vertex indices into ``points``); NaN where it misses them.

    A triangle meets the line where the barycentric coordinates λ of (x_i, y) in its projection on
    the x-y plane are all ≥ 0 (within ``relative_tolerance``, so that a line along an edge meets
    both triangles); there z = z_0 + λ_1 (z_1 - z_0) + λ_2 (z_2 - z_0). Triangles standing vertical
    (their x-y projection degenerate) are passed over: their edges belong to triangles that are not.
    """
    corners = np.asarray(points, dtype=float)[np.asarray(facets)]            # (n_f, 3 corners, 3)
    origin, first, second = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    determinant = first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]   # 2 × projected area
    doubled_area = np.linalg.norm(np.cross(first, second), axis=1)
    upright = np.abs(determinant) > relative_tolerance * doubled_area
    lower, upper = corners[:, :, :2].min(axis=1), corners[:, :, :2].max(axis=1)
    reach = relative_tolerance * np.sqrt(doubled_area)
    x = np.asarray(x, dtype=float)
    top, bottom = np.full(x.size, np.nan), np.full(x.size, np.nan)
    for i, x_i in enumerate(x):
        near = np.flatnonzero(upright & (lower[:, 0] <= x_i + reach) & (upper[:, 0] >= x_i - reach)
                              & (lower[:, 1] <= y + reach) & (upper[:, 1] >= y - reach))
        offset = np.array([x_i, y]) - origin[near, :2]
        lambda_1 = (offset[:, 0] * second[near, 1] - offset[:, 1] * second[near, 0]) / determinant[near]
        lambda_2 = (first[near, 0] * offset[:, 1] - first[near, 1] * offset[:, 0]) / determinant[near]
        inside = np.minimum(np.minimum(lambda_1, lambda_2), 1.0 - lambda_1 - lambda_2) >= -relative_tolerance
        if not inside.any():
            continue
        z = (origin[near, 2] + lambda_1 * first[near, 2] + lambda_2 * second[near, 2])[inside]
        top[i], bottom[i] = z.max(), z.min()
    return top, bottom
