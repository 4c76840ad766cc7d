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
  reduction, ρ = actual / predicted accepts or rejects the step and resizes the radius (by ρ
  only). A candidate the design check refuses is pulled back along its step to the last design
  that meshes (bisection); a direction refused right at the centre becomes a cut of the surrogate
  problem, the radius unchanged.

Both stop by first-order optimality (``cost.first_order``: KKT residual over the active set,
relative to |L|, below ``optimality_tolerance``) at a design where a PROM was built; step size and
``max_iterations`` are safeguards. ``starts`` > 1 repeats the run from Latin-hypercube feasible
starts (:func:`start_points`), all sharing the PROM cache.

The state after every iteration goes to an atomic checkpoint; a resumed run continues from it to
the same result (PROM builds are deterministic).
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import LinearConstraint, minimize
from scipy.stats import qmc

from aquarom_fenics.reduction.cache import cached_prom
from aquarom_fenics.optimization.cost import (CostWeights, DesignSpace, Evaluation, FirstOrder, design_space, evaluate, first_order,
                   meshable_space, require_interior)
from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.dynamics.reduced_dynamics import reduced_stability
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.io.scene import Scene

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
    optimality: FirstOrder | None = None      # at the optimum, from the PROM's exact gradient
    converged: bool = False                   # optimality.measure ≤ optimality_tolerance

    @property
    def iterations(self) -> int:
        return int(self.history[-1]["iteration"])


STABILITY_STROKES = 2
"""Strokes the horizon must hold before the gait's stability is judged."""


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
        self._refuse_unstable(prom, z)
        return prom

    def _refuse_unstable(self, prom: ReducedModel, z: np.ndarray) -> None:
        """A design whose PROM gait is unstable (Floquet multiplier |μ| > 1.01 over the last stroke,
        ``reduced_stability``) is refused like one the mesh check refuses: the optimisers step back.
        Judged only on horizons of two strokes or more (a start-up from rest is no periodic gait)."""
        actuation = self.scene.actuation
        if self.scene.solver.duration * actuation.frequency < STABILITY_STROKES:
            return
        amplitude = float(z[-1]) if self.space.with_amplitude else None
        stable, reason = reduced_stability(prom, self.scene, z[: self.space.n_shapes], amplitude)
        if not stable:
            raise InputError(f"design {self.space.as_dict(z)} is infeasible: its PROM is unstable ({reason})")

    def evaluate(self, prom, z, weights) -> Evaluation:
        started = time.perf_counter()
        try:
            return evaluate(prom, self.scene, self.space, z, weights)
        finally:
            self.solve_time += time.perf_counter() - started

    def meshes(self, z: np.ndarray) -> bool:
        """The design check of SPEC §4 (det F_1 > 0.1 everywhere) at the shapes of z."""
        try:
            self.fish.design(z[: self.space.n_shapes])
            return True
        except InputError:
            return False


def history_columns(space: DesignSpace) -> list[str]:
    """The columns of a history row, in the order :func:`history_row` makes them."""
    return (["iteration", *(f"xi_{name}" for name in space.names), "cost", *(f"grad_{name}" for name in space.names)]
            + ["distance", "prom", "wall_time", "radius", "ratio", "optimality"])


def history_row(space: DesignSpace, iteration: int, z, cost, gradient, distance, kind: str, started: float,
                radius: float | None = None, ratio: float | None = None, optimality: float | None = None) -> dict:
    """One iteration: ξ, cost, gradient, distance [m], how the PROM was used, the first-order
    measure, and for the trust region its radius (fraction of the validity box) and
    actual/predicted reduction."""
    row = {"iteration": iteration}
    row.update({f"xi_{name}": float(value) for name, value in zip(space.names, z)})
    row["cost"] = float(cost)
    row.update({f"grad_{name}": float(value) for name, value in zip(space.names, gradient)})
    row.update({"distance": float(distance), "prom": kind, "wall_time": time.perf_counter() - started,
                "radius": radius, "ratio": ratio, "optimality": optimality})
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


