"""The source's optimiser (SPEC §10): gradient descent with a log-barrier and a PROM-linearised trajectory.

z ← z - γ W ∇L_b with L_b = L + μ B, B(z) = -Σ log s_i(z); the diagonal W starts at
1/‖∇L_b(z_0)‖_∞ and is halved along a direction whose gradient component changes sign or whose
bound becomes active; between PROM builds d ≈ d_c + ∇d_c·(z - z_c); a new PROM when any
|z - z_c|_i exceeds ``rebuild_threshold`` or every ``n_rebuild`` iterations, except that a
rebuild due by the count alone, at a design inside the last PROM's validity radius, simulates
that PROM there for the new linearisation (history ``surrogate``) instead of building one.

Co-optimisation (z = (ξ, A)): the amplitude enters the reduced actuation exactly, so the PROM of
the shapes ξ_c is valid over A's whole range. At every exact evaluation (a build or a surrogate)
A is set to its conditional optimum A*(ξ) = argmin_A L(ξ, A) on that PROM (a bounded 1-D search),
and the descent z ← z - γ W ∇L_b moves the shapes only, with A fixed until the next centre: one
W over (ξ, A) is set by ∂L/∂A, much larger than ∂L/∂ξ, and the linearised d is convex in A, so
a joint descent creeps (docs/studies.md, CO).
"""
from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import (CostWeights, DesignSpace, Evaluation, barrier_scale_at, first_order,
                                              first_order_at, require_interior, weighted_cost)
from aquarom_fenics.optimization.history import Checkpoint, Safeguard, history_row, optimality_reason, record
from aquarom_fenics.optimization.paper_state import Linearisation, PaperState
from aquarom_fenics.optimization.prom_builder import PromBuilder

log = logging.getLogger("aquarom")


def barrier(space: DesignSpace, z: np.ndarray) -> tuple[float, np.ndarray]:
    """B(z) = -Σ log s_i(z) and ∇B, over the box bounds of the free parameters and the linear
    inequalities s(z) ≥ 0 (a fixed parameter, lower = upper, has no interior to keep to)."""
    rows = space.barrier_rows
    slacks = space.slacks(z)[rows]
    if np.any(slacks <= 0):
        return np.inf, np.full(z.size, np.nan)
    jacobian = space.slack_jacobian[rows]   # ∂s/∂z
    return float(-np.log(slacks).sum()), -(jacobian / slacks[:, None]).sum(axis=0)


@dataclass
class _Gradients:
    """The cost and its gradients at one iterate, from the linearised distance."""

    descent: DesignSpace            # the space the step moves in (the amplitude fixed)
    distance: float
    distance_gradient: np.ndarray
    cost: float
    gradient: np.ndarray            # ∇L
    barrier_part: np.ndarray        # μ ∇B
    total: np.ndarray               # ∇L_b = ∇L + μ ∇B over the free parameters of the descent
    measure: float                  # first-order measure (cost.first_order)


class _Stop(Exception):
    """The loop ends: ``reason``, and the answer when a step already found it (else None)."""

    def __init__(self, reason: str, answer: tuple[np.ndarray, Evaluation, str] | None = None):
        super().__init__(reason)
        self.reason, self.answer = reason, answer


