"""The batched reduced integration of :mod:`batched` compiled (numba): one design at a time, every step, every
Newton iteration and every sensitivity step in machine code.

numpy's batched solve spends its time in the calls, not in the arithmetic: an 8-unknown system takes
microseconds to assemble and solve, each numpy call about one. Here the same steps run as loops over the
design's arrays: the generalized-α modified Newton of ``integrator._Newton`` (the same refresh rules and test
‖r‖ ≤ tol · max(scale, floor)) and the direct-differentiation sensitivities of
``reduced_dynamics.propagate_sensitivity``, on the terms that :class:`~.batched_system.BatchedSystem` prepares
per design (``kernel_pack.pack`` reads them): the terms in ``kernel_terms``, the thrust's segment law on
half-segments in ``kernel_thrust``. The tests compare the kernel with ``simulate_reduced`` to 1e-12 on every
thrust variant. A design integrated alone takes the distance's gradient from the discrete adjoint of that
sensitivity step (``kernel_adjoint``: one reverse sweep over the stored steps, one transposed solve per step
whatever the number of parameters) unless ``integrate_packed(adjoint=False)`` asks for the forward columns.

A design whose step fails (no convergence, a non-finite residual, a singular matrix) is reported failed; the
caller integrates it alone with the step control (as the numpy batch does). A batch of several designs runs in
blocks of eight designs advanced through each step together (``lockstep_kernel``: the same Newton sequence per
design; a last block of fewer than ``LOCKSTEP_TAIL`` designs one by one). Compiled once per machine into numba's
cache beside these modules (``python -m aquarom_fenics.dynamics.reduced_kernel``, which ``make setup`` runs):
about a minute and a half.
"""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.dynamics.compiled import TypedCall, available, jit as _jit, refresh_stale_cache
from aquarom_fenics.dynamics.kernel_adjoint import reverse_sweep
from aquarom_fenics.dynamics.kernel_pack import Packed, pack, synthetic
from aquarom_fenics.dynamics.kernel_terms import (between, derivative_at, design_elastic, factorize, lu_solve,
                                                  residual_at, tangents_at)
from aquarom_fenics.dynamics.kernel_thrust import (banded_tangents, half_blocks, newton_matrix_into,
                                                   point_kinematics, step_points)
from aquarom_fenics.dynamics.lockstep_kernel import LANES, integrate_lockstep, part

__all__ = ["available", "integrate_all", "integrate_packed", "transition_packed", "pack", "Packed", "synthetic", "warm_up", "OK", "FAILED"]

OK, FAILED = 0, 1


@_jit
def exact_newton_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear, has_drag,
                    drag_direction, drag_row, has_thrust, state, length, thrust_weights, tail_weight, lagrangian,
                    own_node, other_node, k_u, k_v, k_a, points, transposed, work, s_banded, stiffness, damping_t,
                    mass_t, k_banded, c_banded, m_banded, exact, factors, pivots):
    """At an evaluation point: the tangents K_t, C_t, M_t and the thrust's K_J, C_J, M_J (into the given arrays), the
    exact S = k_u K + k_v C + k_a M of the full tangents and its LU; False when S is singular. What a Newton refresh,
    the forward sensitivity step and the adjoint's stores (at a converged step's point) all need."""
    tangents_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear, has_drag,
                drag_direction, drag_row, stiffness, damping_t, mass_t)
    if has_thrust:
        half_blocks(state, length, thrust_weights, tail_weight, lagrangian, own_node, other_node, k_banded, c_banded,
                    m_banded)
    newton_matrix_into(k_u, k_v, k_a, stiffness, damping_t, mass_t, has_thrust, k_banded, c_banded, m_banded,
                       s_banded, points, transposed, work, exact)
    return factorize(exact, factors, pivots)


