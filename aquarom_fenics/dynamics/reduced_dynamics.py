"""Reduced generalized-α Newton integration of a PROM at a design ξ, with sensitivities dη/dξ (SPEC §8–§9).

Direct differentiation of the discrete step r(t_{n+1-α_f}, η_{n+1-α_f}, η̇_{n+1-α_f}, η̈_{n+1-α_m}; ξ) = 0
(Brüls & Eberhard): after each converged (sub-)step one linear solve with the Newton matrix
S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t of that step (``propagate_sensitivity``).
"""
from __future__ import annotations

import functools
import math
import time as clock
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.linalg
from threadpoolctl import ThreadpoolController

from aquarom_fenics.dynamics.integrator import IntegrationStopped, NewtonSettings, StepReport, TimeScheme, integrate
from aquarom_fenics.fem.time_scheme import between
from aquarom_fenics.physics.muscle import ActivationLaw
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.dynamics.trajectory import (Trajectory, swimming_distance, tail_amplitude, window_mask,
                                                DISTANCE_WINDOW, last_stroke_start)



@functools.cache
def blas_thread_pools() -> ThreadpoolController:
    """The thread pools of the loaded libraries, inspected once (numpy's and scipy's BLAS are loaded on
    import): ``threadpool_limits`` would inspect them again on every call."""
    return ThreadpoolController()


def one_blas_thread(function):
    """Run ``function`` with one BLAS thread. The reduced systems are m × m with m ≈ 10, far too
    small for a threaded BLAS to gain: its threads' start-up and waits cost more than the solve."""
    @functools.wraps(function)
    def single_threaded(*args, **kwargs):
        with blas_thread_pools().limit(limits=1, user_api="blas"):
            return function(*args, **kwargs)
    return single_threaded