def optimization_space(scene: Scene, fish: Fish) -> DesignSpace:
    """The scene's design space with its bounds pulled in to where the design meshes."""
    space, notes = meshable_space(design_space(scene), fish)
    for note in notes:
        log.warning("design space: %s", note)
    return space


def optimize(scene: Scene, fish: Fish | None = None, weights: CostWeights | None = None,
             checkpoint_path: Path | None = None, resume: bool = False,
             on_iteration=None, write_checkpoint: bool = True, max_time: float = DEFAULT_MAX_TIME,
             start: np.ndarray | None = None, builder: PromBuilder | None = None) -> OptimizationResult:
    """Run the scene's optimiser from ``start`` (the scene's start point by default);
    ``on_iteration(row)`` sees every history row as it is made.

    Every rank reads a checkpoint to resume from; only ranks with ``write_checkpoint`` write one.
    The run stops at first-order optimality, or after ``scene.optimizer.max_iterations``
    iterations or ``max_time`` seconds. ``builder`` gives PROMs and their evaluations (a
    :class:`PromBuilder` of this scene by default).
    """
    fish = fish or load_fish(scene)
    space = builder.space if builder is not None else optimization_space(scene, fish)
    if start is not None:
        space = dataclasses.replace(space, start=np.asarray(start, dtype=float))
    weights = weights or CostWeights()
    method = scene.optimizer.method
    builder = builder or PromBuilder(scene, fish, space)
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
    optimality = _optimality(scene, space, evaluation)
    log.info("optimisation (%s) stopped: %s; first-order measure %.2e; %d PROM builds (%d reused from the cache), "
             "%.1f s", method, reason, optimality.measure, builder.builds, builder.reused, timings["total"])
    return OptimizationResult(optimum, evaluation, history, builder.builds, reason, space, builder.last_size, timings,
                              builder.reused, optimality, optimality.measure <= scene.optimizer.optimality_tolerance)


def _optimality(scene: Scene, space: DesignSpace, evaluation: Evaluation) -> FirstOrder:
    """First-order measure and active set at an evaluated design; the paper method's barrier
    multipliers μ / s_i count for its inactive rows."""
    settings = scene.optimizer
    barrier_scale = _barrier_scale(settings, evaluation.cost) if settings.method == "paper" else 0.0
    return first_order(space, evaluation.z, evaluation.cost, evaluation.gradient, settings.active_tolerance,
                       barrier_scale)


def _barrier_scale(settings, cost: float) -> float:
    """μ = barrier_weight · |L| of the paper method's L_b = L + μ B."""
    return settings.barrier_weight * max(abs(cost), 1e-12)


def optimality_reason(measure: float, tolerance: float) -> str:
    return f"first-order optimality: measure {measure:.2e} ≤ tolerance {tolerance:g}"


