"""Reduced generalized-α Newton integration of a PROM at a design ξ, with sensitivities dη/dξ (SPEC §8–§9).

Direct differentiation of the discrete step r(t_{n+1-α_f}, η_{n+1-α_f}, η̇_{n+1-α_f}, η̈_{n+1-α_m}; ξ) = 0
(Brüls & Eberhard): after each converged (sub-)step one linear solve with the Newton matrix
S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t of that step (``propagate_sensitivity``).
"""
from __future__ import annotations

import time as clock
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.linalg

from aquarom_fenics.dynamics.integrator import IntegrationStopped, NewtonSettings, StepReport, TimeScheme, between, integrate
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.thrust import SpineGeometry, thrust_force, thrust_force_per_virtual_mass, thrust_jacobians, virtual_mass
from aquarom_fenics.dynamics.trajectory import Trajectory, swimming_distance, tail_amplitude, window_mask, DISTANCE_WINDOW


class ReducedSystem:
    """The PROM's tensors evaluated at one design ξ (implements ``NewtonSystem``)."""

    def __init__(self, prom: ReducedModel, scene: Scene, xi, scheme: TimeScheme, amplitude: float | None = None):
        self.prom, self.scheme = prom, scheme
        self.delta = prom.delta(xi)
        d = self.delta
        self.mass = prom.mass.at(d)
        self.k1, self.k2, self.k3 = (t.at(d) for t in (prom.stiffness_linear, prom.stiffness_quadratic, prom.stiffness_cubic))
        alpha, beta = prom.rayleigh
        self.damping = alpha * self.mass + beta * self.k1
        self.actuation_constant = prom.actuation_constant.at(d)
        self.actuation_linear = prom.actuation_linear.at(d)
        self.drag = prom.drag.at(d)
        self.amplitude = scene.actuation.amplitude if amplitude is None else amplitude
        self.frequency = scene.actuation.frequency
        self.dorsal_z = prom.dorsal_z + prom.dorsal_z_gradient @ d if d.size else prom.dorsal_z
        self.spine = SpineGeometry(prom.spine_rest_xy, virtual_mass(self.dorsal_z, prom.fluid_density),
                                   scene.fluid.spine_force)
        self.spine_rows = prom.spine_rows.reshape(-1, prom.size)            # (2 n_spine, m)
        self.com_weights = prom.mass_moment_x.at(d) / float(prom.total_mass.at(d))
        self._factors = None

    # ------------------------------------------------------------------ forces
    def activations(self, time: float) -> np.ndarray:
        """(a_left, a_right) = A sin(2π f t) (1, -1)."""
        return self.amplitude * self.unit_activations(time)

    def unit_activations(self, time: float) -> np.ndarray:
        """∂(a_left, a_right)/∂A = sin(2π f t) (1, -1)."""
        value = np.sin(2 * np.pi * self.frequency * time)
        return np.array([value, -value])

    def amplitude_derivative(self, time, eta) -> np.ndarray:
        """∂r/∂A = Σ_j (∂a_j/∂A) (b_j + B_j η)."""
        a = self.unit_activations(time)
        return a @ self.actuation_constant + np.einsum("j,jab,b->a", a, self.actuation_linear, eta)

    def internal_force(self, eta):
        """K1 η + K2 η η + K3 η η η."""
        quadratic = self.k2 @ eta
        cubic = (self.k3 @ eta) @ eta
        return self.k1 @ eta + quadratic @ eta + cubic @ eta

    def internal_tangent(self, eta):
        """K1 + 2 K2 η + 3 K3 η η (symmetric tensors)."""
        return self.k1 + 2.0 * (self.k2 @ eta) + 3.0 * ((self.k3 @ eta) @ eta)

    def actuation_force(self, time, eta):
        """f_act,r = -Σ_j a_j (b_j + B_j η)."""
        a = self.activations(time)
        return -(a @ self.actuation_constant + np.einsum("j,jab,b->a", a, self.actuation_linear, eta))

    def _spine_states(self, eta, eta_dot, eta_ddot):
        return [(self.spine_rows @ x).reshape(-1, 2) for x in (eta, eta_dot, eta_ddot)]

    def thrust_force(self, eta, eta_dot, eta_ddot):
        if not self.prom.thrust:
            return np.zeros_like(eta)
        return self.spine_rows.T @ thrust_force(self.spine, *self._spine_states(eta, eta_dot, eta_ddot)).ravel()

    def drag_force(self, eta_dot):
        """g_r v_x², v_x the head's x-velocity."""
        return self.drag * (self.prom.head_x_row @ eta_dot) ** 2

    def residual(self, time, eta, eta_dot, eta_ddot):
        inertia = self.mass @ eta_ddot
        internal = self.internal_force(eta)
        external = self.actuation_force(time, eta) + self.thrust_force(eta, eta_dot, eta_ddot) + self.drag_force(eta_dot)
        residual = inertia + self.damping @ eta_dot + internal - external
        return residual, max(self.norm(internal), self.norm(external), self.norm(inertia))

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """(K_t, C_t, M_t) = ∂r/∂(η, η̇, η̈)."""
        a = self.activations(time)
        stiffness = self.internal_tangent(eta) + np.einsum("j,jab->ab", a, self.actuation_linear)
        damping = self.damping.copy()
        mass = self.mass.copy()
        if self.prom.thrust:
            jacobians = thrust_jacobians(self.spine, *self._spine_states(eta, eta_dot, eta_ddot))
            rows = self.spine_rows
            stiffness -= rows.T @ jacobians[0] @ rows
            damping -= rows.T @ jacobians[1] @ rows
            mass -= rows.T @ jacobians[2] @ rows
        head = self.prom.head_x_row
        damping -= 2.0 * (head @ eta_dot) * np.outer(self.drag, head)
        return stiffness, damping, mass

    def set_time_step(self, scheme: TimeScheme) -> None:
        self.scheme = scheme

    def newton_matrix(self, time, eta, eta_dot, eta_ddot):
        """S = ∂r_{n+1-α}/∂η_{n+1} at the evaluation point (t, η, η̇, η̈)."""
        return newton_matrix(self.scheme, *self.tangents(time, eta, eta_dot, eta_ddot))

    def factorize(self, time, eta, eta_dot, eta_ddot):
        self._factors = scipy.linalg.lu_factor(self.newton_matrix(time, eta, eta_dot, eta_ddot))

    def solve(self, rhs):
        return scipy.linalg.lu_solve(self._factors, rhs)

    def norm(self, vector):
        return float(np.linalg.norm(vector))

    # ------------------------------------------------------------------ ξ-derivatives
    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """∂r/∂ξ_k at fixed (η, η̇, η̈), shape (m, p)."""
        prom, d = self.prom, self.delta
        p = prom.n_parameters
        if p == 0 or prom.mass.first is None:
            return np.zeros((eta.size, p))
        alpha, beta = prom.rayleigh
        mass_k = prom.mass.gradient(d)
        a = self.activations(time)
        columns = (mass_k @ eta_ddot + (alpha * mass_k + beta * prom.stiffness_linear.gradient(d)) @ eta_dot
                   + self.internal_force_gradient(eta)
                   + np.einsum("j,kja->ka", a, prom.actuation_constant.gradient(d))
                   + np.einsum("j,kjab,b->ka", a, prom.actuation_linear.gradient(d), eta)
                   - prom.drag.gradient(d) * (prom.head_x_row @ eta_dot) ** 2)
        if prom.thrust:
            per_mass = thrust_force_per_virtual_mass(self.spine, *self._spine_states(eta, eta_dot, eta_ddot))
            # m̃ = (π/4) ρ_w (2 z_d)² ⇒ ∂m̃/∂ξ_k = 2π ρ_w z_d ∂z_d/∂ξ_k
            mass_gradient = 2 * np.pi * prom.fluid_density * self.dorsal_z[:, None] * prom.dorsal_z_gradient
            thrust_k = np.einsum("snc,sk->knc", per_mass, mass_gradient).reshape(p, -1)
            columns -= thrust_k @ self.spine_rows
        return columns.T

    def internal_force_gradient(self, eta) -> np.ndarray:
        """∂f_int,r/∂ξ_k = K1_k η + K2_k η η + K3_k η η η, shape (p, m)."""
        d = self.delta
        k1_k, k2_k, k3_k = (t.gradient(d) for t in (self.prom.stiffness_linear, self.prom.stiffness_quadratic,
                                                     self.prom.stiffness_cubic))
        return (k1_k @ eta + np.einsum("kabc,b,c->ka", k2_k, eta, eta)
                + np.einsum("kabcd,b,c,d->ka", k3_k, eta, eta, eta))

    def observables(self, eta) -> tuple[float, float, float]:
        """(head x, tail y, centre-of-mass x) [m]."""
        return float(self.prom.head_x_row @ eta), float(self.prom.tail_y_row @ eta), float(self.com_weights @ eta)

    def com_weights_gradient(self) -> np.ndarray:
        """∂(c(ξ))/∂ξ_k for com_x = c(ξ)·η, c = n(ξ)/mass(ξ); shape (p, m)."""
        prom, d = self.prom, self.delta
        if prom.n_parameters == 0 or prom.mass_moment_x.first is None:
            return np.zeros((prom.n_parameters, prom.size))
        # c = n / m_total ⇒ ∂c/∂ξ_k = (∂n/∂ξ_k - c ∂m_total/∂ξ_k) / m_total
        total = float(prom.total_mass.at(d))
        return (prom.mass_moment_x.gradient(d) - np.outer(prom.total_mass.gradient(d), self.com_weights)) / total


