"""The exact Jacobians of the Lighthill thrust (``thrust.py``) as 2x2 blocks per segment.

∂f/∂u [N/m], ∂f/∂u̇ [N s/m] and ∂f/∂ü [kg] of ``thrust.thrust_force``: a segment's forces depend
on its rear and front nodes only, so each matrix is block-tridiagonal; the trapezoid rule's front
half is the rear rule on the mirrored spine, mirrored back.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from aquarom_fenics.physics.thrust import ROTATION_90, SegmentState, SpineGeometry, rotate_back, segment_state

_IDENTITY_2 = np.eye(2)


def _outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a_i b_iᵀ of (..., n, 2) rows, (..., n, 2, 2) (of (..., 2) vectors: (..., 2, 2))."""
    return a[..., :, None] * b[..., None, :]


def _column(values) -> np.ndarray:
    """(...) values as (..., 1, 1), to scale a stack of 2x2 blocks."""
    return np.asarray(values)[..., None, None]


class SegmentBlocks(NamedTuple):
    """A matrix on the nodes (dof order x0, y0, x1, y1, ...) as per-segment 2x2 blocks (n_segments, 2, 2),
    None where zero: ∂f_r/∂x_r, ∂f_r/∂x_f, ∂f_f/∂x_r, ∂f_f/∂x_f of segment i (rear r = i, front f = i + 1)."""

    rear_rear: np.ndarray | None = None
    rear_front: np.ndarray | None = None
    front_rear: np.ndarray | None = None
    front_front: np.ndarray | None = None