def start_points(space: DesignSpace, count: int, seed: int, meshes) -> list[np.ndarray]:
    """The space's start, then ``count - 1`` Latin-hypercube points of the box (scrambled, seeded)
    that satisfy the linear constraints and the design check ``meshes(z)``.

    Draws at most 20 batches of ``count`` points; raises InputError if too few qualify.
    """
    points = [space.start.copy()]
    sampler = qmc.LatinHypercube(d=len(space.names), seed=seed)
    for _ in range(20):
        if len(points) == count:
            break
        for unit in sampler.random(count):
            z = space.lower + unit * (space.upper - space.lower)
            if len(points) < count and space.is_feasible(z) and meshes(z):
                points.append(z)
    if len(points) < count:
        raise InputError(f"only {len(points)} of [optimizer] starts = {count} feasible, meshable start points found "
                         f"in 20 batches of Latin-hypercube samples; lower starts")
    return points


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
    reason = "maximum number of iterations (safeguard)"
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
        barrier_scale = _barrier_scale(settings, cost)
        total_gradient = np.where(space.free, gradient + barrier_scale * barrier_gradient, 0.0)
        measure = first_order(space, z, cost, gradient, settings.active_tolerance, barrier_scale).measure
        if measure <= settings.optimality_tolerance and not rebuild:
            # optimal by the linearised gradient: confirm with a PROM built here before stopping
            state["since_build"] = settings.n_rebuild
            continue
        _record(history, history_row(space, iteration, z, cost, gradient, distance,
                                     "built" if rebuild else "approximated", started, optimality=measure), on_iteration)
        if measure <= settings.optimality_tolerance:
            reason = optimality_reason(measure, settings.optimality_tolerance)
            state.update(iteration=iteration + 1)
            checkpoint.save(state, history, builder)
            break
        previous = state["previous_gradient"]
        if previous is None:     # W starts at 1/‖∇L_0‖_∞: the first step changes the leading parameter by γ
            scaling /= max(np.abs(total_gradient).max(), 1e-300)
        else:
            scaling = _rescaled(scaling, total_gradient, np.array(previous), barrier_scale * barrier_gradient,
                                rebuild, settings)
        step = -settings.step_size * scaling * total_gradient
        fraction, blocking = _fraction_to_boundary(space, z, step)
        if fraction < 1.0:
            scaling[blocking] *= 0.5
            step = fraction * step
        z = safeguard.finite(z + step, iteration)
        state.update(z=z.tolist(), iteration=iteration + 1, scaling=scaling.tolist(),
                     previous_gradient=total_gradient.tolist(), since_build=state["since_build"] + 1, center=center)
        checkpoint.save(state, history, builder)
        if safeguard.out_of_time():
            reason = safeguard.reason
            break
        if np.linalg.norm(step) < settings.step_tolerance:
            if rebuild and state.get("restarted"):
                reason = f"step {np.linalg.norm(step):.2e} below the step tolerance (stalled before optimality)"
                break
            if rebuild:     # W restarts once, as at the first iteration (1/‖∇L_b‖_∞)
                state.update(scaling=np.ones(z.size).tolist(), previous_gradient=None, restarted=True)
                scaling = np.ones(z.size)
            else:           # a linearised gradient may be stale: rebuild first
                state["since_build"] = settings.n_rebuild
            checkpoint.save(state, history, builder)
    if center is not None and np.allclose(z, center["z"]) and prom is not None:
        final = builder.evaluate(prom, z, weights)
    else:
        final = _final_evaluation(builder, weights, z, np.array(center["z"]))
    if not reason.startswith("first-order"):        # a converged iterate's row is the last one recorded
        _record_final(scene, space, history, history[-1]["iteration"] + 1, final, started, on_iteration)
    closed = _barrier_gap_closed(space, builder, weights, final, settings.barrier_weight)
    if closed is not None:
        names, final = closed
        measure = _optimality(scene, space, final).measure
        reason += (f"; then {', '.join(names)} moved from the barrier iterate onto the bound "
                   f"(first-order measure {measure:.2e} there)")
        _record_final(scene, space, history, history[-1]["iteration"] + 1, final, started, on_iteration)
    return final.z, final, reason


def _record_final(scene, space, history, iteration, final: Evaluation, started, on_iteration) -> None:
    measure = _optimality(scene, space, final).measure
    _record(history, history_row(space, iteration, final.z, final.cost, final.gradient, final.distance, "built",
                                 started, optimality=measure), on_iteration)


def _barrier_gap_closed(space: DesignSpace, builder: PromBuilder, weights, final: Evaluation, barrier_weight: float):
    """The barrier holds a bound off by s_i ≈ μ / |∂L/∂z_i| (complementarity λ_i s_i = μ). A bound
    within √barrier_weight of its range whose gradient pushes towards it (λ_i = μ / s_i would exceed
    s_i, both relative) is taken as active: the design with those parameters on their bounds
    (the weakest-held, by |∂L/∂z_i| · range, let go until it is feasible and meshes) replaces the
    iterate when a PROM built there gives a lower cost.
    Returns (the bounds moved onto, its evaluation) or None."""
    z, gradient = final.z, final.gradient
    width = space.upper - space.lower
    near_lower = space.free & (z - space.lower < np.sqrt(barrier_weight) * width) & (gradient > 0)
    near_upper = space.free & (space.upper - z < np.sqrt(barrier_weight) * width) & (gradient < 0)
    if not (near_lower.any() or near_upper.any()):
        return None
    # the weakest-held bounds are let go, one at a time, until the design is feasible and meshes
    for weakest in [i for i in np.argsort(np.abs(gradient) * width) if near_lower[i] or near_upper[i]]:
        snapped = np.where(near_lower, space.lower, np.where(near_upper, space.upper, z))
        if not (near_lower.any() or near_upper.any()) or (space.is_feasible(snapped) and builder.meshes(snapped)):
            break
        near_lower[weakest] = near_upper[weakest] = False
    if not (near_lower.any() or near_upper.any()):
        return None
    try:
        evaluation = builder.evaluate(builder.build(snapped), snapped, weights)
    except InputError:
        return None
    if evaluation.cost >= final.cost:
        return None
    names = [f"{n} = lower" for n in np.array(space.names)[near_lower]]
    names += [f"{n} = upper" for n in np.array(space.names)[near_upper]]
    return names, evaluation