@_jit
def record_step(step, eu, ev, ea, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear,
                has_drag, drag_direction, drag_row, has_thrust, state, length, thrust_weights, tail_weight, lagrangian,
                own_node, other_node, k_u, k_v, k_a, points, transposed, work, s_banded, exact, mono, tangents,
                banded, factors, pivots, states, evaluations, monos, activation_history):
    """What the adjoint's reverse sweep reads of a converged step, stored at ``step``: the tangents K_t, C_t, M_t and
    the thrust's K_J, C_J, M_J at the evaluation point, the LU of the exact S = k_u K + k_v C + k_a M (pivots[step, 0]
    = -1 when singular), the half-segments' state, (η, η̇, η̈), the monomials and the activations."""
    if not exact_newton_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear,
                           has_drag, drag_direction, drag_row, has_thrust, state, length, thrust_weights, tail_weight,
                           lagrangian, own_node, other_node, k_u, k_v, k_a, points, transposed, work, s_banded,
                           tangents[step, 0], tangents[step, 1], tangents[step, 2], banded[step, 0], banded[step, 1],
                           banded[step, 2], exact, factors[step], pivots[step]):
        pivots[step, 0] = -1
    states[step] = state
    evaluations[step, 0] = eu
    evaluations[step, 1] = ev
    evaluations[step, 2] = ea
    monos[step] = mono
    activation_history[step] = activations


