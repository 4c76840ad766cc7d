"""What a force term provides to the full and the reduced model (SPEC §5, §8).

The equations of motion are a sum of terms,

    r = M ü + C u̇ + f_int(u) - f_act(u, t) - f_thrust(u, u̇, ü) - f_drag(u̇) = 0,

one module per term: ``elastic`` (f_int, SVK), ``muscle`` (f_act), ``inertia`` (M ü + C u̇ with
Rayleigh damping C = α M + β K_0), ``drag`` (f_drag = g v_x²) and ``thrust`` (Lighthill, with
``thrust_full_order``, ``thrust_reduced``). On the FOM a term assembles its part of r and, where it
has one, of the Newton matrix S = k_u ∂r/∂u + k_v ∂r/∂u̇ + k_a ∂r/∂ü (``add_newton_matrix``; the
FOM sums them), and projects itself on a basis V into reduced tensors (``reduce(projector)``),
Taylor polynomials in Δξ = ξ - ξ_c. The reduced model evaluates those tensors at a design ξ
(``tensors.at(Δξ)``) into a :class:`ReducedTerm`.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np


class ReducedTerm(Protocol):
    """A term of the reduced model at one design ξ; η, η̇, η̈ are (m,) arrays."""

    def residual(self, time: float, eta: np.ndarray, eta_dot: np.ndarray, eta_ddot: np.ndarray) -> np.ndarray:
        """Its part of r_r, (m,)."""

    def tangents(self, time: float, eta: np.ndarray, eta_dot: np.ndarray, eta_ddot: np.ndarray):
        """Its parts of (K_t, C_t, M_t) = ∂r_r/∂(η, η̇, η̈), each (m, m) or None where it has none."""

    def parameter_derivative(self, time: float, eta: np.ndarray, eta_dot: np.ndarray,
                             eta_ddot: np.ndarray) -> np.ndarray:
        """Its part of ∂r_r/∂ξ_k at fixed (η, η̇, η̈), (p, m)."""
