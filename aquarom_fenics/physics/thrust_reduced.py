"""The Lighthill thrust of ``thrust.py`` in the reduced model (SPEC §8): the tensors a FOM term
projects (``ThrustTensors``) and the term at one design ξ (``ReducedThrust``).

The law is evaluated exactly on the reduced kinematics W η (W = B V for stations, V at the spine
nodes for the nodal model); its virtual mass is quadratic in ξ (the half depth d/2 linear), the rest
stations linear in ξ (B U).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aquarom_fenics.physics.thrust import (SegmentState, SpineGeometry, derivative_weights, segment_difference,
                                           segment_state_of, segment_weighted_force, thrust_force_of_state,
                                           virtual_mass, virtual_mass_gradient)
from aquarom_fenics.physics.thrust_jacobians import SegmentBlocks, thrust_jacobian_blocks
from aquarom_fenics.physics.thrust_projection import block_kinds, block_products, project_jacobians


@dataclass
class ThrustTensors:
    """What the reduced thrust needs: f_thrust,r = Wᵀ f_thrust(W η, W η̇, W η̈; ξ) with W the x-y rows of
    the kinematic points (B V for stations, V at the spine nodes for the nodal model)."""

    rows: np.ndarray                     # (n_points, 2, m): W
    rest_xy: np.ndarray                  # (n_points, 2) rest x-y at ξ_c [m]
    rest_xy_gradient: np.ndarray         # (n_points, 2, p) ∂(rest x-y)/∂ξ: B U (exact; zero for the nodal model)
    dorsal_z: np.ndarray                 # (n_segments,) half depth d/2 at ξ_c (z_dorsal - z_axis on the nodal spine)
    dorsal_z_gradient: np.ndarray        # (n_segments, p) ∂(d/2)/∂ξ (exact)
    fluid_density: float                 # c_T ρ_w [kg/m³]: the fluid density of the virtual mass (thrust_factor × ρ_w)
    front_dorsal_z: np.ndarray | None = None            # the same at the segments' front stations
    front_dorsal_z_gradient: np.ndarray | None = None   # (trapezoid rule; None: rear rule)

    def at(self, delta: np.ndarray, spine_force: str) -> "ReducedThrust":
        return ReducedThrust(self, delta, spine_force)


class ReducedThrust:
    """The reduced thrust at one design ξ (a :class:`ReducedTerm`).

    The Newton iterations evaluate the residual, the tangents and the ξ-derivative repeatedly at the same
    point: the segment state of the last point and its Jacobian blocks are kept for the next call.
    """

    def __init__(self, data: ThrustTensors, delta: np.ndarray, spine_force: str):
        self.data = data
        moves = delta.size and np.any(data.rest_xy_gradient)
        self.moving_rest = bool(moves)
        self.dorsal_z = data.dorsal_z + data.dorsal_z_gradient @ delta if delta.size else data.dorsal_z
        trapezoid = data.front_dorsal_z is not None
        front_z = None
        if trapezoid:
            front_z = data.front_dorsal_z + data.front_dorsal_z_gradient @ delta if delta.size else data.front_dorsal_z
        rest_xy = data.rest_xy + data.rest_xy_gradient @ delta if moves else data.rest_xy
        self.spine = SpineGeometry(rest_xy, virtual_mass(self.dorsal_z, data.fluid_density), spine_force,
                                   virtual_mass(front_z, data.fluid_density) if trapezoid else None)
        m = data.rows.shape[-1]
        self.rows = data.rows.reshape(-1, m)                         # (2 n_points, m): W
        rear, front = data.rows[:-1], data.rows[1:]                  # (n_segments, 2, m): W_r, W_f
        # the segment kinematics are linear in η: t = t_rest + T η, ṫ = T η̇, T = (W_f - W_r)/ℓ_0
        length = self.spine.rest_length[:, None]
        self.rest_tangent = segment_difference(self.spine.rest_xy) / length
        tangent_rows, own_rows = (front - rear) / length[:, :, None], rear
        self.half_rest_length, self.half_rest_tangent = self.spine.rest_length, self.rest_tangent
        if trapezoid:       # the half-segments of SegmentState: the mirrored half has -t, -ṫ and the front node
            self.half_rest_length = np.concatenate([self.spine.rest_length, self.spine.rest_length[::-1]])
            self.half_rest_tangent = np.concatenate([self.rest_tangent, -self.rest_tangent[::-1]])
            tangent_rows = np.concatenate([tangent_rows, -tangent_rows[::-1]])
            own_rows = np.concatenate([rear, front[::-1]])
        self.tangent_rows = tangent_rows.reshape(-1, m)
        self.rear_rows = own_rows.reshape(-1, m)                     # each half-segment's own node
        self.block_kinds = block_kinds(self.spine)
        self.block_products = block_products(rear, front, rear, front, self.block_kinds)
        mass_gradient = virtual_mass_gradient(self.dorsal_z, data.dorsal_z_gradient, data.fluid_density)
        length_gradient = None
        if self.moving_rest:
            gradient = data.rest_xy_gradient                                 # (n, 2, p): B U
            self.rest_products = block_products(rear, front, gradient[:-1], gradient[1:], self.block_kinds)
            # ∂ℓ_0/∂ξ_k = ê·(B U_k,f - B U_k,r), ê = t_rest the unit chord
            length_gradient = np.einsum("sc,sck->sk", self.rest_tangent, segment_difference(gradient))
        front_gradient = (virtual_mass_gradient(front_z, data.front_dorsal_z_gradient, data.fluid_density)
                          if trapezoid else None)
        self.derivative_weights = derivative_weights(self.spine, mass_gradient, length_gradient, front_gradient)
        self._point, self._state, self._blocks = None, None, None

    def _segment_state(self, eta, eta_dot, eta_ddot) -> SegmentState:
        """The segment state of the reduced kinematics (W η, W η̇, W η̈): t = t_rest + T η, ṫ = T η̇, the rear
        nodes' W_r η̇ and W_r η̈ (for the trapezoid rule, of the half-segments: rows made once); kept for the
        same point."""
        point = (eta.tobytes(), eta_dot.tobytes(), eta_ddot.tobytes())
        if point != self._point:
            tangent = self.half_rest_tangent + (self.tangent_rows @ eta).reshape(-1, 2)
            tangent_rate = (self.tangent_rows @ eta_dot).reshape(-1, 2)
            self._state = segment_state_of(self.half_rest_length, tangent, tangent_rate,
                                           (self.rear_rows @ eta_dot).reshape(-1, 2),
                                           (self.rear_rows @ eta_ddot).reshape(-1, 2))
            self._point, self._blocks = point, None
        return self._state

    def _jacobian_blocks(self, eta, eta_dot, eta_ddot) -> tuple[list[SegmentBlocks], ...]:
        """The Jacobians' segment blocks at the point, kept with its segment state."""
        state = self._segment_state(eta, eta_dot, eta_ddot)
        if self._blocks is None:
            self._blocks = thrust_jacobian_blocks(self.spine, state)
        return self._blocks

    def force(self, eta, eta_dot, eta_ddot) -> np.ndarray:
        """Wᵀ f(W η, W η̇, W η̈)."""
        return self.rows.T @ thrust_force_of_state(self.spine, self._segment_state(eta, eta_dot, eta_ddot)).ravel()

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """-Wᵀ (∂f/∂u, ∂f/∂u̇, ∂f/∂ü) W, from the Jacobians' segment blocks."""
        m = self.rows.shape[1]
        projected = project_jacobians(self._jacobian_blocks(eta, eta_dot, eta_ddot), self.block_products,
                                      self.block_kinds)
        return tuple(-jacobian.reshape(m, m) for jacobian in projected)

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """-Wᵀ ∂f/∂ξ_k, shape (p, m): through the virtual masses, Σ_i (∂f/∂m̃_i) ∂m̃_i/∂ξ_k, and, where the
        shape moves the rest points (x̄_rest = B(X + U ξ)), through the positions and rest lengths:
        (∂f/∂u) B U_k + Σ_s (∂f/∂ℓ_0,s) ê_s·(B U_k,f - B U_k,r)."""
        state = self._segment_state(eta, eta_dot, eta_ddot)
        thrust_k = segment_weighted_force(self.spine, state, *self.derivative_weights)      # (p, n, 2)
        p = thrust_k.shape[0]
        derivative = -(thrust_k.reshape(p, -1) @ self.rows)
        if self.moving_rest:
            stiffness = self._jacobian_blocks(eta, eta_dot, eta_ddot)[0]
            # Wᵀ (∂f/∂u) B U, (m, p)
            derivative -= project_jacobians((stiffness,), self.rest_products, self.block_kinds)[0].reshape(-1, p).T
        return derivative
