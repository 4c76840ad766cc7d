"""Newmark time integration with Newton iterations (SPEC §6), shared by the FOM and the PROM.

The integrator works on plain numpy arrays (for the FOM: the owned dofs of this rank) and asks
a :class:`NewtonSystem` for residuals and solves, so that models stay replaceable.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from .errors import SolverError


@dataclass(frozen=True)
class NewmarkScheme:
    """γ = ½ + α_N, β = (1 + α_N)²/4 with step h [s].

    u_{n+1} = u_n + h u̇_n + h²(½ - β) ü_n + h² β ü_{n+1}
    u̇_{n+1} = u̇_n + h (1 - γ) ü_n + h γ ü_{n+1}
    """

    time_step: float
    gamma: float
    beta: float

    @classmethod
    def with_damping(cls, time_step: float, alpha: float) -> "NewmarkScheme":
        return cls(time_step, 0.5 + alpha, (1.0 + alpha) ** 2 / 4.0)

    @property
    def velocity_factor(self) -> float:
        """∂u̇_{n+1}/∂u_{n+1} = γ / (β h)."""
        return self.gamma / (self.beta * self.time_step)

    @property
    def acceleration_factor(self) -> float:
        """∂ü_{n+1}/∂u_{n+1} = 1 / (β h²)."""
        return 1.0 / (self.beta * self.time_step ** 2)

    def predict(self, u, v, a):
        """Displacement and velocity with ü_{n+1} = 0."""
        h = self.time_step
        return u + h * v + h * h * (0.5 - self.beta) * a, v + h * (1.0 - self.gamma) * a

    def correct(self, u_new, u_predicted, v_predicted):
        """(u̇_{n+1}, ü_{n+1}) consistent with a trial u_{n+1}."""
        a_new = (u_new - u_predicted) * self.acceleration_factor
        return v_predicted + self.gamma * self.time_step * a_new, a_new


class NewtonSystem(Protocol):
    """What the integrator needs from a model at time t and state (u, u̇, ü)."""

    def residual(self, time: float, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, float]:
        """r = M ü + C u̇ + f_int - f_ext (zero on fixed dofs) and the force scale of the test."""

    def factorize(self, time: float, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Assemble and factorise S = K_t + (γ/(βh)) C_t + (1/(βh²)) M_t at this state."""

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """S⁻¹ rhs with the current factors."""

    def norm(self, vector: np.ndarray) -> float:
        """Global Euclidean norm."""


@dataclass
class NewtonSettings:
    tolerance: float = 1e-6
    max_iterations: int = 30
    contraction_to_refactor: float = 0.25
    iterations_per_factorization: int = 4
    force_floor: float = 1e-12


@dataclass
class StepReport:
    step: int
    time: float
    iterations: int
    factorizations: int


Observer = Callable[[StepReport, np.ndarray, np.ndarray, np.ndarray], None]


def integrate(system: NewtonSystem, scheme: NewmarkScheme, n_steps: int, state, settings: NewtonSettings,
              observe: Observer, explain: Callable[[], str] | None = None):
    """Integrate from ``state = (u, u̇, ü)`` at t = 0 over ``n_steps`` steps.

    Modified Newton: the factors of S are kept across iterations and steps and refreshed when an
    iteration contracts the residual by less than ``contraction_to_refactor`` or when they have
    served ``iterations_per_factorization`` iterations of the current step; the converged answer
    satisfies the same test ‖r‖ ≤ tol · scale whatever the factors. A step that does not converge
    in ``max_iterations``, yields non-finite values or whose linear solve fails (the system raises
    :class:`SolverError`) raises :class:`SolverError` naming the time, with the relative residuals
    of the step, the system's ``linear_solve_status()`` if it has one, and the text of
    ``explain()`` (called only then) as hints, all on one line; ``observe`` has seen every
    converged step before that.
    """
    u, v, a = (np.array(x, dtype=float) for x in state)
    have_factors = False
    for step in range(1, n_steps + 1):
        time = step * scheme.time_step
        u_predicted, v_predicted = scheme.predict(u, v, a)
        u_new = u_predicted.copy()
        factorizations = 0
        iterations_with_factors = 0
        previous_norm = np.inf
        history = []
        where = f"t = {time:.4g} s (step {step} of {n_steps})"
        kept_until = time - scheme.time_step
        for iteration in range(settings.max_iterations + 1):
            v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
            residual, scale = system.residual(time, u_new, v_new, a_new)
            residual_norm = system.norm(residual)
            history.append(residual_norm / max(scale, settings.force_floor))
            if not np.isfinite(residual_norm):
                raise SolverError(failure_message(f"non-finite residual at {where}, Newton iteration {iteration}",
                                                  history, kept_until, system, explain))
            if residual_norm <= settings.tolerance * max(scale, settings.force_floor):
                break
            if iteration == settings.max_iterations:
                raise SolverError(failure_message(f"Newton did not converge at {where} in {settings.max_iterations} "
                                                  "iterations", history, kept_until, system, explain))
            slow = residual_norm > settings.contraction_to_refactor * previous_norm
            worn = iterations_with_factors >= settings.iterations_per_factorization
            try:
                if not have_factors or slow or worn:
                    system.factorize(time, u_new, v_new, a_new)
                    have_factors = True
                    factorizations += 1
                    iterations_with_factors = 0
                iterations_with_factors += 1
                previous_norm = residual_norm
                u_new = u_new - system.solve(residual)
            except SolverError as failure:
                raise SolverError(failure_message(f"{failure} at {where}, Newton iteration {iteration}",
                                                  history, kept_until, system, explain)) from None
        u, v, a = u_new, v_new, a_new
        observe(StepReport(step, time, iteration, factorizations), u, v, a)
    return u, v, a


def failure_message(what: str, history: list[float], kept_until: float, system, explain) -> str:
    """One line: what stopped where, the step's relative residuals, the last linear solve,
    the time [s] up to which results are kept, and the hints of ``explain()``."""
    parts = [what, "relative residuals " + ", ".join(f"{value:.2e}" for value in history[-6:])]
    linear_solve_status = getattr(system, "linear_solve_status", None)
    status = linear_solve_status() if linear_solve_status is not None else ""
    if status and status not in what:
        parts.append(f"last linear solve: {status}")
    parts.append(f"results kept up to t = {kept_until:.4g} s")
    hints = " ".join(explain().split()) if explain is not None else ""
    if hints:
        parts.append(f"hints: {hints}")
    return "; ".join(parts)
