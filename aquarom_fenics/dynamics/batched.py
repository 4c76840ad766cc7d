"""Many designs of one PROM integrated at once: the generalized-α Newton steps of :mod:`integrator` and the
direct-differentiation sensitivities of :mod:`reduced_dynamics`, vectorised over a batch of designs.

Each design follows the single run's Newton exactly (the same modified Newton: factors refreshed at the first
iteration, when an iteration contracts the residual by less than ``contraction_to_refactor`` or after
``iterations_per_factorization`` iterations; the same test ‖r‖ ≤ tol · max(scale, floor)), with its own state,
factors and counters, so the batch agrees with ``simulate_reduced`` to rounding. What the batch does not do is
cut steps: a design whose step fails (no convergence, a non-finite residual, a singular Newton matrix) leaves
the batch and is integrated alone by ``simulate_reduced``, with its step control and stop report.
"""
from __future__ import annotations

import time as clock
from dataclasses import dataclass, field

import numpy as np

from aquarom_fenics.dynamics.batched_system import BatchedSystem, design_rows, norms2
from aquarom_fenics.dynamics.integrator import NewtonSettings
from aquarom_fenics.dynamics.reduced_dynamics import (newton_matrix, one_blas_thread, sensitivity_rhs,
                                                       simulate_reduced)
from aquarom_fenics.dynamics.trajectory import AMPLITUDE_WINDOW, DISTANCE_WINDOW, window_mask
from aquarom_fenics.fem.time_scheme import TimeScheme
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.muscle import ActivationLaw
from aquarom_fenics.reduction.prom import ReducedModel

CHUNK_SIZE = 1024
"""Designs integrated together at most (the batch's arrays grow with it, its per-step overhead shrinks)."""

ENGINES = ("compiled", "numpy")
"""How a batch is integrated: the compiled kernel (``reduced_kernel``, numba), or numpy vectorised over the batch."""


def default_engine() -> str:
    """The compiled kernel where numba is installed (``make setup`` installs it), numpy otherwise."""
    from aquarom_fenics.dynamics import reduced_kernel
    return "compiled" if reduced_kernel.available() else "numpy"


@dataclass
class BatchedResult:
    """The outcome of every design of a batch, (B, ...) arrays; None entries of a design that stopped."""

    distance: np.ndarray                         # (B,) [m], NaN where not completed
    tail_amplitude: np.ndarray                   # (B,) [m], NaN where not completed
    completed: np.ndarray                        # (B,) bool
    errors: list                                 # (B,) the stop reason, None where completed
    distance_gradient: np.ndarray | None         # (B, columns) dd/dξ (and dd/dA), NaN where not completed
    alone: np.ndarray                            # (B,) bool: integrated alone after its step failed in the batch
    cut_steps: np.ndarray                        # (B,) sub-steps shorter than h (designs integrated alone)
    wall_time: float                             # [s] for the whole batch
    timings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return self.distance.size

    def summary(self, b: int) -> dict:
        """Design b as ``ReducedResult.summary`` gives it (distance, tail amplitude, completed, stop reason,
        gradient)."""
        completed = bool(self.completed[b])
        gradient = None if self.distance_gradient is None or not completed else self.distance_gradient[b].tolist()
        return {"distance": float(self.distance[b]) if completed else None,
                "tail_amplitude": float(self.tail_amplitude[b]) if completed else None,
                "completed": completed, "error": self.errors[b], "stop_reason": self.errors[b] or "completed",
                "distance_gradient": gradient, "cut_steps": int(self.cut_steps[b]), "alone": bool(self.alone[b])}