@dataclass
class ReducedResult:
    trajectory: Trajectory
    distance: float | None
    tail_amplitude: float | None
    completed: bool
    wall_time: float
    error: str | None = None
    cut_steps: int = 0                            # sub-steps shorter than h taken by the step control
    states: np.ndarray | None = None              # (n_samples, m) η
    sensitivities: np.ndarray | None = None       # (n_samples, m, p) dη/dξ
    distance_gradient: np.ndarray | None = None   # (p,) dd/dξ
    timings: dict = field(default_factory=dict)

    def summary(self) -> dict:
        iterations = np.asarray(self.trajectory.newton_iterations[1:])
        return {"distance": self.distance, "tail_amplitude": self.tail_amplitude, "completed": self.completed,
                "error": self.error, "wall_time": self.wall_time, "steps": len(self.trajectory) - 1,
                "cut_steps": self.cut_steps,
                "mean_newton_iterations": float(iterations.mean()) if iterations.size else None,
                "distance_gradient": None if self.distance_gradient is None else self.distance_gradient.tolist(),
                "timings": self.timings}


def simulate_reduced(prom: ReducedModel, scene: Scene, xi=None, sensitivities: bool = False,
                     amplitude: float | None = None, amplitude_sensitivity: bool = False) -> ReducedResult:
    """Integrate the PROM at design ξ over the scene's horizon.

    With ``sensitivities`` the result carries dη/dξ (and dd/dξ); with ``amplitude_sensitivity``
    one more column, d/dA of the actuation amplitude (``amplitude`` overrides the scene's A).
    """
    from aquarom_fenics.dynamics.diagnostics import newton_failure_hints
    from aquarom_fenics.dynamics.simulate import check_time_grid

    started = clock.perf_counter()
    n_steps = check_time_grid(scene)
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    scheme = TimeScheme.from_solver(scene.solver)
    system = ReducedSystem(prom, scene, xi, scheme, amplitude)
    m = prom.size
    columns = (prom.n_parameters if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    trajectory = Trajectory()
    states = [np.zeros(m)]
    zero = np.zeros(m)
    trajectory.append(0.0, *system.observables(zero), 0)
    sensitivity = [np.zeros((m, columns))] * 3
    sensitivity_history = [np.zeros((m, columns))]
    cut_steps = 0

    def advance_sensitivity(step_scheme: TimeScheme, time: float, old, new):
        """(η', η̇', η̈') follow every accepted (sub-)step."""
        nonlocal sensitivity
        point = step_scheme.evaluation_point(time, old, new)
        derivative = np.zeros((m, 0))
        if sensitivities:
            derivative = system.parameter_derivative(*point)
        if amplitude_sensitivity:
            derivative = np.column_stack([derivative, system.amplitude_derivative(point[0], point[1])])
        sensitivity = propagate_sensitivity(system, step_scheme, point, sensitivity, derivative)

    def record(report: StepReport, eta, eta_dot, eta_ddot):
        nonlocal cut_steps
        cut_steps = report.cut_steps
        trajectory.append(report.time, *system.observables(eta), report.iterations)
        states.append(eta.copy())
        if columns:
            sensitivity_history.append(sensitivity[0].copy())

    error = None
    try:
        integrate(system, scheme, n_steps, (zero, zero, zero), NewtonSettings.from_solver(scene.solver), record,
                  explain=lambda: "; ".join(newton_failure_hints(scene)),
                  on_step=advance_sensitivity if columns else None)
    except IntegrationStopped as failure:
        error, cut_steps = str(failure), failure.cut_steps
    arrays = trajectory.arrays()
    completed = error is None
    result = ReducedResult(
        trajectory=trajectory, completed=completed, error=error, states=np.array(states), cut_steps=cut_steps,
        distance=swimming_distance(arrays["time"], arrays["com_x"]) if completed else None,
        tail_amplitude=tail_amplitude(arrays["time"], arrays["tail_y"]) if completed else None,
        wall_time=clock.perf_counter() - started)
    if columns and completed:
        result.sensitivities = np.array(sensitivity_history)
        weights_gradient = system.com_weights_gradient() if sensitivities else np.zeros((0, m))
        if amplitude_sensitivity:
            weights_gradient = np.vstack([weights_gradient, np.zeros(m)])
        result.distance_gradient = distance_gradient(system, arrays["time"], result.states, result.sensitivities,
                                                     weights_gradient)
    return result


def newton_matrix(scheme: TimeScheme, stiffness, damping, mass) -> np.ndarray:
    """S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t."""
    return scheme.stiffness_factor * stiffness + scheme.velocity_factor * damping + scheme.acceleration_factor * mass


def propagate_sensitivity(system: ReducedSystem, scheme: TimeScheme, point, previous, parameter_derivative):
    """(η', η̇', η̈')_{n+1} from ``previous`` = (η', η̇', η̈')_n by differentiating the converged step.

    d/dξ of r(t_{n+1-α_f}, η_{n+1-α_f}, η̇_{n+1-α_f}, η̈_{n+1-α_m}; ξ) = 0 with the scheme's kinematics,
    tangents (K_t, C_t, M_t) and ∂r/∂ξ = ``parameter_derivative`` (shape (m, columns)) at the
    evaluation ``point``, and (η'_p, η̇'_p) = predict(η'_n, η̇'_n, η̈'_n), v_f = (1 - α_f)γ/(βh),
    a_f = (1 - α_m)/(βh²):

        S η'_{n+1} = -∂r/∂ξ - α_f K_t η'_n - C_t ((1 - α_f) η̇'_p + α_f η̇'_n - v_f η'_p)
                     + a_f M_t η'_p - α_m M_t η̈'_n
    """
    stiffness, damping, mass = system.tangents(*point)
    u_old, v_old, a_old = previous
    u_predicted, v_predicted = scheme.predict(*previous)
    rhs = (-parameter_derivative
           - damping @ (between(v_old, v_predicted, scheme.alpha_f) - scheme.velocity_factor * u_predicted)
           + scheme.acceleration_factor * (mass @ u_predicted))
    if scheme.alpha_f:
        rhs -= scheme.alpha_f * (stiffness @ u_old)
    if scheme.alpha_m:
        rhs -= scheme.alpha_m * (mass @ a_old)
    u_new = np.linalg.solve(newton_matrix(scheme, stiffness, damping, mass), rhs)
    v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
    return u_new, v_new, a_new


def distance_gradient(system: ReducedSystem, time, states, sensitivities, weights_gradient) -> np.ndarray:
    """dd/dξ of d = mean_window c(ξ)·η: mean of (∂c/∂ξ) η + c S over the last 0.1 s."""
    mask = window_mask(time, DISTANCE_WINDOW)
    per_sample = states[mask] @ weights_gradient.T + np.einsum("m,smk->sk", system.com_weights, sensitivities[mask])
    return per_sample.mean(axis=0)


FLOQUET_LIMIT = 1.01
"""Largest |μ| of the one-period transition matrix accepted as stable: a perturbation may grow by at most
1 % per actuation period (the gait at the end of a 2 s horizon is periodic only up to its start-up transient;
the nominal fish measures |μ| ≈ 1, the rigid translation)."""


class Stability(NamedTuple):
    """Verdict of :func:`reduced_stability`: ``stable`` and the reason, one line."""

    stable: bool
    reason: str


def transition_matrix(system: ReducedSystem, scheme: TimeScheme, n_steps: int, settings: NewtonSettings,
                      window_start: float, state=None) -> np.ndarray:
    """Φ = ∂s(T)/∂s(t_w) ∈ R^{3m×3m} of s = (η, η̇, η̈) over [t_w, T] along the run from ``state`` (rest).

    Φ = Π_n ∂s_{n+1}/∂s_n over the (sub-)steps that start at or after t_w = ``window_start``, each the
    exact derivative of the converged step, ``propagate_sensitivity`` with ∂r/∂ξ = 0. Raises
    :class:`IntegrationStopped` if the run stops.
    """
    m = system.prom.size
    identity = np.eye(3 * m)
    columns = [identity[:m], identity[m:2 * m], identity[2 * m:]]     # ∂(η, η̇, η̈)/∂s(t_w)

    def advance(step_scheme: TimeScheme, time: float, old, new):
        nonlocal columns
        if time - step_scheme.time_step >= window_start - 1e-9 * step_scheme.time_step:
            point = step_scheme.evaluation_point(time, old, new)
            columns = propagate_sensitivity(system, step_scheme, point, columns, np.zeros((m, 3 * m)))

    zero = np.zeros(m)
    integrate(system, scheme, n_steps, (zero, zero, zero) if state is None else state, settings,
              lambda *_: None, on_step=advance)
    return np.vstack(columns)


def reduced_stability(prom: ReducedModel, scene: Scene, xi=None, amplitude: float | None = None,
                      limit: float = FLOQUET_LIMIT) -> Stability:
    """Is the PROM's gait at design ξ (amplitude A) stable? Floquet test of the discrete reduced system.

    The state of a step is s = (η, η̇, η̈). The transition matrix Φ of the last actuation period
    [T - 1/f, T] (the whole horizon if T < 1/f; judge horizons of two periods or more, the start-up
    from rest is no periodic gait) along the converged trajectory (:func:`transition_matrix`):

        stable ⇔ ρ(Φ) = max |μ_i(Φ)| ≤ limit

    A perturbation of the periodic gait is multiplied by μ each period: |μ| > 1 is a growing mode of
    the model (physical, e.g. energy fed by the thrust, or numerical). The rigid translation along x
    gives μ = 1. A PROM run that stops is unstable with its stop message as the reason.
    """
    from aquarom_fenics.dynamics.simulate import check_time_grid

    n_steps = check_time_grid(scene)
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    scheme = TimeScheme.from_solver(scene.solver)
    system = ReducedSystem(prom, scene, xi, scheme, amplitude)
    m = prom.size
    window_start = max(scene.solver.duration - 1.0 / scene.actuation.frequency, 0.0)
    try:
        transition = transition_matrix(system, scheme, n_steps, NewtonSettings.from_solver(scene.solver),
                                       window_start)
    except IntegrationStopped as failure:
        return Stability(False, f"unstable: the PROM stops ({failure})")
    if not np.all(np.isfinite(transition)):
        return Stability(False, "unstable: the one-period transition matrix is not finite")
    multipliers, vectors = np.linalg.eig(transition)
    largest = int(np.argmax(np.abs(multipliers)))
    radius = float(np.abs(multipliers[largest]))
    period = scene.solver.duration - window_start
    if radius <= limit:
        return Stability(True, f"stable: largest Floquet multiplier |μ| = {radius:.4f} over [{window_start:g}, "
                               f"{scene.solver.duration:g}] s (limit {limit:g})")
    coordinate = int(np.argmax(np.abs(vectors[:m, largest])))
    return Stability(False, f"unstable: a perturbation grows by |μ| = {radius:.4g} per {period:g} s "
                            f"(growth rate {np.log(radius) / period:.3g} 1/s), mostly along basis vector "
                            f"{prom.labels[coordinate]}")
