"""The trust-region optimiser (SPEC §10): the PROM at the centre as a nonlinear surrogate.

SciPy's SLSQP solves the surrogate problem with bounds and linear constraints inside the radius (a
fraction of the PROM validity box); a PROM built at the candidate gives the actual reduction, and
ρ = actual / predicted accepts or rejects the step and resizes the radius. A candidate the design
check refuses is pulled back along its step (bisection); a direction refused right at the centre
becomes a cut of the surrogate problem. A run that stalls away from a first-order point (its radius or its
step below the step tolerance) on a PROM whose basis is reused from another centre rebuilds that PROM on its
own basis and starts the radius again (``_on_own_basis``); on its own basis the stall stops the run.

With ``[optimizer] atlas`` the PROM "at" a design is the atlas's at the centre of the leaf holding it
(``PromBuilder.build``): the surrogate is the centre leaf's PROM, its box the trust box around the iterate
intersected with that PROM's validity box (its centre ± its radius), so that every candidate is a design the
surrogate answers; the function minimised is the atlas's answer, each design's leaf PROM at the design.
"""
from __future__ import annotations

import logging

import numpy as np
from scipy.optimize import LinearConstraint, minimize

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.optimization.cost import first_order_at
from aquarom_fenics.optimization.history import history_row, optimality_reason, record
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.reduction.prom import ReducedModel

log = logging.getLogger("aquarom")


