"""The calibration parameters θ of the reduced model and its sensitivities dη/dθ (issue 52, SPEC §8).

A PROM built at the scene's values θ_0 is evaluated at other values θ without a new basis, each
parameter scaling its part of the reduced equations of motion exactly:

    r(θ) = M η̈ + (α M + β s_E K_0) η̇ + s_E f_int(η) - f_act(η, t; A_eff) - s_T f_thrust - s_D f_drag,
    f_int = f_all + (s_H - 1) f_head,   K_0 = K_0,all + (s_H - 1) K_0,head

with s_E = E / E_0 (the SVK internal force and K_0 are linear in E at fixed ν: both Lamé constants
are), s_H = h / h_0 the head's stiffness factor, which scales the head cells' share f_head of the
elastic tensors only (``ReducedModel.head_elastic``, projected with ``build_prom(head_share=True)``),
α, β the Rayleigh coefficients, A_eff = k A / k_0 (the muscle force is linear in k a(t): k and A
enter only as their product k·A), s_T = c_T / c_T,0 and s_D = c_D / c_D,0 the fluid factors. The
basis (vibration modes and modal derivatives of K and M) does not depend on E, α, β, k·A or the fluid
factors, so the PROM at θ is the PROM a rebuild at θ would give on the same basis (the head's factor moves the
head's vectors of a ``head_share`` basis a little: the fit rebuilds the PROM when a parameter moved far).

The columns of ∂r/∂θ at fixed (η, η̇, η̈):

    ∂r/∂E = (f_int(η) + β K_0 η̇) / E_0        ∂r/∂α = M η̇          ∂r/∂β = s_E K_0 η̇
    ∂r/∂h = s_E (f_head(η) + β K_0,head η̇) / h_0
    ∂r/∂k = ∂r/∂A_eff · A / k_0               ∂r/∂A = ∂r/∂A_eff · k / k_0
    ∂r/∂c_T = -f_thrust / c_T,0               ∂r/∂c_D = -f_drag / c_D,0
    ∂r/∂f = A_eff Σ_j (∂u_j/∂f) (b_j + B_j η),   ∂u_j/∂f = 2π t s_j r(t) cos(2π f t + φ_j)

(the muscle force -Σ_j a_j (b_j + B_j η) with a_j = A_eff u_j(t); the last over the muscles driven at
``[actuation] frequency``, for a gait whose smooth start τ does not depend on f: ``check_fit``).

enter ``propagate_sensitivity`` (direct differentiation of each converged step).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from aquarom_fenics.dynamics.integrator import NewtonSettings, TimeScheme, integrate
from aquarom_fenics.dynamics.reduced_dynamics import ReducedSystem, one_blas_thread, propagate_sensitivity
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.elastic import ElasticTensors
from aquarom_fenics.physics.inertia import rayleigh_damping
from aquarom_fenics.physics.taylor import Taylor
from aquarom_fenics.physics.muscle import start_ramp
from aquarom_fenics.reduction.prom import ReducedModel

ALPHA, BETA = "material.rayleigh_alpha", "material.rayleigh_beta"
"""The Rayleigh coefficients' keys (C = α M + β K_0, ``physics.inertia.rayleigh_damping``)."""

HEAD = "material.head_stiffness_factor"
"""The head's stiffness factor: it scales the head cells' share of the elastic tensors only."""

CALIBRATION_KEYS = ("material.young_modulus", HEAD, ALPHA, BETA,
                    "actuation.stiffness", "actuation.amplitude", "actuation.frequency", "fluid.thrust_factor",
                    "fluid.drag_factor")
"""The scene keys a fit can take, as section.key."""

TIME_OFFSET = "time_offset"
"""Not a scene key: a constant shift τ [s] between the data's clock and the model's, y_data(t) = y_model(t + τ)
(the model at rest before t = 0). Its derivative is the model's velocity, dy/dτ = ẏ(t + τ)."""


def scene_value(scene: Scene, key: str) -> float:
    """The value of ``section.key`` in ``scene`` (0 for the time offset: the scene's clock is the data's)."""
    if key == TIME_OFFSET:
        return 0.0
    section, name = key.split(".")
    return float(getattr(getattr(scene, section), name))


def with_values(scene: Scene, values: dict[str, float]) -> Scene:
    """``scene`` with the keys ``section.key`` set to ``values`` (the time offset is not the scene's)."""
    for key, value in scene_values(values).items():
        section, name = key.split(".")
        scene = scene.replace(section, **{name: float(value)})
    return scene


def scene_values(values: dict[str, float]) -> dict[str, float]:
    """``values`` without the time offset: the scene keys the model runs with."""
    return {key: value for key, value in values.items() if key != TIME_OFFSET}