class ReducedSystem:
    """The PROM's terms evaluated at one design ξ (implements ``NewtonSystem``).

    r_r = M_r η̈ + C_r η̇ + s_E f_int,r(η) - f_act,r(η, t) - s_T f_thrust,r(η, η̇, η̈) - s_D f_drag,r(η̇); its
    tangents and ξ-derivative are the sums of the terms' parts. The factors s_E, s_T, s_D (``elastic_scale``,
    ``thrust_scale``, ``drag_scale``) are 1 but for a calibration's system (``calibration.parameters``); a term
    whose factor is 1 is not multiplied (the results are those of the plain sum, bit for bit).
    """

    def __init__(self, prom: ReducedModel, scene: Scene, xi, scheme: TimeScheme, amplitude: float | None = None):
        self.prom, self.scheme = prom, scheme
        self.delta = d = prom.delta(xi)
        self.elastic = prom.elastic.at(d)
        self.inertia = prom.inertia.at(d, prom.elastic.linear, self.elastic.k1)
        self.muscle = prom.muscle.at(d, scene.actuation.amplitude if amplitude is None else amplitude,
                                     ActivationLaw.of(scene))
        self.thrust = prom.thrust.at(d, scene.fluid.spine_force) if prom.thrust is not None else None
        self.drag = prom.drag.at(d) if prom.drag is not None else None
        self.terms = [term for term in (self.elastic, self.muscle, self.inertia, self.thrust, self.drag)
                      if term is not None]
        self.com_weights = self.inertia.com_weights
        self.com_y_weights = self.inertia.com_y_weights
        self.elastic_scale = self.thrust_scale = self.drag_scale = 1.0
        self._factors = None

    # ------------------------------------------------------------------ forces
    def amplitude_derivative(self, time, eta) -> np.ndarray:
        """∂r/∂A of the actuation amplitude."""
        return self.muscle.amplitude_derivative(time, eta)

    def internal_force(self, eta):
        return self.elastic.force(eta)

    def residual(self, time, eta, eta_dot, eta_ddot):
        inertia = self.inertia.mass @ eta_ddot
        internal = scaled(self.elastic_scale, self.elastic.force(eta))
        external = self.muscle.force(time, eta)
        if self.thrust is not None:
            external = external + scaled(self.thrust_scale, self.thrust.force(eta, eta_dot, eta_ddot))
        if self.drag is not None:
            external = external + scaled(self.drag_scale, self.drag.force(eta_dot))
        residual = inertia + self.inertia.damping @ eta_dot + internal - external
        return residual, max(self.norm(internal), self.norm(external), self.norm(inertia))

    def term_scale(self, term) -> float:
        """The factor of ``term``'s force: s_E, s_T, s_D, or 1."""
        return {id(self.elastic): self.elastic_scale, id(self.thrust): self.thrust_scale,
                id(self.drag): self.drag_scale}.get(id(term), 1.0)

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """(K_t, C_t, M_t) = ∂r/∂(η, η̇, η̈), the sums of the terms' parts, each by its factor (new arrays)."""
        parts = [(self.term_scale(term), term.tangents(time, eta, eta_dot, eta_ddot)) for term in self.terms]
        return tuple(sum_of_matrices([scaled(scale, part[slot]) for scale, part in parts if part[slot] is not None],
                                     eta.size)
                     for slot in range(3))

    def set_time_step(self, scheme: TimeScheme) -> None:
        self.scheme = scheme

    def newton_matrix(self, time, eta, eta_dot, eta_ddot):
        """S = ∂r_{n+1-α}/∂η_{n+1} at the evaluation point (t, η, η̇, η̈)."""
        return newton_matrix(self.scheme, *self.tangents(time, eta, eta_dot, eta_ddot))

    def factorize(self, time, eta, eta_dot, eta_ddot):
        self._factors = scipy.linalg.lu_factor(self.newton_matrix(time, eta, eta_dot, eta_ddot))

    def solve(self, rhs):
        """S⁻¹ rhs; the factors come from a checked ``lu_factor`` and the integrator has checked the
        residual ``rhs`` to be finite, so ``lu_solve`` checks nothing again."""
        return scipy.linalg.lu_solve(self._factors, rhs, check_finite=False)

    def norm(self, vector):
        """‖x‖ = √(x·x) (what np.linalg.norm computes, without its dispatch)."""
        return math.sqrt(vector.dot(vector))

    def dot(self, left, right):
        return float(left @ right)

    # ------------------------------------------------------------------ ξ-derivatives
    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """∂r/∂ξ_k at fixed (η, η̇, η̈), shape (m, p): the sum of the terms' parts."""
        p = self.prom.n_parameters
        if p == 0 or self.prom.inertia.mass.first is None:
            return np.zeros((eta.size, p))
        return sum(term.parameter_derivative(time, eta, eta_dot, eta_ddot) for term in self.terms).T

    def internal_force_gradient(self, eta) -> np.ndarray:
        """∂f_int,r/∂ξ_k, shape (p, m)."""
        return self.elastic.force_gradient(eta)

    def observables(self, eta) -> tuple[float, float, float, float, float]:
        """(head x, tail y, centre-of-mass x, tail x, centre-of-mass y) [m]."""
        observation = self.prom.observation
        return (float(observation.head_x_row @ eta), float(observation.tail_y_row @ eta), float(self.com_weights @ eta),
                float(observation.tail_x_row @ eta), float(self.com_y_weights @ eta))

    def com_weights_gradient(self) -> np.ndarray:
        """∂c/∂ξ_k of com_x = c(ξ)·η, shape (p, m)."""
        return self.inertia.com_weights_gradient()


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
    velocities: np.ndarray | None = None          # (n_samples, m) η̇
    accelerations: np.ndarray | None = None       # (n_samples, m) η̈
    sensitivities: np.ndarray | None = None       # (n_samples, m, p) dη/dξ
    velocity_sensitivities: np.ndarray | None = None   # (n_samples, m, p) dη̇/dξ
    distance_gradient: np.ndarray | None = None   # (p,) dd/dξ
    timings: dict = field(default_factory=dict)
    strain: object = None                         # StrainReport of fem/strains.py, for a single run

    def summary(self) -> dict:
        iterations = np.asarray(self.trajectory.newton_iterations[1:])
        return {"strain": self.strain.as_dict() if self.strain is not None else None, "distance": self.distance, "tail_amplitude": self.tail_amplitude, "completed": self.completed,
                "error": self.error, "stop_reason": self.error or "completed", "wall_time": self.wall_time,
                "steps": len(self.trajectory) - 1, "cut_steps": self.cut_steps,
                "mean_newton_iterations": float(iterations.mean()) if iterations.size else None,
                "distance_gradient": None if self.distance_gradient is None else self.distance_gradient.tolist(),
                "timings": self.timings}