def thrust_jacobians(
    geometry: SpineGeometry, displacement, velocity, acceleration
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact Jacobians (∂f/∂u [N/m], ∂f/∂u̇ [N s/m], ∂f/∂ü [kg]) of `thrust_force`.

    Each is (2 n_nodes, 2 n_nodes) in the dof order (x0, y0, x1, y1, ...). A segment's forces
    depend only on its rear and front nodes r and r + 1, so the matrices are block-tridiagonal
    with 2x2 blocks; the source's form acts on rear nodes only (block upper-bidiagonal), the
    lagrangian term and the trapezoid rule's front half add the lower blocks. ∂f/∂ü is the added-mass
    block, non-zero on the block diagonal only: -m̃ ℓ_0 n nᵀ (halves of it from each of a node's two
    segments for the trapezoid rule).
    """
    state = segment_state(geometry, displacement, velocity, acceleration)
    jacobians = []
    for parts in thrust_jacobian_blocks(geometry, state):
        jacobian = _assemble_segment_blocks(geometry.n_nodes, *parts[0])
        for part in parts[1:]:
            jacobian += _assemble_segment_blocks(geometry.n_nodes, *part)
        jacobians.append(jacobian)
    return tuple(jacobians)


def thrust_jacobian_blocks(geometry: SpineGeometry, state: SegmentState) -> tuple[list[SegmentBlocks], ...]:
    """The Jacobians of `thrust_jacobians` as segment blocks: for each of (∂f/∂u, ∂f/∂u̇, ∂f/∂ü) the list of
    parts whose sum it is (the source's form, then the lagrangian term's; for the trapezoid rule the rear
    half's, then the front half's)."""
    if not geometry.trapezoid:
        return _rear_rule_blocks(state, geometry.virtual_mass, geometry.virtual_mass[..., 0], geometry.lagrangian)
    masses = 0.5 * np.concatenate([geometry.virtual_mass, geometry.front_mass[..., ::-1]], axis=-1)
    halves = _rear_rule_blocks(state, masses, geometry.virtual_mass[..., 0], geometry.lagrangian)
    n_segments = geometry.n_nodes - 1
    return tuple([_half_blocks(part, slice(0, n_segments)) for part in parts]
                 + [_mirrored_blocks(_half_blocks(part, slice(n_segments, None))) for part in parts]
                 for parts in halves)


def _half_blocks(blocks: SegmentBlocks, rows: slice) -> SegmentBlocks:
    """The blocks of the half-segments ``rows`` (the rear half or the mirrored half)."""
    return SegmentBlocks(*(None if values is None else values[..., rows, :, :] for values in blocks))


def _mirrored_blocks(blocks: SegmentBlocks) -> SegmentBlocks:
    """The blocks of the mirrored spine's segments on the spine's own segments: the mirrored rear node
    is the front node, and segment s is mirrored segment n_segments - 1 - s."""
    def back(values):
        return None if values is None else values[..., ::-1, :, :]
    return SegmentBlocks(rear_rear=back(blocks.front_front), rear_front=back(blocks.front_rear),
                         front_rear=back(blocks.rear_front), front_front=back(blocks.rear_rear))


def _rear_rule_blocks(state: SegmentState, spine_mass: np.ndarray, tail_mass: float | None,
                      lagrangian: bool) -> tuple[list[SegmentBlocks], ...]:
    """The rear-node rule's Jacobian blocks with segment masses ``spine_mass`` and the tail force's
    ``tail_mass`` (None: no tail force)."""
    negative_mass = -_column(spine_mass)
    negative_mass_length = negative_mass * _column(state.rest_length)
    n, n_rate = state.normal, state.normal_rate
    v, a = state.rear_velocity, state.rear_acceleration
    v_dot_n = state.v_dot_n

    # Spine force, B = (a·n) n + (v·ṅ) n + (v·n) ṅ, f_spine = -m̃ ℓ_0 B.
    # ∂B/∂n = (a·n + v·ṅ) I + n aᵀ + ṅ vᵀ;  ∂n/∂u_f = -∂n/∂u_r = R/ℓ_0
    # => ∂f_spine/∂u_f = -m̃ (∂B/∂n) R,  ∂f_spine/∂u_r = +m̃ (∂B/∂n) R
    db_dn = _column(state.a_dot_n + state.v_dot_ndot) * _IDENTITY_2 + _outer(n, a) + _outer(n_rate, v)
    stiffness_front = negative_mass * rotate_back(db_dn)             # (∂B/∂n) R: rows of ∂B/∂n times R
    stiffness_rear = -stiffness_front

    # ∂B/∂ṅ = n vᵀ + (v·n) I;  ∂ṅ/∂u̇_f = -∂ṅ/∂u̇_r = R/ℓ_0;  ∂B/∂v (explicit) = n ṅᵀ + ṅ nᵀ
    # => ∂f_spine/∂u̇_f = -m̃ (∂B/∂ṅ) R
    #    ∂f_spine/∂u̇_r = -m̃ ℓ_0 (n ṅᵀ + ṅ nᵀ) + m̃ (∂B/∂ṅ) R
    db_dndot = _outer(n, v) + _column(v_dot_n) * _IDENTITY_2
    damping_front = negative_mass * rotate_back(db_dndot)
    damping_rear = negative_mass_length * (_outer(n, n_rate) + _outer(n_rate, n)) - damping_front

    # ∂f_spine/∂ü_r = -m̃ ℓ_0 n nᵀ  (added mass)
    added_mass_rear = negative_mass_length * _outer(n, n)

    # Tail force, f_tail = ½ m̃ (v·n)² t, segment 0, v = u̇_0; ∂t/∂u_1 = -∂t/∂u_0 = I/ℓ_0,
    # ∂(v·n)/∂t = Rᵀ v
    # => ∂f_tail/∂u_1 = -∂f_tail/∂u_0 = (m̃/ℓ_0) [ (v·n) t (Rᵀ v)ᵀ + ½ (v·n)² I ]
    #    ∂f_tail/∂u̇_0 = m̃ (v·n) t nᵀ
    if tail_mass is not None:
        tail_length = state.rest_length[..., 0]
        tail_t, tail_n, tail_v, tail_v_dot_n = state.tangent[..., 0, :], n[..., 0, :], v[..., 0, :], v_dot_n[..., 0]
        tail_stiffness_front = _column(tail_mass / tail_length) * (
            _column(tail_v_dot_n) * _outer(tail_t, rotate_back(tail_v)) + _column(0.5 * tail_v_dot_n**2) * _IDENTITY_2
        )
        stiffness_front[..., 0, :, :] += tail_stiffness_front
        stiffness_rear[..., 0, :, :] -= tail_stiffness_front
        damping_rear[..., 0, :, :] += _column(tail_mass * tail_v_dot_n) * _outer(tail_t, tail_n)

    blocks = ([SegmentBlocks(rear_rear=stiffness_rear, rear_front=stiffness_front)],
              [SegmentBlocks(rear_rear=damping_rear, rear_front=damping_front)],
              [SegmentBlocks(rear_rear=added_mass_rear)])
    if lagrangian:
        blocks[0].append(_position_force_stiffness(spine_mass, state))
        blocks[1].append(_position_force_damping(spine_mass, state))
    return blocks


def _position_force_stiffness(spine_mass: np.ndarray, state: SegmentState) -> SegmentBlocks:
    """∂(±g)/∂u of the lagrangian term g = m̃ (v·n) Rᵀ v (front +g, rear -g).

    ∂g/∂n = m̃ Rᵀ v vᵀ, ∂n/∂u_f = -∂n/∂u_r = R/ℓ_0  =>  ∂g/∂u_f = -∂g/∂u_r = (m̃/ℓ_0) Rᵀ v vᵀ R.
    """
    v = state.rear_velocity
    rotated = rotate_back(v)                       # rows Rᵀ v
    block = _column(spine_mass / state.rest_length) * _outer(rotated, rotated)
    # vᵀ R = (Rᵀ v)ᵀ, so Rᵀ v vᵀ R = (Rᵀ v)(Rᵀ v)ᵀ
    return SegmentBlocks(rear_rear=block, rear_front=-block, front_rear=-block, front_front=block)


def _position_force_damping(spine_mass: np.ndarray, state: SegmentState) -> SegmentBlocks:
    """∂(±g)/∂u̇_r of g = m̃ (v·n) Rᵀ v: ∂g/∂v = m̃ [Rᵀ v nᵀ + (v·n) Rᵀ]."""
    v, n = state.rear_velocity, state.normal
    mass = _column(spine_mass)
    block = mass * (_outer(rotate_back(v), n) + _column(state.v_dot_n) * ROTATION_90.T)
    return SegmentBlocks(rear_rear=-block, front_rear=block)


def _assemble_segment_blocks(n_nodes: int, rear_rear=None, rear_front=None, front_rear=None,
                             front_front=None) -> np.ndarray:
    """(2 n_nodes, 2 n_nodes) matrix summing, per segment i (rear r = i, front f = i + 1), the 2x2
    blocks ∂f_r/∂x_r, ∂f_r/∂x_f, ∂f_f/∂x_r, ∂f_f/∂x_f given as (n_segments, 2, 2) arrays."""
    blocks = np.zeros((n_nodes, 2, n_nodes, 2))
    rear = np.arange(n_nodes - 1)
    front = rear + 1
    for rows, columns, values in ((rear, rear, rear_rear), (rear, front, rear_front),
                                  (front, rear, front_rear), (front, front, front_front)):
        if values is not None:
            blocks[rows, :, columns, :] += values
    return blocks.reshape(2 * n_nodes, 2 * n_nodes)
