"""Shape (and actuation) optimisation with PROM sensitivities (SPEC §10).

Two algorithms over the same cost and design space (``cost.py``):

* ``paper``: the source's gradient descent with a log-barrier, z ← z - γ W ∇L_b with a diagonal
  W that starts at 1/‖∇L_b(z_0)‖_∞ (so the first step changes the leading parameter by γ) and is
  halved along a direction whose gradient component changes sign or whose bound becomes active,
  the linearised trajectory η ≈ η_c + S (ξ - ξ_c) between PROM builds (so d ≈ d_c + ∇d_c·(z - z_c)),
  and a new PROM when any |z - z_c|_i exceeds ``rebuild_threshold`` or every ``n_rebuild``
  iterations.
* ``trust-region``: the PROM built at the centre is a nonlinear surrogate (simulated at any z in
  the radius, with its own sensitivities); SciPy's SLSQP solves the surrogate problem with bounds
  and linear constraints inside the radius; a PROM built at the candidate gives the actual
  reduction, ρ = actual / predicted accepts or rejects the step and resizes the radius.

The state after every iteration goes to an atomic checkpoint; a resumed run continues from it to
the same result (PROM builds are deterministic).
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import LinearConstraint, minimize

from .cache import cached_prom
from .cost import CostWeights, DesignSpace, Evaluation, design_space, evaluate, meshable_space, require_interior
from .errors import InputError, SolverError
from .fish import Fish, load_fish
from .outputs import write_json_atomic
from .prom import ReducedModel
from .reductor import build_prom
from .scene import Scene

log = logging.getLogger("aquarom")
DEFAULT_MAX_TIME = 24 * 3600.0     # s, wall-time safeguard of one optimisation


@dataclass
class OptimizationResult:
    optimum: np.ndarray
    evaluation: Evaluation                    # PROM prediction at the optimum (from a PROM built there)
    history: list[dict]
    builds: int
    stop_reason: str
    space: DesignSpace
    prom_size: int = 0                        # reduced dofs of the last PROM built
    timings: dict = field(default_factory=dict)
    reused: int = 0                           # of the builds, PROMs taken from the cache


class PromBuilder:
    """Builds PROMs centred on designs, counting builds, cache reuses and their time."""

    def __init__(self, scene: Scene, fish: Fish, space: DesignSpace):
        self.scene, self.fish, self.space = scene, fish, space
        self.builds = 0
        self.reused = 0
        self.last_size = 0
        self.build_time = 0.0
        self.solve_time = 0.0

    def build(self, z: np.ndarray) -> ReducedModel:
        started = time.perf_counter()
        center = z[: self.space.n_shapes]
        built = []

        def build_here():
            built.append(build_prom(self.scene, xi_center=center, fish=self.fish))
            return built[0]

        prom = cached_prom(self.scene, center, build_here)
        self.build_time += time.perf_counter() - started
        self.builds += 1
        self.reused += not built
        self.last_size = prom.size
        return prom

    def evaluate(self, prom, z, weights) -> Evaluation:
        started = time.perf_counter()
        try:
            return evaluate(prom, self.scene, self.space, z, weights)
        finally:
            self.solve_time += time.perf_counter() - started


def history_columns(space: DesignSpace) -> list[str]:
    """The columns of a history row, in the order :func:`history_row` makes them."""
    return (["iteration", *(f"xi_{name}" for name in space.names), "cost", *(f"grad_{name}" for name in space.names)]
            + ["distance", "prom", "wall_time", "radius", "ratio"])


def history_row(space: DesignSpace, iteration: int, z, cost, gradient, distance, kind: str, started: float,
                radius: float | None = None, ratio: float | None = None) -> dict:
    """One iteration: ξ, cost, gradient, distance [m], how the PROM was used, and for the trust
    region its radius (fraction of the validity box) and actual/predicted reduction."""
    row = {"iteration": iteration}
    row.update({f"xi_{name}": float(value) for name, value in zip(space.names, z)})
    row["cost"] = float(cost)
    row.update({f"grad_{name}": float(value) for name, value in zip(space.names, gradient)})
    row.update({"distance": float(distance), "prom": kind, "wall_time": time.perf_counter() - started,
                "radius": radius, "ratio": ratio})
    return row


class Checkpoint:
    """Optimiser state as JSON, written atomically after every iteration."""

    KEYS = ("scene_hash", "method", "state", "history", "builds", "build_time", "solve_time")

    def __init__(self, path: Path | None, scene: Scene, method: str, write: bool = True):
        self.path, self.scene_hash, self.method, self.write = path, scene.hash, method, write

    def save(self, state: dict, history: list[dict], builder: PromBuilder) -> None:
        if self.path is None or not self.write:
            return
        write_json_atomic(self.path, {"scene_hash": self.scene_hash, "method": self.method, "state": state,
                                      "history": history, "builds": builder.builds, "reused": builder.reused,
                                      "build_time": builder.build_time, "solve_time": builder.solve_time})

    def load(self) -> dict | None:
        if self.path is None or not self.path.exists():
            return None
        try:
            data = json.loads(self.path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as error:
            raise InputError(f"checkpoint {self.path}: unreadable ({error}); start without --resume") from None
        if not isinstance(data, dict) or any(key not in data for key in self.KEYS):
            raise InputError(f"checkpoint {self.path}: incomplete (needs {', '.join(self.KEYS)}); "
                             "start without --resume")
        if data.get("scene_hash") != self.scene_hash or data.get("method") != self.method:
            raise InputError(f"checkpoint {self.path}: written for scene hash {data.get('scene_hash')} with "
                             f"method {data.get('method')}, not this scene ({self.scene_hash}, {self.method}); "
                             "start without --resume")
        return data


def optimize(scene: Scene, fish: Fish | None = None, weights: CostWeights | None = None,
             checkpoint_path: Path | None = None, resume: bool = False,
             on_iteration=None, write_checkpoint: bool = True, max_time: float = DEFAULT_MAX_TIME) -> OptimizationResult:
    """Run the scene's optimiser; ``on_iteration(row)`` sees every history row as it is made.

    Every rank reads a checkpoint to resume from; only ranks with ``write_checkpoint`` write one.
    The run stops after ``scene.optimizer.max_iterations`` iterations or ``max_time`` seconds.
    """
    fish = fish or load_fish(scene)
    space, notes = meshable_space(design_space(scene), fish)
    for note in notes:
        log.warning("design space: %s", note)
    weights = weights or CostWeights()
    method = scene.optimizer.method
    builder = PromBuilder(scene, fish, space)
    checkpoint = Checkpoint(checkpoint_path, scene, method, write=write_checkpoint)
    saved = checkpoint.load() if resume else None
    history = list(saved["history"]) if saved else []
    if saved:
        builder.builds, builder.build_time, builder.solve_time = saved["builds"], saved["build_time"], saved["solve_time"]
        builder.reused = saved.get("reused", 0)
    started = time.perf_counter() - (history[-1]["wall_time"] if history else 0.0)
    algorithm = {"paper": _paper_method, "trust-region": _trust_region}[method]
    safeguard = Safeguard(started, max_time)
    optimum, evaluation, reason = algorithm(scene, space, builder, weights, history, checkpoint,
                                            saved["state"] if saved else None, safeguard,
                                            on_iteration or (lambda row: None))
    timings = {"prom_builds": builder.build_time, "prom_solves": builder.solve_time,
               "total": time.perf_counter() - started}
    log.info("optimisation (%s) stopped: %s; %d PROM builds (%d reused from the cache), %.1f s", method, reason,
             builder.builds, builder.reused, timings["total"])
    return OptimizationResult(optimum, evaluation, history, builder.builds, reason, space, builder.last_size, timings,
                              builder.reused)


@dataclass
class Safeguard:
    """Stops a loop past its wall-time budget and refuses a non-finite design."""

    started: float
    max_time: float

    def out_of_time(self) -> bool:
        return time.perf_counter() - self.started > self.max_time

    @property
    def reason(self) -> str:
        return f"wall-time limit of {self.max_time:g} s reached"

    @staticmethod
    def finite(z: np.ndarray, iteration: int) -> np.ndarray:
        if not np.all(np.isfinite(z)):
            raise SolverError(f"the optimiser produced a non-finite design {z.tolist()} at iteration {iteration}")
        return z


def _record(history, row, on_iteration):
    history.append(row)
    on_iteration(row)


# ---------------------------------------------------------------------- the source's method
def barrier(space: DesignSpace, z: np.ndarray) -> tuple[float, np.ndarray]:
    """B(z) = -Σ log s_i(z) and ∇B, over the box bounds of the free parameters and the linear
    inequalities s(z) ≥ 0 (a fixed parameter, lower = upper, has no interior to keep to)."""
    rows = space.barrier_rows
    slacks = space.slacks(z)[rows]
    if np.any(slacks <= 0):
        return np.inf, np.full(z.size, np.nan)
    jacobian = space.slack_jacobian[rows]   # ∂s/∂z
    return float(-np.log(slacks).sum()), -(jacobian / slacks[:, None]).sum(axis=0)


def _paper_method(scene, space, builder, weights, history, checkpoint, state, safeguard, on_iteration):
    settings = scene.optimizer
    started = safeguard.started
    require_interior(space, scene)
    interior = _strictly_inside(space, space.start)
    if state is None:
        state = {"z": interior.tolist(), "iteration": 0, "scaling": np.ones(space.names.__len__()).tolist(),
                 "previous_gradient": None, "since_build": 0, "center": None}
    z = np.array(state["z"])
    scaling = np.array(state["scaling"])
    prom = None
    center = state["center"]
    reason = "maximum number of iterations"
    while state["iteration"] < settings.max_iterations:
        iteration = state["iteration"]
        drift = np.inf if center is None else np.abs(z - np.array(center["z"])).max()
        rebuild = center is None or drift > settings.rebuild_threshold or state["since_build"] >= settings.n_rebuild
        if rebuild:
            try:
                prom = builder.build(z)
            except InputError as refused:      # the mesh check refuses the design: step back halfway
                if center is None or np.abs(z - np.array(center["z"])).max() < settings.step_tolerance:
                    raise
                log.warning("paper method: %s; stepping back towards the last built design", refused)
                z = np.array(center["z"]) + 0.5 * (z - np.array(center["z"]))
                scaling *= 0.5
                state.update(z=z.tolist(), scaling=scaling.tolist())
                continue
            exact = builder.evaluate(prom, z, weights)
            center = {"z": z.tolist(), "distance": exact.distance, "distance_gradient": exact.distance_gradient.tolist()}
            state["since_build"] = 0
        distance, distance_gradient = _linearised_distance(center, z)
        cost, gradient = _weighted_cost(space, weights, z, distance, distance_gradient)
        barrier_value, barrier_gradient = barrier(space, z)
        barrier_scale = settings.barrier_weight * max(abs(cost), 1e-12)
        total_gradient = np.where(space.free, gradient + barrier_scale * barrier_gradient, 0.0)
        _record(history, history_row(space, iteration, z, cost, gradient, distance,
                                     "built" if rebuild else "approximated", started), on_iteration)
        previous = state["previous_gradient"]
        if previous is None:     # W starts at 1/‖∇L_0‖_∞: the first step changes the leading parameter by γ
            scaling /= max(np.abs(total_gradient).max(), 1e-300)
        else:
            scaling[np.sign(total_gradient) * np.sign(previous) < 0] *= 0.5
        step = -settings.step_size * scaling * total_gradient
        fraction, blocking = _fraction_to_boundary(space, z, step)
        if fraction < 1.0:
            scaling[blocking] *= 0.5
            step = fraction * step
        previous_cost = history[-2]["cost"] if len(history) > 1 else None
        z = safeguard.finite(z + step, iteration)
        state.update(z=z.tolist(), iteration=iteration + 1, scaling=scaling.tolist(),
                     previous_gradient=total_gradient.tolist(), since_build=state["since_build"] + 1, center=center)
        checkpoint.save(state, history, builder)
        if safeguard.out_of_time():
            reason = safeguard.reason
            break
        if np.linalg.norm(step) < settings.step_tolerance:
            reason = f"step {np.linalg.norm(step):.2e} below the step tolerance"
            break
        if previous_cost is not None and abs(cost - previous_cost) < settings.cost_tolerance * abs(cost) and not rebuild:
            reason = f"cost change below {settings.cost_tolerance:g} of the cost"
            break
    if center is not None and np.allclose(z, center["z"]) and prom is not None:
        final = builder.evaluate(prom, z, weights)
    else:
        final = _final_evaluation(builder, weights, z, np.array(center["z"]))
        z = final.z
    _record(history, history_row(space, state["iteration"], z, final.cost, final.gradient, final.distance,
                                 "built", started), on_iteration)
    return z, final, reason


def _final_evaluation(builder: PromBuilder, weights, z, last_built) -> Evaluation:
    """A PROM built at the last iterate (stepping back towards the last built design if refused)."""
    for _ in range(20):
        try:
            return builder.evaluate(builder.build(z), z, weights)
        except InputError:
            z = last_built + 0.5 * (z - last_built)
    return builder.evaluate(builder.build(last_built), last_built, weights)


def _strictly_inside(space: DesignSpace, z: np.ndarray) -> np.ndarray:
    """Move a start on a bound slightly inside (the barrier needs interior points); a start on a
    linear constraint moves halfway towards the most interior point of the feasible set."""
    margin = 1e-3 * (space.upper - space.lower)
    z = np.clip(z, space.lower + margin, space.upper - margin)
    if np.all(space.slacks(z)[space.barrier_rows] > 0):
        return z
    return 0.5 * (z + space.most_interior_point())


def _linearised_distance(center: dict, z: np.ndarray) -> tuple[float, np.ndarray]:
    """d(z) ≈ d_c + ∇d_c · (z - z_c), the first-order trajectory approximation between builds."""
    gradient = np.array(center["distance_gradient"])
    return center["distance"] + gradient @ (z - np.array(center["z"])), gradient


def _weighted_cost(space, weights, z, distance, distance_gradient):
    cost = -weights.distance * distance
    gradient = -weights.distance * np.asarray(distance_gradient, dtype=float)
    if space.with_amplitude:
        cost += weights.energy * weights.energy_term(z[-1])
        gradient = gradient.copy()
        gradient[-1] += weights.energy * 2 * weights.alpha * z[-1]
    return cost, gradient


def _fraction_to_boundary(space: DesignSpace, z, step, keep: float = 0.1) -> tuple[float, np.ndarray]:
    """Largest t ≤ 1 that keeps ``keep`` of every slack s(z) > 0, and the directions it blocks."""
    rows = space.barrier_rows
    slacks = space.slacks(z)[rows]
    jacobian = space.slack_jacobian[rows]
    change = jacobian @ step
    shrinking = change < 0
    if not np.any(shrinking):
        return 1.0, np.array([], dtype=int)
    limits = np.full(slacks.size, np.inf)
    limits[shrinking] = -slacks[shrinking] / change[shrinking]
    limits *= 1.0 - keep
    if limits.min() >= 1.0:
        return 1.0, np.array([], dtype=int)
    fraction = limits.min()
    limiting = np.flatnonzero(limits < 1.0)
    return fraction, np.flatnonzero(np.abs(jacobian[limiting]).sum(axis=0) * (step != 0) > 0)


# ---------------------------------------------------------------------- trust region
def _trust_region(scene, space, builder, weights, history, checkpoint, state, safeguard, on_iteration):
    settings = scene.optimizer
    started = safeguard.started
    # The trust radius is a fraction of the PROM validity box; the amplitude enters the reduced
    # actuation exactly (linearly), so its box is its whole range.
    half_widths = np.array(scene.validity_radii() + ([space.upper[-1] - space.lower[-1]] if space.with_amplitude else []))
    if state is None:
        state = {"center": space.start.tolist(), "radius": settings.initial_radius, "iteration": 0}
    center = np.array(state["center"])
    prom = _build_or_stop(builder, center)
    current = builder.evaluate(prom, center, weights)
    if not history:
        _record(history, history_row(space, 0, center, current.cost, current.gradient, current.distance,
                                     "built", started, radius=state["radius"]), on_iteration)
    reason = "maximum number of iterations"
    while state["iteration"] < settings.max_iterations:
        if safeguard.out_of_time():
            reason = safeguard.reason
            break
        radius = state["radius"]
        candidate, predicted_cost = _surrogate_step(builder, prom, space, weights, center, radius * half_widths)
        candidate = safeguard.finite(candidate, state["iteration"] + 1)
        predicted = current.cost - predicted_cost
        step = candidate - center
        iteration = state["iteration"] + 1
        if np.abs(step).max() < settings.step_tolerance or predicted <= settings.cost_tolerance * abs(current.cost):
            reason = "no predicted improvement inside the trust radius"
            break
        candidate, candidate_prom = _meshable_candidate(builder, center, candidate)
        if candidate_prom is None:
            trial, ratio = None, -np.inf
        else:
            step = candidate - center
            predicted = current.cost - _surrogate_cost(builder, prom, weights, candidate)
            trial = builder.evaluate(candidate_prom, candidate, weights)
            ratio = (current.cost - trial.cost) / predicted if predicted > 0 else -np.inf
        accepted = ratio > settings.accept_ratio
        if trial is not None:
            _record(history, history_row(space, iteration, candidate, trial.cost, trial.gradient, trial.distance,
                                         "built" if accepted else "rejected", started, radius=radius,
                                         ratio=float(ratio)), on_iteration)
        if ratio < 0.25:
            radius *= 0.5
        elif ratio > 0.75 and np.any(np.abs(step) >= 0.9 * radius * half_widths):
            radius = min(2 * radius, 1.0)
        if accepted:
            center, prom, current = candidate, candidate_prom, trial
        state.update(center=center.tolist(), radius=radius, iteration=iteration)
        checkpoint.save(state, history, builder)
        if np.all(radius * half_widths < settings.step_tolerance):
            reason = f"trust radius {radius:.2e} of the validity box below the step tolerance"
            break
    return center, current, reason


def _meshable_candidate(builder: PromBuilder, center, candidate, attempts: int = 6):
    """The candidate, or the point halfway back towards the centre, … that the mesh check accepts."""
    for _ in range(attempts):
        try:
            return candidate, builder.build(candidate)
        except InputError as refused:
            log.warning("trust region: candidate refused (%s); trying halfway back", refused)
            candidate = center + 0.5 * (candidate - center)
    return candidate, None


def _surrogate_cost(builder: PromBuilder, prom, weights, z) -> float:
    return builder.evaluate(prom, z, weights).cost


def _build_or_stop(builder: PromBuilder, z: np.ndarray) -> ReducedModel:
    try:
        return builder.build(z)
    except InputError as refused:
        raise InputError(f"the PROM cannot be built at {builder.space.as_dict(z)}: {refused}") from None


def _surrogate_step(builder, prom, space, weights, center, radius) -> tuple[np.ndarray, float]:
    """Minimise the surrogate cost (PROM at its centre, simulated at z) inside bounds, constraints and radius."""
    cache = {}

    lower = np.maximum(space.lower, center - radius)
    upper = np.minimum(space.upper, center + radius)

    def surrogate(z):
        z = np.clip(np.asarray(z, dtype=float), lower, upper)
        key = tuple(z)
        if key not in cache:
            cache[key] = builder.evaluate(prom, z, weights)
        return cache[key]

    constraints = []
    if space.constraint_matrix.size:
        constraints.append(LinearConstraint(space.constraint_matrix, -np.inf, space.constraint_bound))
    solution = minimize(lambda z: surrogate(z).cost, center, jac=lambda z: surrogate(z).gradient, method="SLSQP",
                        bounds=list(zip(lower, upper)), constraints=constraints,
                        options={"maxiter": 30, "ftol": 1e-10})
    candidate = np.clip(solution.x, lower, upper)
    if not space.is_feasible(candidate, tolerance=1e-9):
        raise SolverError(f"the surrogate step left the feasible set at {space.as_dict(candidate)}")
    value = surrogate(candidate).cost
    return candidate, value