def paper_method(scene: Scene, space: DesignSpace, builder: PromBuilder, weights: CostWeights, history: list[dict],
                 checkpoint: Checkpoint, state: dict | None, safeguard: Safeguard,
                 on_iteration: Callable[[dict], None]) -> tuple[np.ndarray, Evaluation, str]:
    """Minimise L(z) over ``space`` by the paper method; returns (optimum, its PROM evaluation, stop reason).

    ``state``: a checkpoint's ``state`` to resume from (None: start at the space's start, moved
    strictly inside). Each iteration: (1) :meth:`_PaperRun.linearise` when an exact evaluation is
    due (a PROM build, or the last PROM simulated at z), stepping back halfway towards the centre
    when the design check or a stability test refuses z; (2) :meth:`_PaperRun.gradients` of L_b
    from the linearised distance and the first-order measure; (3) a measure under the tolerance
    is confirmed by an exact evaluation (:meth:`_PaperRun.confirm`), (4) otherwise
    :meth:`_PaperRun.step` z ← z - γ W ∇L_b with W rescaled, slid along nearly active constraint
    rows and cut to the boundary, and the step-tolerance restarts. The run stops at first-order
    optimality, ``max_iterations``, the wall-time safeguard, a stalled step or a refused
    neighbourhood; :meth:`_PaperRun.finish` evaluates the last iterate on a PROM and moves bounds
    the barrier holds off onto them. Every iteration's state goes to ``checkpoint``."""
    require_interior(space, scene)
    run = _PaperRun(scene, space, builder, weights, history, checkpoint, safeguard, on_iteration,
                    PaperState.start(_strictly_inside(space, space.start)) if state is None
                    else PaperState.from_dict(state))
    reason = "maximum number of iterations (safeguard)"
    try:
        while run.state.iteration < run.settings.max_iterations:
            exact = run.linearise()
            if exact is None:
                continue
            rebuild, surrogate = exact
            point = run.gradients()
            if point.measure <= run.settings.optimality_tolerance and not rebuild:
                run.confirm(point)
                continue
            run.record(point, "built" if rebuild else "surrogate" if surrogate else "approximated")
            if point.measure <= run.settings.optimality_tolerance:
                run.state.iteration += 1
                run.save()
                raise _Stop(optimality_reason(point.measure, run.settings.optimality_tolerance))
            run.step(point, rebuild, due=rebuild or surrogate)
    except _Stop as stop:
        if stop.answer is not None:
            return stop.answer
        reason = stop.reason
    return run.finish(reason)


