"""Frozen-coefficient stability of a FOM state on a region of the body (SPEC §5–§6).

Linearised about a state (u, u̇, ü) at time t, the FOM's equations r = M ü + C u̇ + f_int - f_ext = 0 read

    M_t δü + C_t δu̇ + K_t δu = 0,   M_t = ∂r/∂ü,  C_t = ∂r/∂u̇,  K_t = ∂r/∂u

(the thrust's added mass is in M_t, its velocity Jacobian in C_t, its position Jacobian and the muscles'
stiffness in K_t). Restricted to the dofs of a region, the rest of the body held fixed, with the
coefficients frozen at the state:

- continuous: the eigenvalues λ of λ² M_t + λ C_t + K_t; a mode with Re λ > 0 grows like e^{Re λ t};
- discrete: the spectral radius ρ of generalized-α's step map (δu, δu̇, δü)_n → (δu, δu̇, δü)_{n+1}
  of that linear system at step h; ρ > 1 grows by ρ per step.

Frozen coefficients describe modes much faster than the state changes (here kHz modes of the tail
against a 1 Hz gait); the region must be small for dense eigenvalues (a few hundred nodes).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse

from aquarom_fenics.dynamics.integrator import TimeScheme


@dataclass(frozen=True)
class _TangentFactors:
    """Factors of the Newton matrix S = k_u K_t + k_v C_t + k_a M_t that pick one tangent."""

    stiffness_factor: float
    velocity_factor: float
    acceleration_factor: float


@dataclass
class LocalStability:
    """The region's frozen linearisation at one state."""

    time: float                     # [s]
    growth_rate: float              # max Re λ [1/s]
    frequency: float                # |Im λ| / 2π of that eigenvalue [Hz]
    spectral_radius: float          # ρ of the scheme's step map at the scheme's h

    def summary(self) -> dict:
        return {"time": self.time, "growth_rate": self.growth_rate, "frequency": self.frequency,
                "spectral_radius": self.spectral_radius}


def tangents(model, time: float, u, v, a) -> tuple[scipy.sparse.csr_matrix, ...]:
    """(K_t, C_t, M_t) of a serial FOM at a state, from its Newton matrix (fixed dofs: unit rows)."""
    if model.comm.size > 1:
        raise ValueError("the local stability analysis runs on one rank")
    scheme = model.scheme
    matrices = []
    try:
        for factors in ((1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (1.0, 0.0, 1.0)):
            model.set_time_step(_TangentFactors(*factors))
            rows, columns, values = model.assemble_newton_matrix(time, u, v, a).getValuesCSR()
            matrices.append(scipy.sparse.csr_matrix((values.copy(), columns.copy(), rows.copy())))
    finally:
        model.set_time_step(scheme)
    stiffness, with_damping, with_mass = matrices
    return stiffness, with_damping - stiffness, with_mass - stiffness


def region_dofs(model, center_node: int, radius: float) -> np.ndarray:
    """Free dofs of the nodes within ``radius`` [m] of input node ``center_node`` (rest shape)."""
    positions = model.rest_points[model.layout.owned_nodes]
    near = np.flatnonzero(np.linalg.norm(positions - model.rest_points[center_node], axis=1) < radius)
    dofs = (3 * near[:, None] + np.arange(3)).ravel()
    return np.setdiff1d(dofs, model.fixed_dofs)


def pencil_eigenvalues(stiffness: np.ndarray, damping: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """λ with (λ² M + λ C + K) x = 0, from the companion pencil [[0, I], [-K, -C]] - λ [[I, 0], [0, M]]."""
    n = stiffness.shape[0]
    identity, zero = np.eye(n), np.zeros((n, n))
    eigenvalues = scipy.linalg.eigvals(np.block([[zero, identity], [-stiffness, -damping]]),
                                       np.block([[identity, zero], [zero, mass]]))
    return eigenvalues[np.isfinite(eigenvalues)]


def step_matrix(stiffness: np.ndarray, damping: np.ndarray, mass: np.ndarray, scheme: TimeScheme) -> np.ndarray:
    """G with (δu, δu̇, δü)_{n+1} = G (δu, δu̇, δü)_n: one step of the scheme (its own predictor,
    corrector and evaluation point) on M ü + C u̇ + K u = 0, whose Newton step is exact:
    u_{n+1} = ũ - S⁻¹ r(ũ), S = k_a M + k_v C + k_u K, ũ the predictor."""
    n = stiffness.shape[0]
    old = tuple(np.hstack([np.eye(n) if block == k else np.zeros((n, n)) for block in range(3)]) for k in range(3))
    u_predicted, v_predicted = scheme.predict(*old)
    _, u_point, v_point, a_point = scheme.evaluation_point(
        0.0, old, (u_predicted, v_predicted, np.zeros_like(u_predicted)))
    residual = mass @ a_point + damping @ v_point + stiffness @ u_point
    newton = scheme.acceleration_factor * mass + scheme.velocity_factor * damping + scheme.stiffness_factor * stiffness
    u_new = u_predicted - np.linalg.solve(newton, residual)
    return np.vstack([u_new, *scheme.correct(u_new, u_predicted, v_predicted)])


def local_stability(model, time: float, u, v, a, dofs: np.ndarray, scheme: TimeScheme) -> LocalStability:
    """The frozen linearisation of ``model`` at (t, u, u̇, ü) on ``dofs``: fastest growth and ρ at h."""
    region = np.ix_(dofs, dofs)
    stiffness, damping, mass = (matrix[region].toarray() for matrix in tangents(model, time, u, v, a))
    eigenvalues = pencil_eigenvalues(stiffness, damping, mass)
    fastest = eigenvalues[np.argmax(eigenvalues.real)]
    radius = float(np.abs(np.linalg.eigvals(step_matrix(stiffness, damping, mass, scheme))).max())
    return LocalStability(time, float(fastest.real), float(abs(fastest.imag) / (2 * np.pi)), radius)