@one_blas_thread
def simulate_reduced(prom: ReducedModel, scene: Scene, xi=None, sensitivities: bool = False,
                     amplitude: float | None = None, amplitude_sensitivity: bool = False,
                     gait_sensitivity: bool = False) -> ReducedResult:
    """Integrate the PROM at design ξ over the scene's horizon.

    With ``sensitivities`` the result carries dη/dξ (and dd/dξ); with ``amplitude_sensitivity``
    one more column, d/dA of the actuation amplitude (``amplitude`` overrides the scene's A); with
    ``gait_sensitivity`` one more per variable of the scene's ``[gait]`` (the scene driven at the gait's
    values, ``apply_gait``; physics/gait.py), in this order: [ξ, A, gait].
    """
    from aquarom_fenics.dynamics.diagnostics import newton_failure_hints
    from aquarom_fenics.dynamics.simulate import check_time_grid

    started = clock.perf_counter()
    n_steps = check_time_grid(scene)
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    scheme = TimeScheme.from_solver(scene.solver)
    system = ReducedSystem(prom, scene, xi, scheme, amplitude)
    m = prom.size
    gait = gait_rates(scene, system) if gait_sensitivity else None
    columns = ((prom.n_parameters if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
               + (len(gait.names) if gait is not None else 0))
    trajectory = Trajectory()
    zero = np.zeros(m)
    states, velocities, accelerations = [zero], [zero], [zero]
    trajectory.append(0.0, *system.observables(zero), 0)
    sensitivity = [np.zeros((m, columns))] * 3
    sensitivity_history = [np.zeros((m, columns))]
    velocity_history = [np.zeros((m, columns))]
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
        if gait is not None:
            rates = gait.at(point[0])
            derivative = np.column_stack([derivative] + [system.muscle.amplitude_derivative_of(rates[:, q], point[1])
                                                         for q in range(rates.shape[1])])
        sensitivity = propagate_sensitivity(system, step_scheme, point, sensitivity, derivative)

    def record(report: StepReport, eta, eta_dot, eta_ddot):
        nonlocal cut_steps
        cut_steps = report.cut_steps
        trajectory.append(report.time, *system.observables(eta), report.iterations)
        states.append(eta.copy())
        velocities.append(eta_dot.copy())
        accelerations.append(eta_ddot.copy())
        if columns:
            sensitivity_history.append(sensitivity[0].copy())
            velocity_history.append(sensitivity[1].copy())

    error = None
    try:
        integrate(system, scheme, n_steps, (zero, zero, zero), NewtonSettings.reduced_settings(scene.solver), record,
                  explain=lambda: "; ".join(newton_failure_hints(scene)),
                  on_step=advance_sensitivity if columns else None)
    except IntegrationStopped as failure:
        error, cut_steps = str(failure), failure.cut_steps
    arrays = trajectory.arrays()
    completed = error is None
    result = ReducedResult(
        trajectory=trajectory, completed=completed, error=error, states=np.array(states),
        velocities=np.array(velocities), accelerations=np.array(accelerations), cut_steps=cut_steps,
        distance=swimming_distance(arrays["time"], arrays["com_x"]) if completed else None,
        tail_amplitude=tail_amplitude(arrays["time"], arrays["tail_y"]) if completed else None,
        wall_time=clock.perf_counter() - started)
    if columns and completed:
        result.sensitivities = np.array(sensitivity_history)
        result.velocity_sensitivities = np.array(velocity_history)
        weights_gradient = system.com_weights_gradient() if sensitivities else np.zeros((0, m))
        extra = int(amplitude_sensitivity) + (len(gait.names) if gait is not None else 0)
        weights_gradient = np.vstack([weights_gradient, np.zeros((extra, m))])
        result.distance_gradient = distance_gradient(system, arrays["time"], result.states, result.sensitivities,
                                                     weights_gradient)
    return result


def gait_rates(scene: Scene, system: ReducedSystem):
    """The activations' gait derivatives of a run (physics/gait.py)."""
    from aquarom_fenics.physics.gait import GaitRates

    return GaitRates(scene, system.muscle.law, system.muscle.amplitude)


def attach_strains(result: ReducedResult, prom: ReducedModel, scene: Scene, xi, fish=None) -> ReducedResult:
    """The run's largest principal strain (``fem/strains.py``): u = V η at the sampled steps on the
    FOM's mesh at the run's design (the PROM's parameters at ξ, every other shape at the building
    point; a ROM's design is its building point), logged (a warning line above the limit); ``result.strain``."""
    from mpi4py import MPI

    from aquarom_fenics.fem.strains import reduced_run_strains, report_strains
    from aquarom_fenics.geometry.fish import load_fish

    fish = fish or load_fish(scene)
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    design = prom.design_point | dict(zip(prom.shape_names, map(float, xi)))
    result.strain = reduced_run_strains(scene, fish, design, prom.basis, result.states,
                                        result.trajectory.arrays()["time"])
    if MPI.COMM_WORLD.rank == 0:
        report_strains(result.strain, warn=result.completed)
    return result


def scaled(factor: float, array: np.ndarray) -> np.ndarray:
    """factor × array, the array itself when the factor is 1."""
    return array if factor == 1.0 else factor * array


def sum_of_matrices(matrices: list[np.ndarray], size: int) -> np.ndarray:
    """Σ matrices as a new (size, size) array, zero for none."""
    if not matrices:
        return np.zeros((size, size))
    total = matrices[0] + matrices[1] if len(matrices) > 1 else matrices[0].copy()
    for matrix in matrices[2:]:
        total += matrix
    return total


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
    rhs, u_predicted, v_predicted = sensitivity_rhs(scheme, stiffness, damping, mass, previous, parameter_derivative)
    u_new = np.linalg.solve(newton_matrix(scheme, stiffness, damping, mass), rhs)
    v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
    return u_new, v_new, a_new


def sensitivity_rhs(scheme: TimeScheme, stiffness, damping, mass, previous, parameter_derivative):
    """(right-hand side, η'_p, η̇'_p) of ``propagate_sensitivity``'s step; the arrays may carry a leading batch
    axis (tangents (..., m, m), sensitivities and ∂r/∂ξ (..., m, columns))."""
    u_old, v_old, a_old = previous
    u_predicted, v_predicted = scheme.predict(*previous)
    rhs = (-parameter_derivative
           - damping @ (between(v_old, v_predicted, scheme.alpha_f) - scheme.velocity_factor * u_predicted)
           + scheme.acceleration_factor * (mass @ u_predicted))
    if scheme.alpha_f:
        rhs -= scheme.alpha_f * (stiffness @ u_old)
    if scheme.alpha_m:
        rhs -= scheme.alpha_m * (mass @ a_old)
    return rhs, u_predicted, v_predicted


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


@one_blas_thread
def reduced_stability(prom: ReducedModel, scene: Scene, xi=None, amplitude: float | None = None,
                      limit: float = FLOQUET_LIMIT, compiled: bool = True) -> Stability:
    """Is the PROM's gait at design ξ (amplitude A) stable? Floquet test of the discrete reduced system.

    The state of a step is s = (η, η̇, η̈). The transition matrix Φ of the last actuation period
    [T - 1/f, T] (the whole horizon if T < 1/f; judge horizons of two periods or more, the start-up
    from rest is no periodic gait) along the converged trajectory (:func:`transition_matrix`):

        stable ⇔ ρ(Φ) = max |μ_i(Φ)| ≤ limit

    A perturbation of the periodic gait is multiplied by μ each period: |μ| > 1 is a growing mode of
    the model (physical, e.g. energy fed by the thrust, or numerical). The rigid translation along x
    gives μ = 1. A PROM run that stops is unstable with its stop message as the reason.

    Φ comes from the compiled kernel (``floquet_kernel.compiled_transition``, the same steps to rounding) when
    ``compiled`` and it completes the run; else (and for a run whose steps must be cut) from ``transition_matrix``.
    """
    from aquarom_fenics.dynamics.floquet_kernel import compiled_transition
    from aquarom_fenics.dynamics.simulate import check_time_grid

    n_steps = check_time_grid(scene)
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    scheme = TimeScheme.from_solver(scene.solver)
    system = ReducedSystem(prom, scene, xi, scheme, amplitude)
    m = prom.size
    window_start = last_stroke_start(scene.solver.duration, scene.actuation.frequency)
    transition = compiled_transition(prom, scene, xi, amplitude, n_steps, window_start) if compiled else None
    try:
        if transition is None:
            transition = transition_matrix(system, scheme, n_steps, NewtonSettings.reduced_settings(scene.solver),
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