def _rescaled(scaling, gradient, previous, barrier_part, built: bool, settings) -> np.ndarray:
    """W_i halves where ∂L_b/∂z_i changed sign (the source's rule). Beyond the source, at a design
    where a PROM was just built (a linearised gradient holds no new information), W_i doubles
    where the sign held, the barrier's part μ ∂B/∂z_i is under half of ∂L_b/∂z_i (away from the
    bounds' barrier layer) and the doubled step γ W_i |∂L_b/∂z_i| stays within the rebuild
    threshold: a parameter with a small gradient still reaches its bound."""
    sign_change = np.sign(gradient) * np.sign(previous)
    scaling = np.where(sign_change < 0, 0.5 * scaling, scaling)
    outside_barrier_layer = np.abs(barrier_part) < 0.5 * np.abs(gradient)
    room = 2 * settings.step_size * scaling * np.abs(gradient) <= settings.rebuild_threshold
    return np.where(built & (sign_change > 0) & outside_barrier_layer & room, 2.0 * scaling, scaling)


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
        state = {"center": space.start.tolist(), "radius": settings.initial_radius, "iteration": 0, "cuts": []}
    center = np.array(state["center"])
    cuts = [np.array(cut) for cut in state.get("cuts", [])]
    prom = _build_or_stop(builder, center)
    current = builder.evaluate(prom, center, weights)
    measure = _optimality(scene, space, current).measure
    if not history:
        _record(history, history_row(space, 0, center, current.cost, current.gradient, current.distance,
                                     "built", started, radius=state["radius"], optimality=measure), on_iteration)
    reason = "maximum number of iterations (safeguard)"
    while state["iteration"] < settings.max_iterations:
        if measure <= settings.optimality_tolerance:
            reason = optimality_reason(measure, settings.optimality_tolerance)
            break
        if safeguard.out_of_time():
            reason = safeguard.reason
            break
        radius = state["radius"]
        candidate, predicted_cost = _surrogate_step(builder, prom, space, weights, center, radius * half_widths, cuts)
        candidate = safeguard.finite(candidate, state["iteration"] + 1)
        step = candidate - center
        iteration = state["iteration"] + 1
        if (np.abs(step).max() < settings.step_tolerance
                or current.cost - predicted_cost <= settings.cost_tolerance * abs(current.cost)):
            reason = "no predicted improvement inside the trust radius (stalled before optimality)"
            break
        candidate, candidate_prom = _meshable_candidate(builder, center, candidate, settings.step_tolerance)
        if candidate_prom is None:
            # refused right at the centre: the half-space step·(z - z_c) ≤ 0 is cut from the surrogate problem
            if len(cuts) >= 2 * len(space.names):
                reason = "the design check refuses every descent direction from the centre"
                break
            cuts.append(step)
            state.update(iteration=iteration, cuts=[cut.tolist() for cut in cuts])
            checkpoint.save(state, history, builder)
            continue
        step = candidate - center
        predicted = current.cost - _surrogate_cost(builder, prom, weights, candidate)
        trial = builder.evaluate(candidate_prom, candidate, weights)
        ratio = (current.cost - trial.cost) / predicted if predicted > 0 else -np.inf
        accepted = ratio > settings.accept_ratio
        trial_measure = _optimality(scene, space, trial).measure
        _record(history, history_row(space, iteration, candidate, trial.cost, trial.gradient, trial.distance,
                                     "built" if accepted else "rejected", started, radius=radius,
                                     ratio=float(ratio), optimality=trial_measure), on_iteration)
        radius = _resized_radius(radius, ratio)
        if accepted:
            center, prom, current, measure, cuts = candidate, candidate_prom, trial, trial_measure, []
        state.update(center=center.tolist(), radius=radius, iteration=iteration, cuts=[cut.tolist() for cut in cuts])
        checkpoint.save(state, history, builder)
        if np.all(radius * half_widths < settings.step_tolerance):
            reason = f"trust radius {radius:.2e} of the validity box below the step tolerance"
            break
    return center, current, reason