def check_keys(keys) -> None:
    """InputError, one line, for a key no fit takes, a key named twice, or both k and A."""
    for key in keys:
        if key not in CALIBRATION_KEYS and key != TIME_OFFSET:
            raise InputError(f"--fit {key}: not a calibration parameter; choose from {', '.join(CALIBRATION_KEYS)} "
                             f"or {TIME_OFFSET}")
    if len(set(keys)) != len(keys):
        raise InputError(f"--fit names a parameter twice: {', '.join(keys)}")
    if "actuation.stiffness" in keys and "actuation.amplitude" in keys:
        raise InputError("--fit actuation.stiffness and actuation.amplitude: the muscle force depends only on their "
                         "product k·A, so the data cannot tell them apart; fit one of them")


def check_fit(keys, scene: Scene) -> None:
    """InputError, one line, for a fit ``scene`` cannot take: the frequency of a gait without a muscle
    driven at it, or whose automatic smooth start lasts a quarter period (τ depends on f)."""
    from aquarom_fenics.io.scene_muscles import start_ramp_time

    if "actuation.frequency" not in keys:
        return
    if all(muscle.frequency is not None for muscle in scene.actuated_muscles):
        raise InputError("--fit actuation.frequency: every muscle of the scene has its own frequency; none is "
                         "driven at [actuation] frequency")
    if scene.actuation.start_ramp == "auto" and start_ramp_time(scene) > 0:
        raise InputError("--fit actuation.frequency: the gait's automatic smooth start lasts a quarter period, "
                         "which moves with f; give [actuation] start_ramp in seconds to fit the frequency")


def combined(tensors: ElasticTensors, head: ElasticTensors, extra: float) -> ElasticTensors:
    """tensors + extra × head, term by term (each Taylor's constant and ξ-derivatives)."""
    def add(left: Taylor, right: Taylor) -> Taylor:
        return Taylor(*(None if a is None else a + extra * b
                        for a, b in zip((left.constant, left.first, left.second),
                                        (right.constant, right.first, right.second))))
    return ElasticTensors(*(add(getattr(tensors, name), getattr(head, name)) for name in ("linear", "quadratic", "cubic")))


