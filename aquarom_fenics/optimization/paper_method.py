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
and the descent z ← z - γ W ∇L_b moves the shapes only, with A fixed until the next centre. The
descent on (ξ, A) together stalled: ∂L/∂A is 10-15 times ∂L/∂ξ, so W = 1/‖∇L_b‖_∞ made the shape
steps 1/15 of γ; A moved against its lower bound, its W was halved at every sign change, and the
linearised d, convex in A (d ~ A^1.5), under-predicted every climb in A, so w₁ = 0.2 reached the
iteration limit at A = 0.12 (optimum ≈ 0.14).
"""
from __future__ import annotations

import logging

import dataclasses

import numpy as np
from scipy.optimize import minimize_scalar

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.optimization.cost import (DesignSpace, Evaluation, barrier_scale_at, first_order, first_order_at,
                                              require_interior)
from aquarom_fenics.optimization.history import history_row, optimality_reason, record
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


def paper_method(scene, space, builder, weights, history, checkpoint, state, safeguard, on_iteration):
    settings = scene.optimizer
    started = safeguard.started
    require_interior(space, scene)
    interior = _strictly_inside(space, space.start)
    if state is None:
        state = {"z": interior.tolist(), "iteration": 0, "scaling": np.ones(space.names.__len__()).tolist(),
                 "previous_gradient": None, "since_build": 0, "center": None}
    z = np.array(state["z"])
    scaling = np.array(state["scaling"])
    center = state["center"]
    if center is not None:      # resumed: the PROM of the last build comes back from the cache
        center.setdefault("prom_z", center["z"])
    prom = None if center is None else builder.build(np.array(center["prom_z"]))
    reason = "maximum number of iterations (safeguard)"
    while state["iteration"] < settings.max_iterations:
        iteration = state["iteration"]
        drift = np.inf if center is None else np.abs(z - np.array(center["z"])).max()
        due = center is None or drift > settings.rebuild_threshold or state["since_build"] >= settings.n_rebuild
        # due by the count only, inside the last PROM's validity radius: that PROM, simulated at z, re-linearises
        surrogate = (due and drift <= settings.rebuild_threshold and not state.get("confirm")
                     and builder.trusts(prom, z))
        rebuild = due and not surrogate
        if due:
            try:
                if rebuild:
                    prom = builder.build(z)
                else:
                    builder.refuse_infeasible(prom, z)
            except InputError as refused:      # the mesh check or a stability test refuses z: step back halfway
                if center is None:
                    raise
                if np.abs(z - np.array(center["z"])).max() < settings.step_tolerance:
                    # every step from the last accepted design is refused: it is the answer
                    reason = (f"every step from the last accepted design is refused (within the step tolerance "
                              f"{settings.step_tolerance:g}; by the design check or the stability tests: {refused})")
                    z = np.array(center["z"])
                    break
                log.warning("paper method: %s; stepping back towards the last linearisation centre", refused)
                z = np.array(center["z"]) + 0.5 * (z - np.array(center["z"]))
                scaling *= 0.5
                state.update(z=z.tolist(), scaling=scaling.tolist())
                continue
            z = _best_amplitude(space, builder, prom, weights, z)
            exact = builder.evaluate(prom, z, weights)
            center = {"z": z.tolist(), "distance": exact.distance, "distance_gradient": exact.distance_gradient.tolist(),
                      "prom_z": (z if rebuild else np.array(center["prom_z"])).tolist()}
            state.update(since_build=0, confirm=False)
        distance, distance_gradient = _linearised_distance(center, z)
        cost, gradient = _weighted_cost(space, weights, z, distance, distance_gradient)
        descent = _descent_space(space, z)
        barrier_value, barrier_gradient = barrier(descent, z)
        barrier_scale = barrier_scale_at(settings, cost)
        total_gradient = np.where(descent.free, gradient + barrier_scale * barrier_gradient, 0.0)
        measure = first_order(space, z, cost, gradient, settings.active_tolerance, barrier_scale,
                              space.descent_barrier_rows).measure
        if measure <= settings.optimality_tolerance and not rebuild:
            # optimal by a linearised gradient: confirmed by a PROM built where the barrier's nearly
            # active bounds are active, if its first-order measure there passes; else by one built here
            linearised = Evaluation(z, cost, gradient, distance, distance_gradient)
            snapped = _barrier_gap_closed(space, builder, weights, linearised, settings.barrier_weight)
            snapped_measure = None if snapped is None else first_order_at(scene, space, snapped[1]).measure
            if snapped_measure is not None and snapped_measure <= settings.optimality_tolerance:
                record(history, history_row(space, iteration, z, cost, gradient, distance, "approximated", started,
                                            optimality=measure), on_iteration)
                state.update(iteration=iteration + 1)
                checkpoint.save(state, history, builder)
                names, final = snapped
                reason = (f"{optimality_reason(snapped_measure, settings.optimality_tolerance)} after "
                          f"{', '.join(names)} moved from the barrier iterate onto the bound (a PROM built "
                          f"there; linearised measure at the iterate {measure:.2e})")
                _record_final(scene, space, history, iteration + 1, final, started, on_iteration)
                return final.z, final, reason
            state.update(since_build=settings.n_rebuild, confirm=True)
            continue
        kind = "built" if rebuild else "surrogate" if surrogate else "approximated"
        record(history, history_row(space, iteration, z, cost, gradient, distance, kind, started, optimality=measure),
               on_iteration)
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
                                due, settings)
        step = _along_active_rows(descent, z, -settings.step_size * scaling * total_gradient, scaling,
                                  settings.active_tolerance)
        fraction, blocking = _fraction_to_boundary(descent, z, step)
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
            else:           # a linearised (or surrogate) gradient may be stale: rebuild first
                state.update(since_build=settings.n_rebuild, confirm=True)
            checkpoint.save(state, history, builder)
    if center is not None and np.allclose(z, center["prom_z"]) and prom is not None:
        final = builder.evaluate(prom, _best_amplitude(space, builder, prom, weights, z), weights)
    else:
        final = _final_evaluation(space, builder, weights, z, np.array(center["z"]))
    if not reason.startswith("first-order"):        # a converged iterate's row is the last one recorded
        _record_final(scene, space, history, history[-1]["iteration"] + 1, final, started, on_iteration)
    closed = _barrier_gap_closed(space, builder, weights, final, settings.barrier_weight)
    if closed is not None:
        names, final = closed
        measure = first_order_at(scene, space, final).measure
        reason += (f"; then {', '.join(names)} moved from the barrier iterate onto the bound "
                   f"(first-order measure {measure:.2e} there)")
        _record_final(scene, space, history, history[-1]["iteration"] + 1, final, started, on_iteration)
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
    lower[-1] = upper[-1] = z[-1]
    return dataclasses.replace(space, lower=lower, upper=upper)


def _best_amplitude(space: DesignSpace, builder: PromBuilder, prom, weights, z: np.ndarray) -> np.ndarray:
    """z with A = argmin_{A ∈ [A_lo, A_hi]} L(ξ, A) on ``prom`` (shapes ξ of z fixed).

    L(A) = -w_1 d(ξ, A) + w_2 α A²; the PROM's reduced actuation is linear in A, so the PROM of ξ
    answers for every A. Bounded Brent search (tolerance 1e-5 of A's range, so |∂L/∂A| left
    over is far below the first-order tolerance), then each bound is compared. A design the
    PROM cannot simulate counts as L = +∞; an A* whose PROM gait the stability test refuses
    leaves z's amplitude unchanged."""
    if not space.with_amplitude or space.upper[-1] <= space.lower[-1]:
        return z
    lower, upper = float(space.lower[-1]), float(space.upper[-1])

    def cost(amplitude: float) -> float:
        trial = np.array(z, dtype=float)
        trial[-1] = amplitude
        try:
            return builder.evaluate(prom, trial, weights).cost
        except SolverError:
            return np.inf

    search = minimize_scalar(cost, bounds=(lower, upper), method="bounded",
                             options={"xatol": 1e-5 * (upper - lower)})
    candidates = {float(search.x): float(search.fun), lower: cost(lower), upper: cost(upper)}
    amplitude = min(candidates, key=candidates.get)
    if not np.isfinite(candidates[amplitude]):
        return z
    best = np.array(z, dtype=float)
    best[-1] = amplitude
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


def _along_active_rows(space: DesignSpace, z, step, scaling, tolerance: float) -> np.ndarray:
    """The step with its component into each nearly active linear constraint row removed.

    A row a·z ≤ b with slack ≤ ``tolerance`` · range that the step would shrink (a·Δz > 0) takes
    Δz ← Δz - W a (a·Δz) / (aᵀ W a), so that a·Δz = 0: the step slides along the face in the
    metric of W. Without it the fraction to the boundary cut every step at the face and halved
    W of every parameter in the row, so the motion along the face died out (SO9 stopped on the
    step tolerance with a first-order measure of 0.14, the residual tangential to the face).
    The box bounds are left to the barrier and the bound snapping."""
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