@_jit
def integrate_design(  # noqa: PLR0913 (the packed arrays of one design)
        n_steps, h, alpha_m, alpha_f, beta, gamma, tolerance, max_iterations, contraction, per_factorization,
        refresh_each_step, floor, units, distance_mask, amplitude_mask,
        pairs, pair_of_triple, triples, force_coefficients, tangent_coefficients,
        weights, weight_derivatives, mass, damping, mass_gradient, damping_gradient, com_weights, com_gradient,
        amplitude, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient,
        has_thrust, lagrangian, moving_rest, rows, own_node, other_node, rest_rows, length, rest_tangent,
        thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient,
        has_drag, drag_direction, drag_gradient, drag_row, tail_row,
        sensitivities, amplitude_sensitivity, parameter_terms, transition_from, adjoint, result, gradient_out,
        transition_out):
    """Integrate one design; result = (distance, tail amplitude, status), gradient_out (columns,).

    With ``adjoint`` the gradient comes from one reverse sweep over the stored steps (``kernel_adjoint``: each
    step's exact Newton factors, tangents and evaluation point kept) instead of one forward column per parameter.

    ``transition_from`` = n > 0 (the step whose start t_{n-1} opens the window): instead of the sensitivities,
    transition_out (3, m, 3m) = Φ = ∂s(T)/∂s(t_{n-1}) of s = (η, η̇, η̈), the columns ∂s/∂s(t_{n-1}) started at
    the identity and propagated with ∂r/∂ξ = 0 over steps n … N (``reduced_dynamics.transition_matrix``)."""
    m = mass.shape[0]
    p = weight_derivatives.shape[0]
    n_muscles = muscle_constant.shape[0]
    halves = own_node.size
    transition = transition_from > 0
    columns = 3 * m if transition else (p if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    k_u = 1.0 - alpha_f
    k_v = (1.0 - alpha_f) * gamma / (beta * h)
    k_a = (1.0 - alpha_m) / (beta * h * h)
    elastic_force, elastic_tangent = design_elastic(weights, force_coefficients, tangent_coefficients, m)
    n_mono, n_t = force_coefficients.shape[0], tangent_coefficients.shape[0]
    mono, tangent_mono = np.empty(n_mono), np.empty(n_t)
    state = np.zeros((halves, 10))
    n_points = rows.shape[0]
    points = rows.reshape((2 * n_points, m))                       # W: rows (x, y) of each point
    transposed = np.ascontiguousarray(points.T)                    # Wᵀ
    rest_points = rest_rows.reshape((2 * n_points, rest_rows.shape[2]))
    k_banded, c_banded = np.zeros((n_points, 3, 2, 2)), np.zeros((n_points, 3, 2, 2))
    m_banded, s_banded = np.zeros((n_points, 3, 2, 2)), np.zeros((n_points, 3, 2, 2))
    work = np.zeros((2 * n_points, m))
    at_step, kinematics = np.zeros((2 * n_points, 3)), np.zeros((2 * n_points, 3))
    inverse_length = 1.0 / length
    u, v, a = np.zeros(m), np.zeros(m), np.zeros(m)
    u_new, v_new, a_new = np.zeros(m), np.zeros(m), np.zeros(m)
    u_pred, v_pred = np.zeros(m), np.zeros(m)
    eu, ev, ea = np.zeros(m), np.zeros(m), np.zeros(m)
    residual = np.zeros((m, 1))
    matrix, factors, pivots = np.zeros((m, m)), np.zeros((m, m)), np.zeros(m, np.int64)
    exact, exact_factors, exact_pivots = np.zeros((m, m)), np.zeros((m, m)), np.zeros(m, np.int64)   # S converged
    stiffness, damping_t, mass_t = np.zeros((m, m)), np.zeros((m, m)), np.zeros((m, m))
    activations = np.zeros(n_muscles)
    sens = np.zeros((3, m, columns))
    sens_new = np.zeros((3, m, columns))
    rhs = np.zeros((m, columns))
    thrust_rhs = np.zeros((m, columns))
    stacked = np.zeros((m, 3 * columns))
    right = np.zeros((2 * n_points, columns))
    combination = np.zeros((m, columns))
    have_factors = False
    backward = adjoint and columns > 0 and not transition
    stored = n_steps + 1 if backward else 1
    history_factors, history_pivots = np.empty((stored, m, m)), np.empty((stored, m), np.int64)   # steps 1 … N
    history_tangents = np.empty((stored, 3, m, m))                # K_t, C_t, M_t at each converged point
    history_banded = np.empty((stored, 3, n_points, 3, 2, 2))      # the thrust's K_J, C_J, M_J
    history_state = np.empty((stored, halves, 10))
    evaluations = np.zeros((stored, 3, m))                        # (η, η̇, η̈) at the evaluation point; row 0 zero
    history_mono = np.zeros((stored, n_mono))
    history_activations = np.zeros((stored, n_muscles))
    distance_sum, distance_count, amplitude_max = 0.0, 0, 0.0
    gradient_sum = np.zeros(columns)
    if distance_mask[0]:
        distance_count += 1            # the state at rest (zero) may open the window of a short run
    result[2] = OK

    for step in range(1, n_steps + 1):
        for n in range(n_muscles):
            activations[n] = amplitude * units[step, n]
        # predict: u_p = u + h v + h²(½ - β) a, v_p = v + h (1 - γ) a
        for i in range(m):
            u_pred[i] = u[i] + h * v[i] + h * h * (0.5 - beta) * a[i]
            v_pred[i] = v[i] + h * (1.0 - gamma) * a[i]
            u_new[i] = u_pred[i]
        if has_thrust:                    # W (u_n, v_n, a_n): each iterate's kinematics from W u_{n+1} alone
            step_points(points, u, v, a, at_step)
        with_factors = 0
        previous_norm = np.inf
        converged = False
        for iteration in range(max_iterations + 1):
            for i in range(m):
                a_new[i] = (u_new[i] - u_pred[i]) * (1.0 / (beta * h * h))
                v_new[i] = v_pred[i] + gamma * h * a_new[i]
            between(u, u_new, alpha_f, eu)
            between(v, v_new, alpha_f, ev)
            between(a, a_new, alpha_m, ea)
            if has_thrust:
                point_kinematics(np.dot(points, u_new), at_step, h, alpha_m, alpha_f, beta, gamma, kinematics)
            norm, scale = residual_at(eu, ev, ea, residual[:, 0], activations, mono, tangent_mono, pairs,
                                      pair_of_triple, triples, elastic_force, mass, damping, muscle_constant,
                                      muscle_linear, has_thrust, lagrangian, kinematics, transposed, own_node,
                                      other_node, length, inverse_length, rest_tangent, thrust_weights, tail_weight,
                                      state, has_drag, drag_direction, drag_row)
            if not math.isfinite(norm):
                result[2] = FAILED
                return
            if norm <= tolerance * max(scale, floor):
                converged = True
                break
            if iteration == max_iterations:
                break
            slow = norm > contraction * previous_norm
            worn = with_factors >= per_factorization or (iteration == 0 and refresh_each_step)
            if not have_factors or slow or worn:
                if not exact_newton_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping,
                                       muscle_linear, has_drag, drag_direction, drag_row, has_thrust, state, length,
                                       thrust_weights, tail_weight, lagrangian, own_node, other_node, k_u, k_v, k_a,
                                       points, transposed, work, s_banded, stiffness, damping_t, mass_t, k_banded,
                                       c_banded, m_banded, matrix, factors, pivots):
                    result[2] = FAILED
                    return
                have_factors = True
                with_factors = 0
            with_factors += 1
            previous_norm = norm
            lu_solve(factors, pivots, residual)
            for i in range(m):
                u_new[i] -= residual[i, 0]
        if not converged:
            result[2] = FAILED
            return
        for i in range(m):
            a_new[i] = (u_new[i] - u_pred[i]) * (1.0 / (beta * h * h))
            v_new[i] = v_pred[i] + gamma * h * a_new[i]
        if transition and step == transition_from:
            sens[:] = 0.0
            for i in range(m):
                for block in range(3):
                    sens[block, i, block * m + i] = 1.0
        if backward:
            record_step(step, eu, ev, ea, activations, tangent_mono, pairs, elastic_tangent, mass, damping,
                        muscle_linear, has_drag, drag_direction, drag_row, has_thrust, state, length, thrust_weights,
                        tail_weight, lagrangian, own_node, other_node, k_u, k_v, k_a, points, transposed, work,
                        s_banded, exact, mono, history_tangents, history_banded, history_factors, history_pivots,
                        history_state, evaluations, history_mono, history_activations)
            if history_pivots[step, 0] < 0:
                result[2] = FAILED
                return
        elif columns and (not transition or step >= transition_from):
            # the converged step differentiated (reduced_dynamics.propagate_sensitivity) at its evaluation point
            # (eu, ev, ea), where the last residual was evaluated: its monomials and thrust state are current
            if not exact_newton_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping,
                                   muscle_linear, has_drag, drag_direction, drag_row, has_thrust, state, length,
                                   thrust_weights, tail_weight, lagrangian, own_node, other_node, k_u, k_v, k_a, points,
                                   transposed, work, s_banded, stiffness, damping_t, mass_t, k_banded, c_banded,
                                   m_banded, exact, exact_factors, exact_pivots):
                result[2] = FAILED
                return
            if transition:
                rhs[:] = 0.0
            else:
                derivative_at(parameter_terms, eu, ev, ea, activations, units[step], mono, force_coefficients,
                              weight_derivatives, mass_gradient, damping_gradient, muscle_constant, muscle_linear,
                              muscle_constant_gradient, muscle_linear_gradient, has_thrust, points, own_node,
                              other_node, state, length, thrust_weight_gradient, tail_weight_gradient, lagrangian,
                              has_drag, drag_gradient, drag_row, sensitivities, amplitude_sensitivity, rhs)
            # rhs = -∂r/∂ξ - C (η̇'_{n+1-α_f} - v_f η'_p) + a_f M η'_p - α_f K η'_n - α_m M η̈'_n, with
            # η̇'_{n+1-α_f} = (1 - α_f) η̇'_p + α_f η̇'_n: combination = that bracket
            for i in range(m):
                for c in range(columns):
                    u_p = sens[0, i, c] + h * sens[1, i, c] + h * h * (0.5 - beta) * sens[2, i, c]
                    v_p = sens[1, i, c] + h * (1.0 - gamma) * sens[2, i, c]
                    sens_new[0, i, c], sens_new[1, i, c] = u_p, v_p          # kept: the predictors
                    v_between = v_p if alpha_f == 0.0 else (1.0 - alpha_f) * v_p + alpha_f * sens[1, i, c]
                    combination[i, c] = v_between - k_v * u_p
            for i in range(m):
                for c in range(columns):
                    total = -rhs[i, c]
                    for k in range(m):
                        total += (-damping_t[i, k] * combination[k, c] + k_a * mass_t[i, k] * sens_new[0, k, c]
                                  - alpha_f * stiffness[i, k] * sens[0, k, c]
                                  - alpha_m * mass_t[i, k] * sens[2, k, c])
                    thrust_rhs[i, c] = total
            if has_thrust:
                # the thrust's tangents -Wᵀ J W on the same columns: Wᵀ (K (α_f W η'_n + ∂x_rest/∂ξ) + C W (the
                # bracket) - M W (a_f η'_p - α_m η̈'_n)), with -∂r/∂ξ's part from rest stations that move (-Wᵀ K
                # ∂x_rest/∂ξ_k, columns k < p): one product W X of the three column sets, one Wᵀ Y
                for i in range(m):
                    for c in range(columns):
                        stacked[i, c] = alpha_f * sens[0, i, c]
                        stacked[i, columns + c] = combination[i, c]
                        stacked[i, 2 * columns + c] = k_a * sens_new[0, i, c] - alpha_m * sens[2, i, c]
                moved = np.dot(points, stacked)
                if moving_rest and parameter_terms and sensitivities and not transition:
                    for row in range(2 * n_points):
                        for c in range(p):
                            moved[row, c] += rest_points[row, c]
                right[:] = 0.0
                banded_tangents(k_banded, c_banded, m_banded, moved, right)
                projected = np.dot(transposed, right)
                for i in range(m):
                    for c in range(columns):
                        thrust_rhs[i, c] += projected[i, c]
            lu_solve(exact_factors, exact_pivots, thrust_rhs)
            for i in range(m):
                for c in range(columns):
                    a_c = (thrust_rhs[i, c] - sens_new[0, i, c]) * (1.0 / (beta * h * h))
                    sens_new[1, i, c] = sens_new[1, i, c] + gamma * h * a_c
                    sens_new[2, i, c] = a_c
                    sens_new[0, i, c] = thrust_rhs[i, c]
            sens[:] = sens_new
        u[:] = u_new
        v[:] = v_new
        a[:] = a_new
        if distance_mask[step]:
            com = 0.0
            for i in range(m):
                com += com_weights[i] * u[i]
            distance_sum += com
            distance_count += 1
            for c in range(columns):
                total = 0.0
                for i in range(m):
                    if not backward:
                        total += com_weights[i] * sens[0, i, c]
                    if c < p and sensitivities:
                        total += com_gradient[c, i] * u[i]
                gradient_sum[c] += total
        if amplitude_mask[step]:
            tail = 0.0
            for i in range(m):
                tail += tail_row[i] * u[i]
            amplitude_max = max(amplitude_max, abs(tail))
    if backward:
        parameters = sensitivities and parameter_terms
        moved_rest = moving_rest and parameters
        reverse_sweep(
            n_steps, h, alpha_m, alpha_f, beta, gamma, k_v, k_a, distance_mask, com_weights, units, history_factors,
            history_pivots, history_tangents, history_banded, has_thrust, points, transposed, moved_rest, rest_points,
            history_state, length, lagrangian, own_node, other_node, evaluations, history_activations, history_mono, force_coefficients, weight_derivatives, mass_gradient,
            damping_gradient, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient,
            has_drag, drag_gradient, drag_row, thrust_weight_gradient, tail_weight_gradient,
            parameters, amplitude_sensitivity, gradient_sum)
    result[0] = distance_sum / distance_count
    result[1] = amplitude_max
    if transition:
        transition_out[:] = sens
    for c in range(columns):
        gradient_out[c] = gradient_sum[c] / distance_count