@one_blas_thread
def simulate_batch(prom: ReducedModel, scene: Scene, xis, sensitivities: bool = False, amplitudes=None,
                   amplitude_sensitivity: bool = False, chunk_size: int = CHUNK_SIZE,
                   engine: str | None = None, scenes: list | None = None) -> BatchedResult:
    """Integrate the PROM at the designs ``xis`` (B, p) (amplitudes A_b: ``amplitudes`` (B,), default the
    scene's) over the scene's horizon, as ``simulate_reduced`` would one by one.

    ``scenes`` (B,): each design's own scene, the scene driven by its gait (``apply_gait``: frequency, phases and
    scales; the same time grid, body and fluid), whose activation law drives that design and with which a design
    that leaves the batch is integrated alone; default ``scene`` for all.

    With ``sensitivities`` the gradient dd/dξ of each design, with ``amplitude_sensitivity`` one more column
    dd/dA. InputError (as ``simulate_reduced``) for a design beyond the PROM's validity radius. ``engine``: one
    of ``ENGINES``, default ``default_engine()``; both give the same numbers to rounding.
    """
    from aquarom_fenics.dynamics import reduced_kernel
    from aquarom_fenics.dynamics.simulate import check_time_grid

    engine = default_engine() if engine is None else engine
    if engine not in ENGINES:
        raise ValueError(f"engine must be one of {ENGINES}, got {engine!r}")

    started, started_cpu = clock.perf_counter(), clock.thread_time()
    n_steps = check_time_grid(scene)
    xis = design_rows(xis, prom.n_parameters)
    batch = xis.shape[0]
    amplitudes = (np.full(batch, scene.actuation.amplitude) if amplitudes is None
                  else np.asarray(amplitudes, dtype=float).reshape(batch))
    columns = (prom.n_parameters if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    if scenes is not None and len(scenes) != batch:
        raise ValueError(f"{len(scenes)} scenes for {batch} designs")
    result = BatchedResult(np.full(batch, np.nan), np.full(batch, np.nan), np.zeros(batch, bool), [None] * batch,
                           np.full((batch, columns), np.nan) if columns else None, np.zeros(batch, bool),
                           np.zeros(batch, int), 0.0)
    for start in range(0, batch, chunk_size):
        part = slice(start, min(start + chunk_size, batch))
        laws = None if scenes is None else [ActivationLaw.of(own) for own in scenes[part]]
        system = BatchedSystem(prom, scene, xis[part], TimeScheme.from_solver(scene.solver), amplitudes[part], laws)
        if engine == "compiled":
            outcome = reduced_kernel.integrate_packed(reduced_kernel.pack(system, scene, n_steps, sensitivities,
                                                                          amplitude_sensitivity))
        else:
            outcome = _integrate(system, scene, n_steps, sensitivities, amplitude_sensitivity)
        result.distance[part], result.tail_amplitude[part], failed = outcome[:3]
        if columns:
            result.distance_gradient[part] = outcome[3]
        for b in np.flatnonzero(failed) + start:
            alone = simulate_reduced(prom, scene if scenes is None else scenes[b], xis[b], sensitivities=sensitivities, amplitude=amplitudes[b],
                                     amplitude_sensitivity=amplitude_sensitivity)
            result.alone[b], result.cut_steps[b], result.errors[b] = True, alone.cut_steps, alone.error
            if alone.completed:
                result.distance[b], result.tail_amplitude[b] = alone.distance, alone.tail_amplitude
                if columns:
                    result.distance_gradient[b] = alone.distance_gradient
    result.completed = np.array([error is None for error in result.errors])
    result.wall_time = clock.perf_counter() - started
    result.timings["cpu_time"] = clock.thread_time() - started_cpu     # [s] of this thread: robust on a shared host
    return result


def _integrate(system: BatchedSystem, scene: Scene, n_steps: int, sensitivities: bool, amplitude_sensitivity: bool):
    """(distance (B,), tail amplitude (B,), failed (B,) bool, distance gradient (B, columns) or None) of the batch."""
    scheme = system.scheme
    settings = NewtonSettings.reduced_settings(scene.solver)
    batch, m = system.size, system.prom.size
    h = scheme.time_step
    times = np.arange(n_steps + 1) * h
    distance_samples = window_mask(times, DISTANCE_WINDOW)
    com = np.zeros((batch, n_steps + 1))
    tail = np.zeros((batch, n_steps + 1))
    columns = (system.deltas.shape[1] if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    window_states = np.zeros((batch, int(distance_samples.sum()), m))
    window_sensitivities = np.zeros((batch, window_states.shape[1], m, columns))
    state = tuple(np.zeros((batch, m)) for _ in range(3))
    sensitivity = tuple(np.zeros((batch, m, columns)) for _ in range(3))
    newton = _BatchedNewton(system, settings)
    failed = np.zeros(batch, bool)
    sample = int(distance_samples[0])         # the state at rest (zero) may open the window of a short run
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        for step in range(1, n_steps + 1):
            time = step * h
            new = newton.solve_step(scheme, time, state, failed)
            if columns:
                sensitivity = _propagate(system, scheme, time, state, new, sensitivity, sensitivities,
                                         amplitude_sensitivity, failed)
            state = tuple(np.where(failed[:, None], 0.0, values) for values in new)
            _, tail[:, step], com[:, step] = system.observables(state[0])
            if distance_samples[step]:
                window_states[:, sample] = state[0]
                if columns:
                    window_sensitivities[:, sample] = sensitivity[0]
                sample += 1
    distance = com[:, distance_samples].mean(axis=1)
    amplitude = np.abs(tail[:, window_mask(times, AMPLITUDE_WINDOW)]).max(axis=1)
    gradient = None
    if columns:
        weights_gradient = system.com_gradient if sensitivities else np.zeros((batch, 0, m))
        if amplitude_sensitivity:
            weights_gradient = np.concatenate([weights_gradient, np.zeros((batch, 1, m))], axis=1)
        per_sample = (np.einsum("bsm,bkm->bsk", window_states, weights_gradient)
                      + np.einsum("bm,bsmk->bsk", system.com_weights, window_sensitivities))
        gradient = per_sample.mean(axis=1)
    distance[failed] = amplitude[failed] = np.nan
    return distance, amplitude, failed, gradient


class _BatchedNewton:
    """``integrator._Newton`` design by design: per design its Newton matrix (kept across steps, the single
    run's factors), its residual norm history and its iterations on the current factors."""

    def __init__(self, system: BatchedSystem, settings: NewtonSettings):
        batch, m = system.size, system.prom.size
        self.system, self.settings = system, settings
        self.matrices = np.zeros((batch, m, m))
        self.have_factors = np.zeros(batch, bool)

    def solve_step(self, scheme: TimeScheme, time: float, old, failed: np.ndarray):
        """(u, u̇, ü)_{n+1} of every design; designs whose Newton fails are marked in ``failed`` (in place).

        Each iteration evaluates the residual of the designs still iterating only, and the Newton matrix of
        those whose factors are refreshed only."""
        settings, system = self.settings, self.system
        u_predicted, v_predicted = scheme.predict(*old)
        u_new = u_predicted.copy()
        pending = ~failed
        with_factors = np.zeros(failed.size, int)
        previous_norm = np.full(failed.size, np.inf)
        for iteration in range(settings.max_iterations + 1):
            rows = np.flatnonzero(pending)
            if rows.size == 0:
                break
            v_new, a_new = scheme.correct(u_new[rows], u_predicted[rows], v_predicted[rows])
            point = scheme.evaluation_point(time, tuple(values[rows] for values in old), (u_new[rows], v_new, a_new))
            residual, scale = system.select(rows).residual(*point)
            residual_norm = np.sqrt(norms2(residual))
            diverged = ~np.isfinite(residual_norm)
            failed[rows[diverged]] = True
            going = ~diverged & (residual_norm > settings.tolerance * np.maximum(scale, settings.force_floor))
            pending[rows[~going]] = False
            if not going.any():
                break
            if iteration == settings.max_iterations:
                failed[rows[going]] = True
                break
            rows, residual, residual_norm = rows[going], residual[going], residual_norm[going]
            point = (point[0],) + tuple(values[going] for values in point[1:])
            slow = residual_norm > settings.contraction_to_refactor * previous_norm[rows]
            worn = with_factors[rows] >= settings.iterations_per_factorization
            if iteration == 0 and settings.refresh_each_step:
                worn[:] = True
            refresh = ~self.have_factors[rows] | slow | worn
            if refresh.any():
                renewed = rows[refresh]
                self.matrices[renewed] = system.select(renewed).newton_matrix(
                    point[0], *(values[refresh] for values in point[1:]))
                self.have_factors[renewed] = True
                with_factors[renewed] = 0
            with_factors[rows] += 1
            previous_norm[rows] = residual_norm
            u_new[rows] -= _solve(self.matrices, residual, rows, failed)
        v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
        return u_new, v_new, a_new


def _solve(matrices: np.ndarray, rhs: np.ndarray, rows: np.ndarray, failed: np.ndarray) -> np.ndarray:
    """S_b⁻¹ rhs of the designs ``rows`` (rhs (len(rows), m)); a design whose S is singular is marked failed, its
    update zero."""
    selected = matrices[rows]
    try:
        return np.linalg.solve(selected, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        updates = np.zeros_like(rhs)
        for n, b in enumerate(rows):
            try:
                updates[n] = np.linalg.solve(selected[n], rhs[n])
            except np.linalg.LinAlgError:
                failed[b] = True
        return updates


def _propagate(system: BatchedSystem, scheme: TimeScheme, time: float, old, new, previous, sensitivities: bool,
               amplitude_sensitivity: bool, failed: np.ndarray):
    """(η', η̇', η̈')_{n+1} of every design (``reduced_dynamics.propagate_sensitivity`` with a batch axis)."""
    point = scheme.evaluation_point(time, old, new)
    parts = []
    if sensitivities:
        parts.append(system.parameter_derivative(*point))
    if amplitude_sensitivity:
        parts.append(system.amplitude_derivative(point[0], point[1])[:, :, None])
    derivative = np.concatenate(parts, axis=2)
    stiffness, damping, mass = system.tangents(*point)
    rhs, u_predicted, v_predicted = sensitivity_rhs(scheme, stiffness, damping, mass, previous, derivative)
    matrix = newton_matrix(scheme, stiffness, damping, mass)
    matrix[failed] = np.eye(matrix.shape[-1])
    rhs[failed] = 0.0
    try:
        u_new = np.linalg.solve(matrix, rhs)
    except np.linalg.LinAlgError:
        u_new = np.zeros_like(rhs)
        for b in range(rhs.shape[0]):
            try:
                u_new[b] = np.linalg.solve(matrix[b], rhs[b])
            except np.linalg.LinAlgError:
                failed[b] = True
    v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
    return u_new, v_new, a_new


def reduced_distances(prom: ReducedModel, scene: Scene, xis: np.ndarray, gradient: bool = False):
    """The PROM's distances d (B,) at the designs ``xis`` (B, p) (:func:`simulate_batch`) and, with ``gradient``,
    ∂d/∂ξ (B, p); NaN where a solve stopped. What the atlas's check of its cells simulates
    (``reduction.atlas_check``, which sits below this layer and is handed this function)."""
    xis = np.atleast_2d(xis)
    result = simulate_batch(prom, scene, xis, sensitivities=gradient)
    return result.distance, (result.distance_gradient[:, :xis.shape[1]] if gradient else None)
