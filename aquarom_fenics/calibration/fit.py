"""Least-squares calibration of scene parameters θ to a measured swim on the reduced model (issue 52).

Residual r(θ) = y_model(t_i + τ; θ) - y_data(t_i) over every data time t_i and tracked column, the model
sampled at the data's times (shifted by the time offset τ when it is fitted, 0 otherwise) by cubic Hermite
interpolation of the reduced trajectory and its velocity on the time grid (:func:`hermite`), its Jacobian
J = dy/dθ the same interpolation of the forward sensitivities of y and ẏ (``parameters.simulate_parameters``)
and dy/dτ the interpolant's time derivative (ẏ at the grid's times): the exact derivatives of what is sampled.
The FOM is sampled the same way, from its positions and velocities on its grid (:func:`sample_trajectory`).
Levenberg–Marquardt on the relative parameters θ/θ_start (τ, which starts at 0, relative to its
bounds' half-width), with bounds by projection:

    (Jᵀ J + λ diag(Jᵀ J)) δ = -Jᵀ r,   λ ÷ 3 after a step that lowers ½‖r‖², × 4 after one that does not

The PROM is rebuilt at the current θ when a parameter has moved more than ``rebuild_fraction`` of its
value since the last build (τ aside: the PROM does not depend on it). Converged: a relative step below
``step_tolerance`` on every parameter (τ's relative to its bounds' half-width).
The last iterations run on the FOM (``refine_on_fom``), so that the reported point is the FOM's.
At the optimum, with N data, q parameters and the noise estimate σ² = ‖r‖² / (N - q):

    Cov = σ² (Jᵀ J)⁻¹,   std_j = √Cov_jj,   ci95_j = θ_j ± t_{0.975, N-q} std_j,   corr = Cov_jk / (std_j std_k)
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.stats

from aquarom_fenics.calibration.parameters import TIME_OFFSET, ModelSwim, scene_values, simulate_parameters
from aquarom_fenics.dynamics.integrator import IntegrationStopped

CORRELATION_LIMIT = 0.95
"""|corr| above this: the data cannot tell the two parameters apart."""
CONDITION_LIMIT = 1e10
"""Condition number of the relative information matrix above this: nearly singular."""


@dataclass(frozen=True)
class FitSettings:
    max_iterations: int = 30
    step_tolerance: float = 1e-6          # relative step |δθ_j| / |θ_j| on every parameter
    rebuild_fraction: float = 0.2         # rebuild the PROM when a parameter moved more than this fraction
    initial_damping: float = 1e-3         # λ


@dataclass
class FitResult:
    keys: list[str]
    start: np.ndarray                     # θ where the fit started
    values: np.ndarray                    # θ at the end
    converged: bool
    iterations: int
    residual: np.ndarray                  # (n, k) model - data at the data's times [m]
    model: np.ndarray                     # (n, k) the model at the data's times [m]
    jacobian: np.ndarray                  # (n k, q) d(model)/dθ
    rebuilds: int
    history: list = field(default_factory=list)   # per iteration: cost, θ, λ


def hermite(at: np.ndarray, grid: np.ndarray, values: np.ndarray, rates: np.ndarray):
    """The cubic Hermite interpolant of ``values`` (n, …) with time derivatives ``rates`` on ``grid`` (n,) at
    ``at`` and its time derivative; zero before grid[0] (at rest before the start). On [t_k, t_k+1], Δ its
    length and s = (t - t_k)/Δ:

        y = h00 y_k + Δ h10 ẏ_k + h01 y_k+1 + Δ h11 ẏ_k+1,   h00 = 2s³ - 3s² + 1, h10 = s³ - 2s² + s,
        h01 = 3s² - 2s³, h11 = s³ - s²;  dy/dt = (h00' y_k + Δ h10' ẏ_k + h01' y_k+1 + Δ h11' ẏ_k+1) / Δ
    """
    clipped = np.clip(at, grid[0], grid[-1])
    k = np.clip(np.searchsorted(grid, clipped, side="right") - 1, 0, grid.size - 2)
    step = grid[k + 1] - grid[k]
    s = (clipped - grid[k]) / step
    shape = (-1,) + (1,) * (values.ndim - 1)
    s, step, before = s.reshape(shape), step.reshape(shape), (at < grid[0]).reshape(shape)
    h = (2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, 3 * s**2 - 2 * s**3, s**3 - s**2)
    dh = (6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, 6 * s - 6 * s**2, 3 * s**2 - 2 * s)
    ends = (values[k], step * rates[k], values[k + 1], step * rates[k + 1])
    value = sum(weight * end for weight, end in zip(h, ends))
    rate = sum(weight * end for weight, end in zip(dh, ends)) / step
    return np.where(before, 0.0, value), np.where(before, 0.0, rate)


def sample_at(swim: ModelSwim, times: np.ndarray, columns: list[int], keys: list[str] | None = None,
              offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The model's observed columns (n, k) at ``times`` + ``offset`` and their derivatives (n, k, q) with respect
    to ``keys`` (the swim's by default; the time offset's is the time derivative), by :func:`hermite`."""
    keys = swim.keys if keys is None else keys
    at = np.asarray(times, dtype=float) + offset
    values, rates = hermite(at, swim.time, swim.observed[:, columns], swim.velocity[:, columns])
    derivative = np.empty((at.size, len(columns), len(keys)))
    for k, key in enumerate(keys):
        if key == TIME_OFFSET:
            derivative[:, :, k] = rates
        else:
            index = swim.keys.index(key)
            derivative[:, :, k] = hermite(at, swim.time, swim.derivative[:, columns, index],
                                          swim.velocity_derivative[:, columns, index])[0]
    return values, derivative