@_jit
def integrate_all(scalars, settings, units, distance_mask, amplitude_mask, shared, per_design, flags, results,
                  gradients, transitions, adjoint):
    """Every design of the batch in turn (``Packed``'s arrays; ``units`` (B, steps + 1, N): each design's unit
    activations at the steps' evaluation times); results (B, 3), gradients (B, columns); transitions
    (B, 3, m, 3m) if settings' ``transition_from`` > 0 (else unused)."""
    n_steps, max_iterations, per_factorization, transition_from, refresh_each_step = settings
    h, alpha_m, alpha_f, beta, gamma, tolerance, contraction, floor = scalars
    pairs, pair_of_triple, triples, force_coefficients, tangent_coefficients, rows, own_node, other_node, \
        rest_rows, drag_row, tail_row = shared
    has_thrust, lagrangian, moving_rest, has_drag, sensitivities, amplitude_sensitivity, parameter_terms = flags
    (weights, weight_derivatives, mass, damping, mass_gradient, damping_gradient, com_weights, com_gradient,
     amplitudes, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient, length,
     rest_tangent, thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient, drag_direction,
     drag_gradient) = per_design
    for b in range(results.shape[0]):
        integrate_design(
            n_steps, h, alpha_m, alpha_f, beta, gamma, tolerance, max_iterations, contraction, per_factorization,
            refresh_each_step != 0, floor, units[b], distance_mask, amplitude_mask, pairs, pair_of_triple, triples,
            force_coefficients,
            tangent_coefficients, weights[b], weight_derivatives[b], mass[b], damping[b], mass_gradient[b],
            damping_gradient[b], com_weights[b], com_gradient[b], amplitudes[b], muscle_constant[b],
            muscle_linear[b], muscle_constant_gradient[b], muscle_linear_gradient[b], has_thrust, lagrangian,
            moving_rest, rows, own_node, other_node, rest_rows, length[b], rest_tangent[b], thrust_weights[b],
            tail_weight[b], thrust_weight_gradient[b], tail_weight_gradient[b], has_drag, drag_direction[b],
            drag_gradient[b], drag_row, tail_row, sensitivities, amplitude_sensitivity, parameter_terms,
            transition_from, adjoint, results[b], gradients[b], transitions[b])