class CalibratedSystem(ReducedSystem):
    """The PROM (built on ``built``, the scene with θ_0) at the parameter values ``values`` {key: θ}; its
    ``parameter_derivative`` is ∂r/∂θ for ``values``' keys, in their order, shape (m, q)."""

    def __init__(self, prom: ReducedModel, built: Scene, values: dict[str, float], scheme: TimeScheme):
        check_keys(list(values))
        self.keys = list(values)
        theta = {key: scene_value(built, key) for key in CALIBRATION_KEYS} | {k: float(v) for k, v in values.items()}
        self.reference = {key: scene_value(built, key) for key in CALIBRATION_KEYS}
        self.theta = theta
        k0 = self.reference["actuation.stiffness"]
        if k0 <= 0 or self.reference["actuation.amplitude"] <= 0:
            raise InputError("calibration needs driven muscles: [actuation] stiffness and amplitude > 0")
        self.muscle_product = theta["actuation.stiffness"] * theta["actuation.amplitude"] / k0     # A_eff
        check_fit(self.keys, built)
        at_theta = with_values(built, {"actuation.frequency": theta["actuation.frequency"]})
        self.head_extra = theta[HEAD] / self.reference[HEAD] - 1.0                     # s_H - 1
        if prom.head_elastic is None and (HEAD in self.keys or self.head_extra != 0.0):
            raise InputError(f"{HEAD}: this reduced model has no head share of its elastic tensors; build it "
                             "with build_prom(..., head_share=True)")
        if self.head_extra:               # the elastic tensors at h: all + (s_H - 1) head, on the same basis
            prom = dataclasses.replace(prom, elastic=combined(prom.elastic, prom.head_elastic, self.head_extra))
        super().__init__(prom, at_theta, prom.xi_center, scheme, amplitude=self.muscle_product)
        self.head = prom.head_elastic.at(self.delta) if prom.head_elastic is not None else None
        self.driven_at_f = np.array([muscle.frequency is None for muscle in built.actuated_muscles], dtype=float)
        self.elastic_scale = theta["material.young_modulus"] / self.reference["material.young_modulus"]
        self.thrust_scale = theta["fluid.thrust_factor"] / self.reference["fluid.thrust_factor"]
        self.drag_scale = theta["fluid.drag_factor"] / self.reference["fluid.drag_factor"]
        self.rest_stiffness = self.elastic.k1                          # K_0 at E_0 and h
        self.mass = self.inertia.mass
        self.alpha, self.beta = theta[ALPHA], theta[BETA]
        if (self.alpha, self.beta, self.elastic_scale) != (*prom.inertia.rayleigh, 1.0):
            self.inertia.damping = rayleigh_damping(self.alpha, self.mass, self.beta,
                                                    self.elastic_scale * self.rest_stiffness)
        self.damping = self.inertia.damping

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """∂r/∂θ at fixed (η, η̇, η̈), shape (m, q) (the module's equations)."""
        return np.column_stack([self._derivative(key, time, eta, eta_dot, eta_ddot) for key in self.keys])

    def _derivative(self, key, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        reference, theta = self.reference, self.theta
        zero = np.zeros(eta.size)
        if key == "material.young_modulus":
            return (self.elastic.force(eta) + self.beta * (self.rest_stiffness @ eta_dot)) \
                / reference["material.young_modulus"]
        if key == HEAD:
            return self.elastic_scale * (self.head.force(eta) + self.beta * (self.head.k1 @ eta_dot)) / reference[HEAD]
        if key == ALPHA:
            return self.mass @ eta_dot
        if key == BETA:
            return self.elastic_scale * (self.rest_stiffness @ eta_dot)
        if key in ("actuation.stiffness", "actuation.amplitude"):
            other = "actuation.amplitude" if key == "actuation.stiffness" else "actuation.stiffness"
            return self.muscle.amplitude_derivative(time, eta) * theta[other] / reference["actuation.stiffness"]
        if key == "actuation.frequency":
            law = self.muscle.law
            ramp = start_ramp(time, law.ramp_time)
            rate = np.array([2.0 * np.pi * time * ramp * scale * np.cos(2.0 * np.pi * frequency * time + phase)
                             for scale, phase, frequency in zip(law.scales, law.phases, law.frequencies)])
            return self.muscle_product * self.muscle.amplitude_derivative_of(rate * self.driven_at_f, eta)
        if key == "fluid.thrust_factor":
            return zero if self.thrust is None else -self.thrust.force(eta, eta_dot, eta_ddot) / reference[key]
        if key == "fluid.drag_factor":
            return zero if self.drag is None else -self.drag.force(eta_dot) / reference[key]
        raise ValueError(key)

    def observation_rows(self) -> np.ndarray:
        """(5, m): head x, tail y, centre-of-mass x, tail x and centre-of-mass y from η
        (``dynamics.trajectory.OBSERVED``)."""
        observation = self.prom.observation
        return np.vstack([observation.head_x_row, observation.tail_y_row, self.com_weights, observation.tail_x_row,
                          self.com_y_weights])


@dataclass
class ModelSwim:
    """The PROM's observed motion at θ on the time-step grid and, with sensitivities, its θ-derivative."""

    time: np.ndarray                     # (n,) [s]
    observed: np.ndarray                 # (n, 5) the points of trajectory.OBSERVED [m] (displacements)
    velocity: np.ndarray                 # (n, 5) their velocities [m/s]
    derivative: np.ndarray | None        # (n, 5, q) d(observed)/dθ [m per unit of θ]
    velocity_derivative: np.ndarray | None   # (n, 5, q) d(velocity)/dθ
    keys: list[str]


@one_blas_thread
def simulate_parameters(prom: ReducedModel, built: Scene, values: dict[str, float],
                        sensitivities: bool = True) -> ModelSwim:
    """Integrate the PROM at θ = ``values`` over ``built``'s horizon (and time step), from rest; with
    ``sensitivities`` also dη/dθ. Raises ``IntegrationStopped`` if the run stops."""
    from aquarom_fenics.dynamics.simulate import check_time_grid

    n_steps = check_time_grid(built)
    scheme = TimeScheme.from_solver(built.solver)
    system = CalibratedSystem(prom, built, values, scheme)
    rows = system.observation_rows()
    m, q = prom.size, len(values)
    zero = np.zeros(m)
    sensitivity = [np.zeros((m, q))] * 3
    times, states, velocities, history, rate_history = [0.0], [zero], [zero], [np.zeros((m, q))], [np.zeros((m, q))]

    def advance(step_scheme: TimeScheme, time: float, old, new):
        nonlocal sensitivity
        point = step_scheme.evaluation_point(time, old, new)
        sensitivity = propagate_sensitivity(system, step_scheme, point, sensitivity, system.parameter_derivative(*point))

    def record(report, eta, eta_dot, eta_ddot):
        times.append(report.time)
        states.append(eta.copy())
        velocities.append(eta_dot.copy())
        history.append(sensitivity[0].copy())
        rate_history.append(sensitivity[1].copy())

    integrate(system, scheme, n_steps, (zero, zero, zero), NewtonSettings.reduced_settings(built.solver), record,
              on_step=advance if sensitivities and q else None)
    observed = np.array(states) @ rows.T
    derivative = np.einsum("om,nmq->noq", rows, np.array(history)) if sensitivities else None
    rate = np.einsum("om,nmq->noq", rows, np.array(rate_history)) if sensitivities else None
    return ModelSwim(np.array(times), observed, np.array(velocities) @ rows.T, derivative, rate, list(values))


__all__ = ["CALIBRATION_KEYS", "TIME_OFFSET", "CalibratedSystem", "ModelSwim", "check_keys", "scene_value",
           "scene_values", "simulate_parameters", "with_values"]
