"""Projections of the thrust's Jacobians on reduced rows: Lᵀ J R from the segment blocks of
``thrust_jacobians.py`` as one matrix product (used by ``thrust_reduced.py``)."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.physics.thrust import SpineGeometry, segment_state
from aquarom_fenics.physics.thrust_jacobians import thrust_jacobian_blocks


def block_products(left_rear: np.ndarray, left_front: np.ndarray, right_rear: np.ndarray,
                   right_front: np.ndarray, kinds) -> np.ndarray:
    """(n_kinds · 4 n_segments, k l) products L_sa,i R_sb,j of the rows L (n_segments, 2, k) and R (n_segments, 2, l)
    at the segments' rear and front points, for the block ``kinds`` (indices into ``SegmentBlocks``: rear_rear,
    rear_front, front_rear, front_front) in turn, rows (kind, s, a, b), columns (i, j):
    Lᵀ J R = (J's blocks of those kinds as one vector) @ products."""
    pairs = ((left_rear, right_rear), (left_rear, right_front), (left_front, right_rear), (left_front, right_front))
    return np.vstack([np.einsum("sai,sbj->sabij", *pairs[kind]).reshape(4 * left_rear.shape[0], -1) for kind in kinds])


def project_jacobians(jacobians, products: np.ndarray, kinds) -> np.ndarray:
    """Lᵀ J R flattened, (n_jacobians, k l), of each Jacobian J = Σ parts (a list of ``SegmentBlocks`` with blocks
    of the given ``kinds`` only) in ``jacobians``: Σ_s L_rᵀ J_rr R_r + L_rᵀ J_rf R_f + L_fᵀ J_fr R_r + L_fᵀ J_ff R_f,
    one matrix product with the ``products`` of :func:`block_products` for those kinds. Blocks with leading
    (batch) axes, (..., n_segments, 2, 2), give (..., n_jacobians, k l)."""
    lead = next(part[kind] for parts in jacobians for part in parts for kind in kinds
                if part[kind] is not None).shape[:-3]
    values = np.zeros(lead + (len(jacobians), len(kinds), products.shape[0] // len(kinds)))
    for jacobian, parts in enumerate(jacobians):
        for part in parts:
            for slot, kind in enumerate(kinds):
                if part[kind] is not None:
                    values[..., jacobian, slot, :] += part[kind].reshape(lead + (-1,))
    return (values.reshape(-1, products.shape[0]) @ products).reshape(lead + (len(jacobians), -1))


def block_kinds(spine: SpineGeometry) -> tuple[int, ...]:
    """The kinds of segment blocks (indices into ``SegmentBlocks``) the thrust's Jacobians have on this spine:
    rear rows only for the source's form, all four with the lagrangian term."""
    at_rest = segment_state(spine, *np.zeros((3, spine.n_nodes, 2)))
    return tuple(kind for kind in range(4) if any(part[kind] is not None for parts in
                                                   thrust_jacobian_blocks(spine, at_rest) for part in parts))
