"""The reduced Lighthill thrust of ``thrust_reduced.py`` at a stack of designs ξ_b at once (batch axis b).

The same law and Jacobian blocks (``thrust.py``, ``thrust_jacobians.py``, which take leading axes) on the
reduced kinematics W η_b of every design; W is shared, the spine (virtual masses, rest points and
lengths) is the design's. Arrays are (B, ...) with B designs.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from aquarom_fenics.physics.thrust import (SegmentState, SpineGeometry, derivative_weights, segment_state_of,
                                           segment_weighted_force, thrust_force_of_state, virtual_mass,
                                           virtual_mass_gradient)
from aquarom_fenics.physics.thrust_jacobians import SegmentBlocks, thrust_jacobian_blocks
from aquarom_fenics.physics.thrust_projection import block_kinds, block_products, project_jacobians
from aquarom_fenics.physics.thrust_reduced import ThrustTensors


@dataclass
class BatchedSpine:
    """The spines of B designs at rest (what the thrust functions read of a :class:`SpineGeometry`):
    rest_xy (B, n_nodes, 2) [m], virtual_mass and front_mass (B, n_segments) [kg/m]."""

    rest_xy: np.ndarray
    virtual_mass: np.ndarray
    spine_force: str
    front_mass: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.rest_length = np.linalg.norm(self.rest_xy[:, 1:] - self.rest_xy[:, :-1], axis=-1)   # (B, n_segments)

    @property
    def lagrangian(self) -> bool:
        return self.spine_force == "lagrangian"

    @property
    def trapezoid(self) -> bool:
        return self.front_mass is not None

    @property
    def n_nodes(self) -> int:
        return self.rest_xy.shape[-2]


class BatchedThrust:
    """f_thrust,r = Wᵀ f(W η_b, W η̇_b, W η̈_b; ξ_b) of B designs, its tangents and ξ-derivative.

    Design by design the same arithmetic as :class:`~aquarom_fenics.physics.thrust_reduced.ReducedThrust`
    (to rounding); the segment state of the last point is kept for the tangents at the same point.
    """

    def __init__(self, data: ThrustTensors, deltas: np.ndarray, spine_force: str):
        batch, p = deltas.shape
        m = data.rows.shape[-1]
        self.moving_rest = bool(p and np.any(data.rest_xy_gradient))
        trapezoid = data.front_dorsal_z is not None
        dorsal_z = data.dorsal_z + deltas @ data.dorsal_z_gradient.T
        front_z = data.front_dorsal_z + deltas @ data.front_dorsal_z_gradient.T if trapezoid else None
        rest_xy = np.broadcast_to(data.rest_xy, (batch,) + data.rest_xy.shape)
        if self.moving_rest:
            rest_xy = rest_xy + np.einsum("ncp,bp->bnc", data.rest_xy_gradient, deltas)
        self.spine = spine = BatchedSpine(rest_xy, np.asfortranarray(virtual_mass(dorsal_z, data.fluid_density)),
                                          spine_force, np.asfortranarray(virtual_mass(front_z, data.fluid_density))
                                          if trapezoid else None)
        self.rows = data.rows.reshape(-1, m)                                   # (2 n_points, m): W
        rear, front = data.rows[:-1], data.rows[1:]
        length = spine.rest_length                                             # (B, n_segments)
        rest_tangent = (rest_xy[:, 1:] - rest_xy[:, :-1]) / length[..., None]
        difference_rows, own_rows = front - rear, rear                        # t = t_rest + (W_f - W_r) η / ℓ_0
        self.half_rest_length, self.half_rest_tangent = length, rest_tangent
        if trapezoid:
            self.half_rest_length = np.concatenate([length, length[:, ::-1]], axis=-1)
            self.half_rest_tangent = np.concatenate([rest_tangent, -rest_tangent[:, ::-1]], axis=-2)
            difference_rows = np.concatenate([difference_rows, -difference_rows[::-1]])
            own_rows = np.concatenate([rear, front[::-1]])
        self.half_rest_length = np.asfortranarray(self.half_rest_length)
        self.half_rest_tangent = np.asfortranarray(self.half_rest_tangent)
        self.difference_rows = difference_rows.reshape(-1, m)
        self.rear_rows = own_rows.reshape(-1, m)
        self._data, self._spine_force = data, spine_force
        mass_gradient = virtual_mass_gradient(dorsal_z, data.dorsal_z_gradient, data.fluid_density)
        length_gradient = None
        if self.moving_rest:
            gradient = data.rest_xy_gradient
            length_gradient = np.einsum("bsc,sck->bsk", rest_tangent, gradient[1:] - gradient[:-1])
        front_gradient = (virtual_mass_gradient(front_z, data.front_dorsal_z_gradient, data.fluid_density)
                          if trapezoid else None)
        self.derivative_weights = derivative_weights(spine, mass_gradient, length_gradient, front_gradient)
        self._point, self._state, self._blocks = None, None, None

    # the projection's kinds and products, shared by all designs, formed when the numpy batch first needs them
    # (the compiled kernel projects through the points' banded matrices instead)
    @cached_property
    def block_kinds(self):
        data = self._data
        trapezoid = data.front_dorsal_z is not None
        single = SpineGeometry(data.rest_xy, virtual_mass(data.dorsal_z, data.fluid_density), self._spine_force,
                               virtual_mass(data.front_dorsal_z, data.fluid_density) if trapezoid else None)
        return block_kinds(single)

    @cached_property
    def block_products(self):
        rear, front = self._data.rows[:-1], self._data.rows[1:]
        return block_products(rear, front, rear, front, self.block_kinds)

    @cached_property
    def rest_products(self):
        rows, gradient = self._data.rows, self._data.rest_xy_gradient
        return block_products(rows[:-1], rows[1:], gradient[:-1], gradient[1:], self.block_kinds)

    def select(self, rows: np.ndarray) -> "BatchedThrust":
        """The term of the designs ``rows`` (indices)."""
        part = copy.copy(self)
        spine = self.spine
        part.spine = BatchedSpine(spine.rest_xy[rows], _take(spine.virtual_mass, rows), spine.spine_force,
                                  None if spine.front_mass is None else _take(spine.front_mass, rows))
        part.half_rest_length, part.half_rest_tangent = _take(self.half_rest_length, rows), _take(self.half_rest_tangent, rows)
        part.derivative_weights = tuple(None if weights is None else weights[rows] for weights in self.derivative_weights)
        part._point, part._state, part._blocks = None, None, None
        return part

    def segment_state(self, eta, eta_dot, eta_ddot) -> SegmentState:
        """The (B, n_half_segments, ...) segment state of the reduced kinematics, kept for the same point."""
        point = (eta.tobytes(), eta_dot.tobytes(), eta_ddot.tobytes())
        if point != self._point:
            scale = self.half_rest_length[..., None]
            tangent = self.half_rest_tangent + _rows_times(self.difference_rows, eta) / scale
            tangent_rate = _rows_times(self.difference_rows, eta_dot) / scale
            self._state = segment_state_of(self.half_rest_length, tangent, tangent_rate,
                                           _rows_times(self.rear_rows, eta_dot), _rows_times(self.rear_rows, eta_ddot))
            self._point, self._blocks = point, None
        return self._state

    def _jacobian_blocks(self, eta, eta_dot, eta_ddot):
        state = self.segment_state(eta, eta_dot, eta_ddot)
        if self._blocks is None:
            self._blocks = thrust_jacobian_blocks(self.spine, state)
        return self._blocks

    def force(self, eta, eta_dot, eta_ddot) -> np.ndarray:
        """Wᵀ f(W η_b, W η̇_b, W η̈_b), (B, m)."""
        force = thrust_force_of_state(self.spine, self.segment_state(eta, eta_dot, eta_ddot))
        return force.reshape(eta.shape[0], -1) @ self.rows

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """-Wᵀ (∂f/∂u, ∂f/∂u̇, ∂f/∂ü) W, each (B, m, m)."""
        batch, m = eta.shape
        projected = project_jacobians(self._jacobian_blocks(eta, eta_dot, eta_ddot), self.block_products,
                                      self.block_kinds)
        return tuple(-projected[:, slot].reshape(batch, m, m) for slot in range(3))

    def newton_part(self, factors, eta, eta_dot, eta_ddot) -> np.ndarray:
        """k_u K_t + k_v C_t + k_a M_t of the thrust for ``factors`` (k_u, k_v, k_a), (B, m, m): the segment blocks
        combined before their one projection."""
        batch, m = eta.shape
        combined = [SegmentBlocks(*(None if values is None else factor * values for values in part))
                    for factor, parts in zip(factors, self._jacobian_blocks(eta, eta_dot, eta_ddot)) for part in parts]
        return -project_jacobians((combined,), self.block_products, self.block_kinds)[:, 0].reshape(batch, m, m)

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """-Wᵀ ∂f/∂ξ_k, (B, p, m) (see ``ReducedThrust.parameter_derivative``)."""
        state = self.segment_state(eta, eta_dot, eta_ddot)
        per_parameter = SegmentState(*(np.asarray(values)[:, None] for values in state))   # broadcast over k
        thrust_k = segment_weighted_force(self.spine, per_parameter, *self.derivative_weights)   # (B, p, n, 2)
        batch, p = thrust_k.shape[:2]
        derivative = -(thrust_k.reshape(batch, p, -1) @ self.rows)
        if self.moving_rest:
            stiffness = self._jacobian_blocks(eta, eta_dot, eta_ddot)[0]
            projected = project_jacobians((stiffness,), self.rest_products, self.block_kinds)[:, 0]
            derivative -= np.swapaxes(projected.reshape(batch, -1, p), 1, 2)
        return derivative


def _rows_times(rows: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(R values_b) of every design as (B, n, 2) x-y pairs, laid out with the batch axis contiguous: numpy's
    element-wise products of the segments' 2-vectors and 2x2 blocks then loop over the designs, not over
    axes of length 2 (ten times faster at B = 100)."""
    return (rows @ values.T).T.reshape(values.shape[0], -1, 2)


def _take(values: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The designs ``rows`` of per-design values, batch axis contiguous (see ``_rows_times``)."""
    return np.asfortranarray(values[rows])
