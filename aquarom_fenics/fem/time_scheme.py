"""The generalized-α time discretisation (SPEC §6): step formulas and where the residual is evaluated.

Plain numpy arithmetic, shared by the FOM (its Newton system's time derivatives) and the
integrator of :mod:`aquarom_fenics.dynamics.integrator`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class TimeScheme:
    """Generalized-α (Chung & Hulbert 1993) with step h [s]:

        u_{n+1} = u_n + h u̇_n + h²(½ - β) ü_n + h² β ü_{n+1}
        u̇_{n+1} = u̇_n + h (1 - γ) ü_n + h γ ü_{n+1}
        r(t_{n+1-α_f}, u_{n+1-α_f}, u̇_{n+1-α_f}, ü_{n+1-α_m}) = 0,   x_{n+1-α} = (1 - α) x_{n+1} + α x_n

    so inertia is evaluated at 1 - α_m and every other force at 1 - α_f between the old and the
    new state. Newmark is α_m = α_f = 0.
    """

    time_step: float
    gamma: float
    beta: float
    alpha_m: float = 0.0
    alpha_f: float = 0.0

    @classmethod
    def newmark(cls, time_step: float, alpha: float) -> "TimeScheme":
        """γ = ½ + α_N, β = (1 + α_N)²/4: first order for α_N > 0."""
        return cls(time_step, 0.5 + alpha, (1.0 + alpha) ** 2 / 4.0)

    @classmethod
    def generalized_alpha(cls, time_step: float, rho_infinity: float) -> "TimeScheme":
        """α_m = (2ρ∞ - 1)/(ρ∞ + 1), α_f = ρ∞/(ρ∞ + 1), γ = ½ - α_m + α_f, β = ¼(1 - α_m + α_f)²:
        second order, the highest frequencies damped to the spectral radius ρ∞."""
        alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0)
        alpha_f = rho_infinity / (rho_infinity + 1.0)
        return cls(time_step, 0.5 - alpha_m + alpha_f, 0.25 * (1.0 - alpha_m + alpha_f) ** 2, alpha_m, alpha_f)

    @classmethod
    def from_solver(cls, solver) -> "TimeScheme":
        """The scheme of a scene's [solver] section."""
        if solver.integrator == "newmark":
            return cls.newmark(solver.time_step, solver.newmark_alpha)
        return cls.generalized_alpha(solver.time_step, solver.rho_infinity)

    def with_time_step(self, time_step: float) -> "TimeScheme":
        return dataclasses.replace(self, time_step=time_step)

    @property
    def stiffness_factor(self) -> float:
        """∂u_{n+1-α_f}/∂u_{n+1} = 1 - α_f."""
        return 1.0 - self.alpha_f

    @property
    def velocity_factor(self) -> float:
        """∂u̇_{n+1-α_f}/∂u_{n+1} = (1 - α_f) γ / (β h)."""
        return (1.0 - self.alpha_f) * self.gamma / (self.beta * self.time_step)

    @property
    def acceleration_factor(self) -> float:
        """∂ü_{n+1-α_m}/∂u_{n+1} = (1 - α_m) / (β h²)."""
        return (1.0 - self.alpha_m) / (self.beta * self.time_step ** 2)

    def predict(self, u, v, a):
        """Displacement and velocity with ü_{n+1} = 0."""
        h = self.time_step
        return u + h * v + h * h * (0.5 - self.beta) * a, v + h * (1.0 - self.gamma) * a

    def correct(self, u_new, u_predicted, v_predicted):
        """(u̇_{n+1}, ü_{n+1}) consistent with a trial u_{n+1}."""
        a_new = (u_new - u_predicted) * (1.0 / (self.beta * self.time_step ** 2))
        return v_predicted + self.gamma * self.time_step * a_new, a_new

    def evaluation_point(self, time_new: float, old, new):
        """(t_{n+1-α_f}, u_{n+1-α_f}, u̇_{n+1-α_f}, ü_{n+1-α_m}) where the residual is evaluated."""
        (u_old, v_old, a_old), (u_new, v_new, a_new) = old, new
        return (time_new - self.alpha_f * self.time_step, between(u_old, u_new, self.alpha_f),
                between(v_old, v_new, self.alpha_f), between(a_old, a_new, self.alpha_m))


def between(old, new, alpha: float):
    """x_{n+1-α} = (1 - α) x_{n+1} + α x_n (x_{n+1} itself when α = 0)."""
    return new if alpha == 0.0 else (1.0 - alpha) * new + alpha * old