def sample_trajectory(trajectory, times: np.ndarray, names) -> np.ndarray:
    """A run's observed points ``names`` (n, k) [m] at ``times`` [s] by :func:`hermite` of its positions and
    velocities on the time grid (``Trajectory.rate_arrays``): the FOM sampled as :func:`sample_at` samples
    the reduced model, zero before t = 0."""
    arrays, rates = trajectory.arrays(), trajectory.rate_arrays()
    values = np.column_stack([arrays[name] for name in names])
    velocity = np.column_stack([rates[name] for name in names])
    return hermite(np.asarray(times, dtype=float), arrays["time"], values, velocity)[0]


def model_at(prom, built, data, columns: list[int], keys: list[str], values: np.ndarray):
    """The PROM (built on the scene ``built``) at θ = ``values``: its observed columns at the data's times
    (n, k) and their Jacobian (n k, q) in ``keys``' order."""
    point = dict(zip(keys, values))
    swim = simulate_parameters(prom, built, scene_values(point))
    model, derivative = sample_at(swim, data.time, columns, keys, point.get(TIME_OFFSET, 0.0))
    return model, derivative.reshape(-1, len(keys))


def typical_sizes(keys: list[str], values: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """|θ_j| per parameter, and for the time offset (which starts at 0) its bounds' half-width [s]."""
    is_offset = np.array([key == TIME_OFFSET for key in keys])
    return np.where(is_offset, 0.5 * (bounds[:, 1] - bounds[:, 0]), np.abs(values))


def moved_beyond(keys: list[str], theta: np.ndarray, built_at: np.ndarray, fraction: float) -> bool:
    """Whether a parameter the PROM depends on (not the time offset) moved beyond ``fraction`` of its value."""
    depends = np.array([key != TIME_OFFSET for key in keys])
    return bool(np.any(depends & (np.abs(theta - built_at) > fraction * np.abs(built_at))))


def calibrate(data, columns: list[int], keys: list[str], start: np.ndarray, bounds: np.ndarray,
              build: Callable[[dict], tuple], settings: FitSettings = FitSettings(),
              report: Callable[[int, float, np.ndarray], None] | None = None) -> FitResult:
    """Fit θ (``keys``, from ``start``, within ``bounds`` (q, 2)) to ``data`` (a SwimData; ``columns`` the
    model's observable index of each data column). ``build(values)`` returns (prom, scene it was built on)."""
    scale = typical_sizes(keys, np.asarray(start, dtype=float), bounds)
    theta = np.clip(np.asarray(start, dtype=float), bounds[:, 0], bounds[:, 1])
    prom, built = build(dict(zip(keys, theta)))
    built_at, rebuilds = theta.copy(), 0

    def evaluate(values: np.ndarray):
        model, jacobian = model_at(prom, built, data, columns, keys, values)
        return model, jacobian, model - data.values

    def size(values: np.ndarray) -> np.ndarray:
        return typical_sizes(keys, values, bounds)

    model, jacobian, residual = evaluate(theta)
    cost = 0.5 * float(np.sum(residual ** 2))
    damping, converged, history = settings.initial_damping, False, []
    iteration = 0
    for iteration in range(1, settings.max_iterations + 1):
        scaled = jacobian * scale                              # d(model)/d(θ/θ_start)
        normal = scaled.T @ scaled
        gradient = scaled.T @ residual.ravel()
        accepted = stalled = False
        for _ in range(12):
            system = normal + damping * np.diag(np.diag(normal) + 1e-300)
            step = -np.linalg.lstsq(system, gradient, rcond=None)[0] * scale
            trial = np.clip(theta + step, bounds[:, 0], bounds[:, 1])
            if np.all(np.abs(trial - theta) <= settings.step_tolerance * size(theta)):
                stalled = True                  # no step left to take: at the minimum (to the tolerance)
                break
            try:
                trial_model, trial_jacobian, trial_residual = evaluate(trial)
            except IntegrationStopped:              # the PROM stops far from the data: a shorter step
                damping *= 4.0
                continue
            trial_cost = 0.5 * float(np.sum(trial_residual ** 2))
            if trial_cost <= cost:
                accepted = True
                break
            damping *= 4.0
        history.append({"iteration": iteration, "cost": cost, "values": theta.tolist(), "damping": damping})
        if report is not None:
            report(iteration, cost, theta)
        if stalled:
            converged = True
            break
        if not accepted:
            break
        moved = trial - theta
        theta, model, jacobian, residual, cost = trial, trial_model, trial_jacobian, trial_residual, trial_cost
        damping = max(damping / 3.0, 1e-12)
        if np.all(np.abs(moved) <= settings.step_tolerance * np.maximum(size(theta), 1e-300)):
            converged = True
            break
        if moved_beyond(keys, theta, built_at, settings.rebuild_fraction):
            prom, built = build(dict(zip(keys, theta)))
            built_at, rebuilds = theta.copy(), rebuilds + 1
            model, jacobian, residual = evaluate(theta)
            cost = 0.5 * float(np.sum(residual ** 2))
    return FitResult(keys, np.asarray(start, dtype=float), theta, converged, iteration, residual, model, jacobian, rebuilds, history)


@dataclass
class Statistics:
    std: np.ndarray
    ci95: np.ndarray                      # (q, 2)
    correlation: np.ndarray               # (q, q)
    noise: float                          # σ [m]
    condition: float                      # of the relative information matrix
    unidentifiable: list[str]             # one phrase per problem found


def statistics(result: FitResult) -> Statistics:
    """The Gauss–Newton covariance at the optimum with the residual's noise estimate (module docstring)."""
    n_data, q = result.residual.size, len(result.keys)
    dof = max(n_data - q, 1)
    noise = float(np.sqrt(np.sum(result.residual ** 2) / dof))
    scale = np.where(result.values != 0, np.abs(result.values), 1.0)
    relative = result.jacobian * scale
    information = relative.T @ relative
    singular = np.linalg.svd(information, compute_uv=False)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else float("inf")
    covariance = noise ** 2 * np.linalg.pinv(information) * np.outer(scale, scale)
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(std, std)
    correlation = np.nan_to_num(correlation)
    t = float(scipy.stats.t.ppf(0.975, dof))
    ci95 = np.column_stack([result.values - t * std, result.values + t * std])
    problems = []
    if condition > CONDITION_LIMIT:
        problems.append(f"the information matrix is nearly singular (condition number {condition:.2g})")
    for j in range(q):
        for k in range(j + 1, q):
            if abs(correlation[j, k]) > CORRELATION_LIMIT:
                problems.append(f"{result.keys[j]} and {result.keys[k]} (correlation {correlation[j, k]:+.3f})")
    return Statistics(std, ci95, correlation, noise, condition, problems)


FOM_STEP_TOLERANCE = 1e-4
"""The FOM iterations stop when every relative step is below this (a tenth of a per mille: far inside the
confidence intervals of a swim tracked to tenths of a millimetre)."""


def refine_on_fom(data, result: FitResult, bounds: np.ndarray, fom_model: Callable[[np.ndarray], np.ndarray],
                  prom_jacobian: Callable[[np.ndarray], np.ndarray], max_iterations: int = 6,
                  report: Callable[[int, float, np.ndarray], None] | None = None) -> FitResult:
    """The last iterations on the FOM: Gauss–Newton steps δ = -J⁺ r_FOM(θ) with the FOM's residual and the
    PROM's Jacobian at θ (``prom_jacobian(θ)``, (n k, q); ``fom_model(θ)`` the FOM at the data's times,
    (n, k)), from the PROM's optimum. Its fixed point is a zero of J_PROMᵀ r_FOM: the FOM's least-squares
    point up to the PROM's error in J times the residual. Returns the result at the FOM with ``converged``
    the PROM's and the FOM's both."""
    theta = result.values.copy()
    history = list(result.history)
    converged = False
    for iteration in range(1, max_iterations + 1):
        model = fom_model(theta)
        residual = model - data.values
        jacobian = prom_jacobian(theta)
        cost = 0.5 * float(np.sum(residual ** 2))
        history.append({"iteration": f"fom {iteration}", "cost": cost, "values": theta.tolist()})
        if report is not None:
            report(iteration, cost, theta)
        step = -np.linalg.lstsq(jacobian, residual.ravel(), rcond=None)[0]
        if np.all(np.abs(step) <= FOM_STEP_TOLERANCE * typical_sizes(result.keys, theta, bounds)):
            converged = True
            break
        if iteration == max_iterations:
            break                               # the point reported is the last one the FOM ran
        theta = np.clip(theta + step, bounds[:, 0], bounds[:, 1])
    return FitResult(result.keys, result.start, theta, result.converged and converged,
                     result.iterations + iteration, residual, model, jacobian, result.rebuilds, history)