class _PaperRun:
    """One run of the paper method: its fixed inputs, its state and the PROM of the last build."""

    def __init__(self, scene: Scene, space: DesignSpace, builder: PromBuilder, weights: CostWeights,
                 history: list[dict], checkpoint: Checkpoint, safeguard: Safeguard,
                 on_iteration: Callable[[dict], None], state: PaperState):
        self.scene, self.space, self.builder, self.weights = scene, space, builder, weights
        self.history, self.checkpoint, self.safeguard, self.on_iteration = history, checkpoint, safeguard, on_iteration
        self.settings = scene.optimizer
        self.state = state
        # resumed: the PROM of the last build comes back from the cache
        self.prom = None if state.center is None else builder.build(state.center.prom_z)

    def save(self) -> None:
        self.checkpoint.save(self.state.to_dict(), self.history, self.builder)

    def record(self, point: _Gradients, kind: str) -> None:
        record(self.history, history_row(self.space, self.state.iteration, self.state.z, point.cost, point.gradient,
                                         point.distance, kind, self.safeguard.started, optimality=point.measure),
               self.on_iteration)

    def linearise(self) -> tuple[bool, bool] | None:
        """A new linearisation centre at z when one is due: a PROM built there (``rebuild``), or
        due by the count alone inside the last PROM's validity radius, that PROM simulated at z
        (``surrogate``). Returns (rebuild, surrogate); None when z was refused and stepped back
        halfway towards the centre (the iteration starts again); raises _Stop when every step
        from the centre is refused."""
        state, settings, center = self.state, self.settings, self.state.center
        drift = np.inf if center is None else np.abs(state.z - center.z).max()
        due = center is None or drift > settings.rebuild_threshold or state.since_build >= settings.n_rebuild
        surrogate = (due and drift <= settings.rebuild_threshold and not state.confirm
                     and self.builder.trusts(self.prom, state.z))
        rebuild = due and not surrogate
        if not due:
            return False, False
        try:
            if rebuild:
                self.prom = self.builder.build(state.z)
            else:
                self.builder.refuse_infeasible(self.prom, state.z)
        except InputError as refused:      # the mesh check or a stability test refuses z: step back halfway
            if center is None:
                raise
            if np.abs(state.z - center.z).max() < settings.step_tolerance:
                # every step from the last accepted design is refused: it is the answer
                state.z = center.z.copy()
                raise _Stop(f"every step from the last accepted design is refused (within the step tolerance "
                            f"{settings.step_tolerance:g}; by the design check or the stability tests: {refused})")
            log.warning("paper method: %s; stepping back towards the last linearisation centre", refused)
            state.z = center.z + 0.5 * (state.z - center.z)
            state.scaling *= 0.5
            return None
        state.z = _best_amplitude(self.space, self.builder, self.prom, self.weights, state.z)
        exact = self.builder.evaluate(self.prom, state.z, self.weights)
        state.center = Linearisation(state.z.copy(), exact.distance, np.array(exact.distance_gradient, dtype=float),
                                     state.z.copy() if rebuild else center.prom_z)
        state.since_build, state.confirm = 0, False
        return rebuild, surrogate

    def gradients(self) -> _Gradients:
        """L, ∇L from the linearised distance at z; ∇L_b = ∇L + μ ∇B over the descent's free
        parameters; the first-order measure (the amplitude's rows under no barrier)."""
        space, settings, z = self.space, self.settings, self.state.z
        distance, distance_gradient = self.state.center.at(z)
        cost, gradient = weighted_cost(space, self.weights, z, distance, distance_gradient)
        descent = _descent_space(space, z)
        _, barrier_gradient = barrier(descent, z)
        barrier_scale = barrier_scale_at(settings, cost)
        total = np.where(descent.free, gradient + barrier_scale * barrier_gradient, 0.0)
        measure = first_order(space, z, cost, gradient, settings.active_tolerance, barrier_scale,
                              space.descent_barrier_rows).measure
        return _Gradients(descent, distance, distance_gradient, cost, gradient, barrier_scale * barrier_gradient,
                          total, measure)

    def confirm(self, point: _Gradients) -> None:
        """Optimal by a linearised gradient: confirmed by a PROM built where the barrier's nearly
        active bounds are active, if its first-order measure there passes (_Stop with the answer);
        else the next iteration evaluates here exactly."""
        space, settings, state = self.space, self.settings, self.state
        linearised = Evaluation(state.z, point.cost, point.gradient, point.distance, point.distance_gradient)
        snapped = _barrier_gap_closed(space, self.builder, self.weights, linearised, settings.barrier_weight)
        snapped_measure = None if snapped is None else first_order_at(self.scene, space, snapped[1]).measure
        if snapped_measure is not None and snapped_measure <= settings.optimality_tolerance:
            self.record(point, "approximated")
            state.iteration += 1
            self.save()
            names, final = snapped
            reason = (f"{optimality_reason(snapped_measure, settings.optimality_tolerance)} after "
                      f"{', '.join(names)} moved from the barrier iterate onto the bound (a PROM built "
                      f"there; linearised measure at the iterate {point.measure:.2e})")
            _record_final(self.scene, space, self.history, state.iteration, final, self.safeguard.started,
                          self.on_iteration)
            raise _Stop(reason, (final.z, final, reason))
        state.since_build, state.confirm = settings.n_rebuild, True

    def step(self, point: _Gradients, rebuild: bool, due: bool) -> None:
        """z ← z - γ W ∇L_b: W starts at 1/‖∇L_b‖_∞ (the first step changes the leading parameter
        by γ), then :func:`_rescaled`; the step slides along nearly active constraint rows and is
        cut to keep a tenth of every slack (W halved for the parameters it blocks). A step below
        the step tolerance at an exact centre restarts W once, then stops (stalled); at a
        linearised one the next iteration re-evaluates exactly. Raises _Stop when the run ends."""
        state, settings = self.state, self.settings
        if state.previous_gradient is None:
            state.scaling /= max(np.abs(point.total).max(), 1e-300)
        else:
            state.scaling = _rescaled(state.scaling, point.total, state.previous_gradient, point.barrier_part, due,
                                      settings)
        step = _along_active_rows(point.descent, state.z, -settings.step_size * state.scaling * point.total,
                                  state.scaling, settings.active_tolerance)
        fraction, blocking = _fraction_to_boundary(point.descent, state.z, step)
        if fraction < 1.0:
            state.scaling[blocking] *= 0.5
            step = fraction * step
        state.z = self.safeguard.finite(state.z + step, state.iteration)
        state.iteration += 1
        state.previous_gradient = point.total
        state.since_build += 1
        self.save()
        if self.safeguard.out_of_time():
            raise _Stop(self.safeguard.reason)
        if np.linalg.norm(step) < settings.step_tolerance:
            if rebuild and state.restarted:
                raise _Stop(f"step {np.linalg.norm(step):.2e} below the step tolerance (stalled before optimality)")
            if rebuild:     # W restarts once, as at the first iteration (1/‖∇L_b‖_∞)
                state.scaling, state.previous_gradient, state.restarted = np.ones(state.z.size), None, True
            else:           # a linearised (or surrogate) gradient may be stale: rebuild first
                state.since_build, state.confirm = settings.n_rebuild, True
            self.save()

    def finish(self, reason: str) -> tuple[np.ndarray, Evaluation, str]:
        """The last iterate evaluated on a PROM (its own, or one built there), then the bounds the
        barrier holds off moved onto (:func:`_barrier_gap_closed`) when that lowers the cost."""
        space, builder, weights, z, center = self.space, self.builder, self.weights, self.state.z, self.state.center
        if center is not None and np.allclose(z, center.prom_z) and self.prom is not None:
            final = builder.evaluate(self.prom, _best_amplitude(space, builder, self.prom, weights, z), weights)
        else:
            final = _final_evaluation(space, builder, weights, z, center.z)
        started = self.safeguard.started
        if not reason.startswith("first-order"):        # a converged iterate's row is the last one recorded
            _record_final(self.scene, space, self.history, self.history[-1]["iteration"] + 1, final, started,
                          self.on_iteration)
        closed = _barrier_gap_closed(space, builder, weights, final, self.settings.barrier_weight)
        if closed is not None:
            names, final = closed
            measure = first_order_at(self.scene, space, final).measure
            reason += (f"; then {', '.join(names)} moved from the barrier iterate onto the bound "
                       f"(first-order measure {measure:.2e} there)")
            _record_final(self.scene, space, self.history, self.history[-1]["iteration"] + 1, final, started,
                          self.on_iteration)
        return final.z, final, reason