_integrate_all = TypedCall(integrate_all)
"""``integrate_all`` typed once per kind of arguments, not at every call (``machine_code.TypedCall``)."""


LOCKSTEP_TAIL = 6
"""Designs that fill a block of the lockstep kernel (``lockstep_kernel``) only this far or more are integrated in
one padded block; fewer, one by one (a block of 8 lanes costs about six designs integrated alone)."""
LOCKSTEP_LARGEST = 13
"""The largest reduced size m integrated in lockstep: a block's elastic tangent holds m² × (1 + m + m(m+1)/2)
coefficients per lane (m = 24: 12 MB a block, out of the caches), and at m = 24 the lockstep kernel was slower
than one design at a time (docs/devlog.md)."""


def integrate_packed(packed: Packed, lockstep: bool = True, adjoint: bool = True):
    """(distance (B,), tail amplitude (B,), failed (B,) bool, distance gradient (B, columns) or None).

    The designs integrated alone take their gradient from the adjoint's reverse sweep (``kernel_adjoint``) with
    ``adjoint``, else from one forward sensitivity column per parameter (as the lockstep kernel does); the two
    agree to rounding.

    With ``lockstep`` (and m ≤ ``LOCKSTEP_LARGEST``) the designs run in blocks of ``LANES`` (``lockstep_kernel``),
    a last block of fewer than ``LOCKSTEP_TAIL`` designs one by one; without, every design alone. The two agree to
    rounding."""
    results = np.zeros((packed.batch, 3))
    gradients = np.zeros((packed.batch, packed.columns))
    tail = packed.batch % LANES if packed.batch % LANES < LOCKSTEP_TAIL else 0
    size = packed.arguments[6][2].shape[1]                   # m of the per-design mass matrices (B, m, m)
    in_blocks = packed.batch - tail if lockstep and size <= LOCKSTEP_LARGEST else 0
    if in_blocks:
        results[:in_blocks], gradients[:in_blocks] = integrate_lockstep(part(packed.arguments, slice(0, in_blocks)),
                                                                        in_blocks, packed.columns)
    if in_blocks < packed.batch:
        alone = slice(in_blocks, packed.batch)
        _integrate_all(*part(packed.arguments, alone), results[alone], gradients[alone], np.zeros((0, 0, 0, 0)),
                       adjoint)
    failed = results[:, 2] != OK
    distance, amplitude = results[:, 0].copy(), results[:, 1].copy()
    distance[failed] = amplitude[failed] = np.nan
    return distance, amplitude, failed, gradients if packed.columns else None