def trust_region(scene, space, builder, weights, history, checkpoint, state, safeguard, on_iteration):
    settings = scene.optimizer
    started = safeguard.started
    # The trust radius is a fraction of the PROM validity box; the amplitude and the gait variables enter
    # only the reduced activations (exactly for A; the gait's on a basis that holds each pair's pattern),
    # so their box is their whole range.
    actuation = slice(space.n_shapes, len(space.names))
    half_widths = np.array(scene.validity_radii() + list(space.upper[actuation] - space.lower[actuation]))
    if state is None:
        state = {"center": space.start.tolist(), "radius": settings.initial_radius, "iteration": 0, "cuts": []}
    center = np.array(state["center"])
    cuts = [np.array(cut) for cut in state.get("cuts", [])]
    prom = _build_or_stop(builder, center)
    current = builder.evaluate(prom, center, weights)
    measure = first_order_at(scene, space, current).measure
    if not history:
        record(history, history_row(space, 0, center, current.cost, current.gradient, current.distance,
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
        candidate, predicted_cost = _surrogate_step(builder, prom, space, weights, center,
                                                    radius * trust_box(half_widths, builder.validity_radius(prom),
                                                                       space.n_shapes), cuts, current,
                                                    answered=_answered_box(builder, prom))
        candidate = safeguard.finite(candidate, state["iteration"] + 1)
        step = candidate - center
        iteration = state["iteration"] + 1
        if (np.abs(step).max() < settings.step_tolerance
                or current.cost - predicted_cost <= settings.cost_tolerance * abs(current.cost)):
            restarted = _on_own_basis(scene, space, builder, weights, prom, current, measure)
            if restarted is None:
                reason = "no predicted improvement inside the trust radius (stalled before optimality)"
                break
            prom, current, measure = restarted
            state.update(radius=settings.initial_radius)
            checkpoint.save(state, history, builder)
            continue
        proposed = candidate
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
        # the surrogate's L at the candidate: the step's own value unless the design check shortened it
        predicted = current.cost - (predicted_cost if candidate is proposed
                                    else _surrogate_cost(builder, prom, weights, candidate))
        trial = builder.evaluate(candidate_prom, candidate, weights)
        actual = _actual_reduction(builder, prom, candidate_prom, current, trial, weights)
        ratio = actual[0] / predicted if predicted > 0 else -np.inf
        accepted = ratio > settings.accept_ratio
        trial_measure = first_order_at(scene, space, trial).measure
        log.info("trust region %d: radius %.3g, step %.3g, predicted reduction %.3e, actual %.3e (%s), ρ = %.3g, "
                 "first-order measure %.3g at the candidate", iteration, radius, np.abs(step).max(), predicted,
                 actual[0], actual[1], ratio, trial_measure)
        record(history, history_row(space, iteration, candidate, trial.cost, trial.gradient, trial.distance,
                                     "built" if accepted else "rejected", started, radius=radius,
                                     ratio=float(ratio), optimality=trial_measure), on_iteration)
        radius = resized_radius(radius, ratio, settings.expand_ratio, settings.expand_factor)
        if accepted:
            center, prom, current, measure, cuts = candidate, candidate_prom, trial, trial_measure, []
        elif not builder.shares_basis(prom, candidate_prom) and not scene.optimizer.atlas:
            # (with the atlas the centre's PROM is its leaf's whatever was built since: nothing to recentre)
            prom, current, measure = _recentred(scene, space, builder, weights, prom, current, measure)
        state.update(center=center.tolist(), radius=radius, iteration=iteration, cuts=[cut.tolist() for cut in cuts])
        checkpoint.save(state, history, builder)
        if measure > settings.optimality_tolerance and np.all(radius * half_widths < settings.step_tolerance):
            restarted = _on_own_basis(scene, space, builder, weights, prom, current, measure)
            if restarted is None:
                reason = f"trust radius {radius:.2e} of the validity box below the step tolerance"
                break
            prom, current, measure = restarted
            state.update(radius=settings.initial_radius)
            checkpoint.save(state, history, builder)
    return center, current, reason


def trust_box(half_widths: np.ndarray, prom_radius: np.ndarray, n_shapes: int) -> np.ndarray:
    """The box the trust radius scales: the scene's validity radii, each shape's capped by the centre
    PROM's own radius ``prom_radius`` (``[reduction] validity_change`` caps it where the tensors change
    fast), so that every candidate is a design the centre's PROM answers."""
    box = np.array(half_widths, dtype=float)
    box[:n_shapes] = np.minimum(box[:n_shapes], np.asarray(prom_radius, dtype=float)[:n_shapes])
    return box


SHRINK_RATIO = 0.25
"""ρ below which the trust radius is halved (η₁ of the radius update; steps are accepted above ``accept_ratio``)."""


def resized_radius(radius: float, ratio: float, expand_ratio: float = 0.75, expand_factor: float = 2.0) -> float:
    """The next trust radius (a fraction of the validity box, at most 1): ρ < 1/4: halve; ρ > η₂
    (``expand_ratio``): times ``expand_factor``; otherwise keep. Any 1/4 < η₂ < 1 and factor > 1 is the
    classical update (never larger after ρ < η₁, never smaller after ρ > η₂, bounded above), for which the
    trust region's first-order convergence theory holds (in a run, ``step_tolerance`` may stop it first)."""
    if ratio < SHRINK_RATIO:
        return 0.5 * radius
    if ratio > expand_ratio:
        return min(expand_factor * radius, 1.0)
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


def _recentred(scene, space, builder: PromBuilder, weights, prom, current, measure):
    """The centre's PROM, evaluation and first-order measure after a step rejected on another basis:
    rebuilt at the centre on the basis the builder gives now (the rejected candidate's, which the
    next candidates reuse, or the centre's own), so that the model and the next trials share one
    basis; unchanged if that build is refused."""
    try:
        rebuilt = builder.build(current.z)
        evaluation = builder.evaluate(rebuilt, current.z, weights)
    except (InputError, SolverError) as refused:
        log.warning("trust region: the centre's PROM kept on its basis (a rebuild is refused: %s)", refused)
        return prom, current, measure
    measure = first_order_at(scene, space, evaluation).measure
    log.info("trust region: step rejected on another basis; the centre's PROM rebuilt on the builder's basis "
             "(first-order measure %.3g there)", measure)
    return rebuilt, evaluation, measure


def _on_own_basis(scene, space, builder: PromBuilder, weights, prom, current, measure):
    """(PROM, evaluation, first-order measure) of the centre rebuilt on a basis built at the centre, when the
    run stalls away from a first-order point (its trust radius or its step below the step tolerance) on a PROM
    whose basis is reused from another centre; None when that PROM is on its own basis already or the build is
    refused (the stall stands).

    The rejected steps then said that the model's slopes are wrong there, not that the centre is a first-order
    point: a basis reused from a centre up to half a validity radius away misses the shape change between the
    two, and its projection error moves the PROM's gradient (SO2: the radius fell to the step tolerance at a
    first-order measure of 0.012). Shrinking the radius cannot cure a model error that does not vanish with the
    step, so the model is improved instead (the model-improvement step of derivative-free trust regions) and the
    radius starts again. Bounded: the rebuild leaves the centre's PROM on its own basis, so the next stall stops
    the run unless a trial iteration moved the centre or its basis in between, and ``max_iterations`` bounds
    those."""
    if builder.on_own_basis(prom):
        return None
    try:
        rebuilt = builder.build(current.z, own_basis=True)
        evaluation = builder.evaluate(rebuilt, current.z, weights)
    except (InputError, SolverError) as refused:
        log.warning("trust region: the centre's PROM kept on its reused basis (a build on its own is refused: %s)",
                    refused)
        return None
    rebuilt_measure = first_order_at(scene, space, evaluation).measure
    log.info("trust region: stalled on a reused basis at first-order measure %.3g; the centre's PROM rebuilt on its "
             "own basis (measure %.3g there), the radius reset", measure, rebuilt_measure)
    return rebuilt, evaluation, rebuilt_measure


def _actual_reduction(builder: PromBuilder, prom, trial_prom, current, trial, weights) -> tuple[float, str]:
    """L(z_c) - L(z) measured on one model where there is one, and how it was measured:

    - one basis (the centre's PROM and the candidate's share it, or, with the atlas, are one PROM): L_c(z_c) -
      L_z(z). With ``[optimizer] atlas`` a candidate in the centre's leaf has the centre's PROM, the model
      itself: the actual reduction is the predicted one (ρ = 1), rightly, for the function minimised is the
      atlas's answer L_leaf(z)(z), which is that PROM on the leaf;
    - another basis: L_z(z_c) - L_z(z), the candidate's PROM at both designs. A PROM on another basis carries
      another projection error: its L is offset from the centre's by an amount no step makes (3 % of L on SO2
      at the upper bounds, for a step of 0.002), which the ratio test would read as the step's gain or loss;
    - another basis whose PROM does not answer the centre (z_c beyond its validity radius, which the PROM
      refuses; with the atlas, a centre far from the candidate's leaf centre): L_c(z_c) - L_z(z), each design
      on a PROM that answers it. That is the predicted reduction less the surrogate's own error at the
      candidate, L_z(z) - L_c(z), both PROMs answering z (the surrogate's box is inside its PROM's radius):
      the classical ratio of the function's reduction (the atlas's answer at each design) to the model's."""
    if builder.shares_basis(prom, trial_prom):
        return current.cost - trial.cost, "one basis"
    try:
        return builder.cost(trial_prom, current.z, weights) - trial.cost, "another basis: the candidate's PROM at both"
    except InputError as refused:
        log.info("trust region: the candidate's PROM does not answer the centre (%s); the actual reduction compares "
                 "the centre's PROM at the centre with the candidate's at the candidate", refused)
        return current.cost - trial.cost, "another basis that does not answer the centre: each design on its own PROM"
    except SolverError as failed:
        log.warning("trust region: the candidate's PROM cannot be simulated at the centre (%s); the actual reduction "
                    "compares the two PROMs", failed)
        return current.cost - trial.cost, "another basis that stops at the centre: each design on its own PROM"


def _answered_box(builder: PromBuilder, prom):
    """With ``[optimizer] atlas``: (lower, upper) of the shapes the centre's PROM answers, ξ_c ± R (R its validity
    radius, capped where ``[reduction] validity_change`` caps it); its centre is the atlas leaf's, off the
    iterate. None without the atlas: the PROM is centred on the iterate and the trust box inside R already."""
    if not builder.scene.optimizer.atlas:
        return None
    centre, radius = np.asarray(prom.xi_center, dtype=float), builder.validity_radius(prom)
    return centre - radius, centre + radius


def _surrogate_cost(builder: PromBuilder, prom, weights, z) -> float:
    return builder.cost(prom, z, weights)


def _build_or_stop(builder: PromBuilder, z: np.ndarray) -> ReducedModel:
    try:
        return builder.build(z)
    except InputError as refused:
        raise InputError(f"the PROM cannot be built at {builder.space.as_dict(z)}: {refused}") from None


def _within_cuts(z, center, cuts) -> bool:
    return all(cut @ (z - center) <= 1e-12 for cut in cuts)


def _surrogate_step(builder, prom, space, weights, center, radius, cuts=(), at_center=None,
                    answered=None) -> tuple[np.ndarray, float]:
    """Minimise the surrogate cost (PROM at its centre, simulated at z) inside bounds, constraints,
    radius and the cuts c·(z - z_c) ≤ 0 of directions the design check refused. ``at_center``: the
    surrogate's evaluation at the centre when known (where SLSQP starts). ``answered``: (lower, upper)
    of the shapes the PROM answers, which the box z_c ± radius is intersected with (the atlas)."""
    cache = {}
    if at_center is not None and np.array_equal(at_center.z, center):
        cache[tuple(np.asarray(center, dtype=float))] = at_center

    lower = np.maximum(space.lower, center - radius)
    upper = np.minimum(space.upper, center + radius)
    if answered is not None:      # the centre is answered: kept in the box whatever the rounding
        shapes = slice(0, space.n_shapes)
        lower[shapes] = np.minimum(np.maximum(lower[shapes], answered[0]), center[shapes])
        upper[shapes] = np.maximum(np.minimum(upper[shapes], answered[1]), center[shapes])

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