def _record_final(scene, space, history, iteration, final: Evaluation, started, on_iteration) -> None:
    measure = first_order_at(scene, space, final).measure
    record(history, history_row(space, iteration, final.z, final.cost, final.gradient, final.distance, "built",
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
        prom = builder.build(snapped)
        snapped = _best_amplitude(space, builder, prom, weights, snapped)
        evaluation = builder.evaluate(prom, snapped, weights)
    except InputError:
        return None
    if evaluation.cost >= final.cost:
        return None
    names = [f"{n} = lower" for n in np.array(space.names)[near_lower]]
    names += [f"{n} = upper" for n in np.array(space.names)[near_upper]]
    return names, evaluation


def _rescaled(scaling, gradient, previous, barrier_part, exact: bool, settings) -> np.ndarray:
    """W_i halves where ∂L_b/∂z_i changed sign (the source's rule). Beyond the source, at a design
    where a PROM was just built or simulated (a linearised gradient holds no new information), W_i doubles
    where the sign held, the barrier's part μ ∂B/∂z_i is under half of ∂L_b/∂z_i (away from the
    bounds' barrier layer) and the doubled step γ W_i |∂L_b/∂z_i| stays within the rebuild
    threshold: a parameter with a small gradient still reaches its bound."""
    sign_change = np.sign(gradient) * np.sign(previous)
    scaling = np.where(sign_change < 0, 0.5 * scaling, scaling)
    outside_barrier_layer = np.abs(barrier_part) < 0.5 * np.abs(gradient)
    room = 2 * settings.step_size * scaling * np.abs(gradient) <= settings.rebuild_threshold
    return np.where(exact & (sign_change > 0) & outside_barrier_layer & room, 2.0 * scaling, scaling)


def _final_evaluation(space: DesignSpace, builder: PromBuilder, weights, z, last_built) -> Evaluation:
    """A PROM built at the last iterate (stepping back towards the last built design if refused),
    the amplitude at its conditional optimum there."""
    for _ in range(20):
        try:
            prom = builder.build(z)
            break
        except InputError:
            z = last_built + 0.5 * (z - last_built)
    else:
        z = last_built
        prom = builder.build(z)
    return builder.evaluate(prom, _best_amplitude(space, builder, prom, weights, z), weights)


def _descent_space(space: DesignSpace, z: np.ndarray) -> DesignSpace:
    """The space the descent steps in: with co-optimisation the amplitude fixed at its value in z
    (lower = upper = A; set by :func:`_best_amplitude` at every exact evaluation), so that
    neither the step, W nor the barrier act on it."""
    if not space.with_amplitude:
        return space
    lower, upper = space.lower.copy(), space.upper.copy()
    index = space.amplitude_index
    lower[index] = upper[index] = z[index]
    return dataclasses.replace(space, lower=lower, upper=upper)


def _best_amplitude(space: DesignSpace, builder: PromBuilder, prom, weights, z: np.ndarray) -> np.ndarray:
    """z with A = argmin_{A ∈ [A_lo, A_hi]} L(ξ, A) on ``prom`` (shapes ξ of z fixed).

    L(A) = -w_1 d(ξ, A) + w_2 α A²; the PROM's reduced actuation is linear in A, so the PROM of ξ
    answers for every A. Bounded Brent search on L alone (PROM runs without sensitivities;
    tolerance 1e-5 of A's range, so |∂L/∂A| left over is far below the first-order
    tolerance), then each bound is compared. A design the
    PROM cannot simulate counts as L = +∞; an A* whose PROM gait the stability test refuses
    leaves z's amplitude unchanged."""
    index = space.amplitude_index
    if not space.with_amplitude or space.upper[index] <= space.lower[index]:
        return z
    lower, upper = float(space.lower[index]), float(space.upper[index])

    def cost(amplitude: float) -> float:
        trial = np.array(z, dtype=float)
        trial[index] = amplitude
        try:
            return builder.cost(prom, trial, weights)
        except SolverError:
            return np.inf

    search = minimize_scalar(cost, bounds=(lower, upper), method="bounded",
                             options={"xatol": 1e-5 * (upper - lower)})
    candidates = {float(search.x): float(search.fun), lower: cost(lower), upper: cost(upper)}
    amplitude = min(candidates, key=candidates.get)
    if not np.isfinite(candidates[amplitude]):
        return z
    best = np.array(z, dtype=float)
    best[index] = amplitude
    try:
        builder.refuse_infeasible(prom, best)
    except InputError:
        return z
    return best


def _strictly_inside(space: DesignSpace, z: np.ndarray) -> np.ndarray:
    """Move a start on a bound slightly inside (the barrier needs interior points); a start on a
    linear constraint moves halfway towards the most interior point of the feasible set."""
    margin = 1e-3 * (space.upper - space.lower)
    z = np.clip(z, space.lower + margin, space.upper - margin)
    if np.all(space.slacks(z)[space.barrier_rows] > 0):
        return z
    return 0.5 * (z + space.most_interior_point())


def _along_active_rows(space: DesignSpace, z, step, scaling, tolerance: float) -> np.ndarray:
    """The step with its component into each nearly active linear constraint row removed.

    A row a·z ≤ b with slack ≤ ``tolerance`` · range that the step would shrink (a·Δz > 0) takes
    Δz ← Δz - W a (a·Δz) / (aᵀ W a), so that a·Δz = 0: the step slides along the face in the
    metric of W, where the fraction to the boundary alone would cut it at the face and halve W
    of every parameter in the row. The box bounds are left to the barrier and the bound snapping."""
    rows = space.constraint_matrix
    if not rows.size:
        return step
    slacks = space.slacks(z)[2 * len(space.names):]
    ranges = space.slack_ranges[2 * len(space.names):]
    weight = np.where(space.free, scaling, 0.0)
    for row, slack, width in zip(rows, slacks, ranges):
        scaled = weight * row
        if slack <= tolerance * width and row @ step > 0 and row @ scaled > 0:
            step = step - scaled * (row @ step) / (row @ scaled)
    return step


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