def transition_packed(packed: Packed, m: int):
    """(Φ (B, 3m, 3m), failed (B,) bool) of a batch packed with ``transition_from`` > 0: Φ = ∂s(T)/∂s(t_w) of
    s = (η, η̇, η̈) of each design (``reduced_dynamics.transition_matrix``)."""
    results = np.zeros((packed.batch, 3))
    gradients = np.zeros((packed.batch, packed.columns))
    transitions = np.zeros((packed.batch, 3, m, 3 * m))
    _integrate_all(*packed.arguments, results, gradients, transitions, False)
    return transitions.reshape(packed.batch, 3 * m, 3 * m), results[:, 2] != OK


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel's one signature and the lockstep kernel's on a small
    synthetic batch; a cache compiled from other kernel sources is removed first (``compiled.refresh_stale_cache``)."""
    refresh_stale_cache()
    packed = synthetic()
    distance, _, failed, _ = integrate_packed(packed, lockstep=False)
    results, _ = integrate_lockstep(packed.arguments, packed.batch, packed.columns)      # a padded block
    if (failed.any() or not np.isfinite(distance).all() or results[0, 2] != OK
            or abs(results[0, 0] - distance[0]) > 1e-12 * abs(distance[0])):
        raise RuntimeError("the compiled reduced kernel failed on its synthetic batch")


if __name__ == "__main__":
    import time as clock
    started = clock.perf_counter()
    warm_up()
    print(f"setup: compiled reduced kernel ready ({clock.perf_counter() - started:.1f} s)")