def _resized_radius(radius: float, ratio: float) -> float:
    """ρ < 1/4: halve; ρ > 3/4: double (at most the validity box); otherwise keep."""
    if ratio < 0.25:
        return 0.5 * radius
    if ratio > 0.75:
        return min(2.0 * radius, 1.0)
    return radius


def _meshable_candidate(builder: PromBuilder, center, candidate, step_tolerance: float, bisections: int = 12):
    """The candidate and its PROM, or the last design along z_c + t (z - z_c) that the design check
    accepts (bisection on t ∈ [0, 1]); (candidate, None) when that step is below the tolerance."""
    step = candidate - center
    if not builder.meshes(candidate):
        meshing, refused = 0.0, 1.0
        for _ in range(bisections):
            middle = 0.5 * (meshing + refused)
            meshing, refused = (middle, refused) if builder.meshes(center + middle * step) else (meshing, middle)
        log.warning("trust region: candidate %s refused by the design check; step shortened to %.3g of it",
                    builder.space.as_dict(candidate), meshing)
        candidate = center + meshing * step
        if np.abs(candidate - center).max() < step_tolerance:
            return candidate, None
    try:
        return candidate, builder.build(candidate)
    except InputError as refused:
        log.warning("trust region: candidate refused (%s)", refused)
        return candidate, None


def _surrogate_cost(builder: PromBuilder, prom, weights, z) -> float:
    return builder.evaluate(prom, z, weights).cost


def _build_or_stop(builder: PromBuilder, z: np.ndarray) -> ReducedModel:
    try:
        return builder.build(z)
    except InputError as refused:
        raise InputError(f"the PROM cannot be built at {builder.space.as_dict(z)}: {refused}") from None


def _within_cuts(z, center, cuts) -> bool:
    return all(cut @ (z - center) <= 1e-12 for cut in cuts)


def _surrogate_step(builder, prom, space, weights, center, radius, cuts=()) -> tuple[np.ndarray, float]:
    """Minimise the surrogate cost (PROM at its centre, simulated at z) inside bounds, constraints,
    radius and the cuts c·(z - z_c) ≤ 0 of directions the design check refused."""
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
    for cut in cuts:
        constraints.append(LinearConstraint(cut[None, :], -np.inf, cut @ center))
    try:
        solution = minimize(lambda z: surrogate(z).cost, center, jac=lambda z: surrogate(z).gradient, method="SLSQP",
                            bounds=list(zip(lower, upper)), constraints=constraints,
                            options={"maxiter": 30, "ftol": 1e-10})
        candidate = np.clip(solution.x, lower, upper)
    except SolverError as failed:      # the surrogate cannot be simulated everywhere: its best point so far
        log.warning("trust region: surrogate solve stopped (%s); taking its best feasible point so far", failed)
        candidate = np.array(min((key for key in cache if _within_cuts(np.array(key), center, cuts)
                                  and space.is_feasible(np.array(key), tolerance=1e-9)),
                                 key=lambda key: cache[key].cost))
    if not space.is_feasible(candidate, tolerance=1e-9):
        raise SolverError(f"the surrogate step left the feasible set at {space.as_dict(candidate)}")
    value = surrogate(candidate).cost
    return candidate, value
