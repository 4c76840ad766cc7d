"""The compiled reduced kernel with designs in lockstep: blocks of ``LANES`` designs advanced through each time
step together, their arrays with the design (lane) axis last (``kernel_lanes``), so that the terms, the thrust's
banded products and the sensitivity step run on vectors across the designs and W's products are matrix
products for the whole block.

Each lane follows ``reduced_kernel.integrate_design`` exactly: its own generalized-α modified Newton (its
iteration count, refresh decisions, factors and convergence test ‖r‖ ≤ tol · max(scale, floor)) and its
direct-differentiation sensitivities. The block evaluates every lane at each iteration; a lane that has
converged keeps its iterate (its evaluation point, hence the state its sensitivity step reads, unchanged) and
does no update, and the block's step ends when every lane has converged or failed. A lane that fails is
reported failed (its state reset to rest for the block's remaining steps, its results unused), as the
per-design kernel reports it; the caller integrates it alone with the step control. The eight lanes' Newton
matrices are factorised together without pivoting (``lane_lu``, the per-design kernel's ``kernel_terms.factorize``
lane by lane); a lane that fails its check is factorised alone with partial pivoting. A batch that does not fill
its last block is padded with copies of its last design. Transition matrices (``transition_from`` > 0) are
integrated per design only.
"""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.dynamics.compiled import TypedCall, jit as _jit
from aquarom_fenics.dynamics.kernel_lanes import (LANES, between_lanes, derivative_lanes, elastic_lanes,
                                                  point_kinematics_lanes, residual_lanes, sensitivity_terms_lanes,
                                                  tangents_lanes, times_lanes)
from aquarom_fenics.dynamics.kernel_lanes_thrust import (LAGRANGIAN_ENTRIES, banded_tangents_lanes,
                                                         force_gradients_lanes, half_blocks_lanes, newton_matrix_lanes)
from aquarom_fenics.dynamics.kernel_terms import lu_factor, lu_solve
from aquarom_fenics.dynamics.lane_lu import factor_lanes, solve_lanes

OK, FAILED = 0, 1


@_jit
def _factor(matrices, lane, factors, pivots):
    """factors[lane] = LU of S (m, m) of one lane of matrices (m, m, LANES) with partial pivoting (for a lane that
    ``factor_lanes`` does not accept, as ``kernel_terms.factorize`` falls back); False if singular."""
    m = matrices.shape[0]
    for i in range(m):
        for k in range(m):
            factors[lane, i, k] = matrices[i, k, lane]
    return lu_factor(factors[lane], pivots[lane])


@_jit
def integrate_block(  # noqa: PLR0913, PLR0915 (the block's arrays; one routine as integrate_design)
        n_steps, h, alpha_m, alpha_f, beta, gamma, tolerance, max_iterations, contraction, per_factorization,
        refresh_each_step, floor, units, distance_mask, amplitude_mask,
        pairs, pair_of_triple, triples, force_coefficients, tangent_coefficients, coefficients_t,
        weights, weight_derivatives, mass, damping, mass_gradient, damping_gradient, com_weights, com_gradient,
        amplitude, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient,
        has_thrust, lagrangian, moving_rest, rows, own_node, other_node, rest_rows, length, rest_tangent,
        thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient,
        has_drag, drag_direction, drag_gradient, drag_row, tail_row,
        sensitivities, amplitude_sensitivity, parameter_terms, result, gradient_out):
    """Integrate one block; result (LANES, 3) = (distance, tail amplitude, status) per lane, gradient_out
    (LANES, columns). Arrays per design: ``reduced_kernel.integrate_design``'s with the lane axis last."""
    m = mass.shape[0]
    p = weight_derivatives.shape[0]
    n_muscles = muscle_constant.shape[0]
    halves = own_node.size
    columns = (p if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    k_u = 1.0 - alpha_f
    k_v = (1.0 - alpha_f) * gamma / (beta * h)
    k_a = (1.0 - alpha_m) / (beta * h * h)
    n_mono, n_t = force_coefficients.shape[0], tangent_coefficients.shape[0]
    elastic_force, elastic_tangent = np.empty((m, n_mono, LANES)), np.empty((m * m, n_t, LANES))
    elastic_lanes(weights, force_coefficients, tangent_coefficients, m, elastic_force, elastic_tangent)
    mono, tangent_mono = np.empty((n_mono, LANES)), np.empty((n_t, LANES))
    state = np.zeros((10, halves, LANES))
    entries = np.zeros((LAGRANGIAN_ENTRIES, halves * LANES))
    n_points = rows.shape[0]
    points = rows.reshape((2 * n_points, m))
    transposed = np.ascontiguousarray(points.T)
    rest_points = rest_rows.reshape((2 * n_points, rest_rows.shape[2]))
    k_banded, c_banded = np.zeros((n_points, 3, 2, 2, LANES)), np.zeros((n_points, 3, 2, 2, LANES))
    m_banded, s_banded = np.zeros((n_points, 3, 2, 2, LANES)), np.zeros((n_points, 3, 2, 2, LANES))
    work = np.zeros((2 * n_points, m, LANES))
    kinematics, force = np.zeros((3, 2 * n_points, LANES)), np.zeros((2 * n_points, LANES))
    at_step, at_new = np.zeros((3, 2 * n_points, LANES)), np.zeros((2 * n_points, LANES))
    thrust_forces = np.zeros((2 * n_points, p, LANES))
    inverse_length = 1.0 / length
    u, v, a = np.zeros((m, LANES)), np.zeros((m, LANES)), np.zeros((m, LANES))
    u_new, v_new, a_new = np.zeros((m, LANES)), np.zeros((m, LANES)), np.zeros((m, LANES))
    u_pred, v_pred = np.zeros((m, LANES)), np.zeros((m, LANES))
    eu, ev, ea = np.zeros((m, LANES)), np.zeros((m, LANES)), np.zeros((m, LANES))
    residual = np.zeros((m, LANES))
    norm, scale = np.zeros(LANES), np.zeros(LANES)
    matrix = np.zeros((m, m, LANES))
    factors, pivots = np.zeros((LANES, m, m)), np.zeros((LANES, m), np.int64)       # pivoted lanes' factors
    exact, exact_pivots = np.zeros((LANES, m, m)), np.zeros((LANES, m), np.int64)
    lane_factors, exact_lanes, fresh = np.zeros((m, m, LANES)), np.zeros((m, m, LANES)), np.zeros((m, m, LANES))
    for i in range(m):
        lane_factors[i, i, :] = 1.0
    accepted, pivoted = np.zeros(LANES, np.bool_), np.zeros(LANES, np.bool_)
    update, solved = np.zeros((m, 1, LANES)), np.zeros((m, columns, LANES))
    stiffness, damping_t, mass_t = np.zeros((m, m, LANES)), np.zeros((m, m, LANES)), np.zeros((m, m, LANES))
    activations = np.zeros((n_muscles, LANES))
    sens, sens_new = np.zeros((3, m, columns, LANES)), np.zeros((3, m, columns, LANES))
    rhs, thrust_rhs = np.zeros((m, columns, LANES)), np.zeros((m, columns, LANES))
    stacked = np.zeros((m, 3 * columns, LANES))
    right = np.zeros((2 * n_points, columns, LANES))
    combination = np.zeros((m, columns, LANES))
    status = np.zeros(LANES, np.int64)
    have_factors, pending, refresh = np.zeros(LANES, np.bool_), np.zeros(LANES, np.bool_), np.zeros(LANES, np.bool_)
    with_factors, previous_norm = np.zeros(LANES, np.int64), np.zeros(LANES)
    distance_sum, amplitude_max = np.zeros(LANES), np.zeros(LANES)
    distance_count = 1 if distance_mask[0] else 0
    gradient_sum, total = np.zeros((columns, LANES)), np.zeros(LANES)
    newton_a = 1.0 / (beta * h * h)

    for step in range(1, n_steps + 1):
        for n in range(n_muscles):
            for l in range(LANES):
                activations[n, l] = amplitude[l] * units[step, n, l]
        for i in range(m):
            for l in range(LANES):
                u_pred[i, l] = u[i, l] + h * v[i, l] + h * h * (0.5 - beta) * a[i, l]
                v_pred[i, l] = v[i, l] + h * (1.0 - gamma) * a[i, l]
                u_new[i, l] = u_pred[i, l]
        if has_thrust:                    # W (u_n, v_n, a_n): each iterate's kinematics from W u_{n+1} alone
            times_lanes(points, u, at_step[0])
            times_lanes(points, v, at_step[1])
            times_lanes(points, a, at_step[2])
        for l in range(LANES):
            pending[l] = status[l] == OK
            with_factors[l] = 0
            previous_norm[l] = np.inf
        for iteration in range(max_iterations + 1):
            for i in range(m):
                for l in range(LANES):
                    a_new[i, l] = (u_new[i, l] - u_pred[i, l]) * newton_a
                    v_new[i, l] = v_pred[i, l] + gamma * h * a_new[i, l]
            between_lanes(u, u_new, alpha_f, eu)
            between_lanes(v, v_new, alpha_f, ev)
            between_lanes(a, a_new, alpha_m, ea)
            if has_thrust:
                times_lanes(points, u_new, at_new)
                point_kinematics_lanes(at_new, at_step, h, alpha_m, alpha_f, beta, gamma, kinematics)
            residual_lanes(eu, ev, ea, residual, activations, mono, tangent_mono, pairs, pair_of_triple, triples,
                           elastic_force, mass, damping, muscle_constant, muscle_linear, has_thrust, lagrangian,
                           transposed, own_node, other_node, length, inverse_length, rest_tangent,
                           thrust_weights, tail_weight, state, has_drag, drag_direction, drag_row, kinematics, force,
                           norm, scale)
            any_pending, any_refresh = False, False
            for l in range(LANES):
                refresh[l] = False
                if not pending[l]:
                    continue
                if not math.isfinite(norm[l]) or (norm[l] > tolerance * max(scale[l], floor)
                                                  and iteration == max_iterations):
                    status[l], pending[l] = FAILED, False
                elif norm[l] <= tolerance * max(scale[l], floor):
                    pending[l] = False                                  # converged
                else:
                    slow = norm[l] > contraction * previous_norm[l]
                    worn = with_factors[l] >= per_factorization or (iteration == 0 and refresh_each_step)
                    refresh[l] = not have_factors[l] or slow or worn
                    any_refresh = any_refresh or refresh[l]
                    any_pending = True
            if not any_pending:
                break
            if any_refresh:
                tangents_lanes(ev, activations, tangent_mono, elastic_tangent, mass, damping, muscle_linear, has_drag,
                               drag_direction, drag_row, stiffness, damping_t, mass_t)
                if has_thrust:
                    half_blocks_lanes(state, length, thrust_weights, tail_weight, lagrangian, own_node, other_node,
                                      k_banded, c_banded, m_banded, entries)
                newton_matrix_lanes(k_u, k_v, k_a, stiffness, damping_t, mass_t, has_thrust, k_banded, c_banded,
                                    m_banded, s_banded, points, transposed, work, matrix)
                factor_lanes(matrix, fresh, accepted)
                for l in range(LANES):
                    if refresh[l]:
                        pivoted[l] = not accepted[l]
                        if accepted[l]:
                            for i in range(m):
                                for k in range(m):
                                    lane_factors[i, k, l] = fresh[i, k, l]
                        if accepted[l] or _factor(matrix, l, factors, pivots):
                            have_factors[l] = True
                            with_factors[l] = 0
                        else:
                            status[l], pending[l] = FAILED, False
            solve_lanes(lane_factors, residual.reshape((m, 1, LANES)), update)
            for l in range(LANES):
                if pending[l]:
                    with_factors[l] += 1
                    previous_norm[l] = norm[l]
                    if pivoted[l]:
                        for i in range(m):
                            update[i, 0, l] = residual[i, l]
                        lu_solve(factors[l], pivots[l], update[:, :, l])
                    for i in range(m):
                        u_new[i, l] -= update[i, 0, l]
        for i in range(m):
            for l in range(LANES):
                a_new[i, l] = (u_new[i, l] - u_pred[i, l]) * newton_a
                v_new[i, l] = v_pred[i, l] + gamma * h * a_new[i, l]
        if columns:
            tangents_lanes(ev, activations, tangent_mono, elastic_tangent, mass, damping, muscle_linear, has_drag,
                           drag_direction, drag_row, stiffness, damping_t, mass_t)
            if has_thrust:
                half_blocks_lanes(state, length, thrust_weights, tail_weight, lagrangian, own_node, other_node,
                                  k_banded, c_banded, m_banded, entries)
                if sensitivities and parameter_terms:
                    force_gradients_lanes(state, length, lagrangian, thrust_weight_gradient, tail_weight_gradient,
                                          own_node, other_node, thrust_forces)
            derivative_lanes(parameter_terms, eu, ev, ea, activations, units[step], mono, coefficients_t,
                             weight_derivatives, mass_gradient, damping_gradient, muscle_constant, muscle_linear,
                             muscle_constant_gradient, muscle_linear_gradient, has_thrust, thrust_forces, transposed,
                             has_drag, drag_gradient, drag_row, sensitivities, amplitude_sensitivity, rhs)
            for i in range(m):
                for c in range(columns):
                    for l in range(LANES):
                        u_p = sens[0, i, c, l] + h * sens[1, i, c, l] + h * h * (0.5 - beta) * sens[2, i, c, l]
                        v_p = sens[1, i, c, l] + h * (1.0 - gamma) * sens[2, i, c, l]
                        sens_new[0, i, c, l], sens_new[1, i, c, l] = u_p, v_p
                        v_between = v_p if alpha_f == 0.0 else (1.0 - alpha_f) * v_p + alpha_f * sens[1, i, c, l]
                        combination[i, c, l] = v_between - k_v * u_p
            sensitivity_terms_lanes(k_a, alpha_f, alpha_m, rhs, stiffness, damping_t, mass_t, combination, sens_new[0],
                                    sens[0], sens[2], thrust_rhs)
            if has_thrust:
                for i in range(m):
                    for c in range(columns):
                        for l in range(LANES):
                            stacked[i, c, l] = alpha_f * sens[0, i, c, l]
                            stacked[i, columns + c, l] = combination[i, c, l]
                            stacked[i, 2 * columns + c, l] = k_a * sens_new[0, i, c, l] - alpha_m * sens[2, i, c, l]
                moved = np.dot(points, stacked.reshape((m, 3 * columns * LANES))).reshape(
                    (2 * n_points, 3 * columns, LANES))
                if moving_rest and parameter_terms and sensitivities:
                    for row in range(2 * n_points):
                        for c in range(p):
                            for l in range(LANES):
                                moved[row, c, l] += rest_points[row, c]
                right[:] = 0.0
                banded_tangents_lanes(k_banded, c_banded, m_banded, moved, right)
                projected = np.dot(transposed, right.reshape((2 * n_points, columns * LANES)))
                for i in range(m):
                    for c in range(columns):
                        for l in range(LANES):
                            thrust_rhs[i, c, l] += projected[i, c * LANES + l]
            newton_matrix_lanes(k_u, k_v, k_a, stiffness, damping_t, mass_t, has_thrust, k_banded, c_banded,
                                m_banded, s_banded, points, transposed, work, matrix)
            factor_lanes(matrix, exact_lanes, accepted)
            solve_lanes(exact_lanes, thrust_rhs, solved)
            for l in range(LANES):
                if status[l] != OK or accepted[l]:
                    continue
                if not _factor(matrix, l, exact, exact_pivots):
                    status[l] = FAILED
                    continue
                for i in range(m):
                    for c in range(columns):
                        solved[i, c, l] = thrust_rhs[i, c, l]
                lu_solve(exact[l], exact_pivots[l], solved[:, :, l])
            for i in range(m):
                for c in range(columns):
                    for l in range(LANES):
                        a_c = (solved[i, c, l] - sens_new[0, i, c, l]) * newton_a
                        sens_new[1, i, c, l] = sens_new[1, i, c, l] + gamma * h * a_c
                        sens_new[2, i, c, l] = a_c
                        sens_new[0, i, c, l] = solved[i, c, l]
            sens[:] = sens_new
        u[:] = u_new
        v[:] = v_new
        a[:] = a_new
        for l in range(LANES):
            if status[l] != OK:                         # a failed lane rests: its numbers stay finite and unused
                for i in range(m):
                    u[i, l] = v[i, l] = a[i, l] = 0.0
                    for c in range(columns):
                        sens[0, i, c, l] = sens[1, i, c, l] = sens[2, i, c, l] = 0.0
        if distance_mask[step]:
            distance_count += 1
            total[:] = 0.0
            for i in range(m):
                for l in range(LANES):
                    total[l] += com_weights[i, l] * u[i, l]
            distance_sum += total
            for c in range(columns):
                total[:] = 0.0
                for i in range(m):
                    for l in range(LANES):
                        total[l] += com_weights[i, l] * sens[0, i, c, l]
                        if c < p and sensitivities:
                            total[l] += com_gradient[c, i, l] * u[i, l]
                gradient_sum[c] += total
        if amplitude_mask[step]:
            for l in range(LANES):
                tail = 0.0
                for i in range(m):
                    tail += tail_row[i] * u[i, l]
                amplitude_max[l] = max(amplitude_max[l], abs(tail))
    for l in range(LANES):
        result[l, 0] = distance_sum[l] / distance_count
        result[l, 1] = amplitude_max[l]
        result[l, 2] = status[l]
        for c in range(columns):
            gradient_out[l, c] = gradient_sum[c, l] / distance_count


@_jit
def integrate_blocks(scalars, settings, units, distance_mask, amplitude_mask, shared, per_design, flags, results,
                     gradients):
    """Every block in turn (``lane_arguments``' arrays: per design (blocks, …, LANES)); results (blocks, LANES, 3),
    gradients (blocks, LANES, columns)."""
    n_steps, max_iterations, per_factorization, _, refresh_each_step = settings
    h, alpha_m, alpha_f, beta, gamma, tolerance, contraction, floor = scalars
    pairs, pair_of_triple, triples, force_coefficients, tangent_coefficients, coefficients_t, rows, own_node, \
        other_node, rest_rows, drag_row, tail_row = shared
    has_thrust, lagrangian, moving_rest, has_drag, sensitivities, amplitude_sensitivity, parameter_terms = flags
    (weights, weight_derivatives, mass, damping, mass_gradient, damping_gradient, com_weights, com_gradient,
     amplitudes, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient, length,
     rest_tangent, thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient, drag_direction,
     drag_gradient) = per_design
    for b in range(results.shape[0]):
        integrate_block(
            n_steps, h, alpha_m, alpha_f, beta, gamma, tolerance, max_iterations, contraction, per_factorization,
            refresh_each_step != 0, floor, units[b], distance_mask, amplitude_mask, pairs, pair_of_triple, triples,
            force_coefficients,
            tangent_coefficients, coefficients_t, weights[b], weight_derivatives[b], mass[b], damping[b],
            mass_gradient[b], damping_gradient[b], com_weights[b], com_gradient[b], amplitudes[b],
            muscle_constant[b], muscle_linear[b], muscle_constant_gradient[b], muscle_linear_gradient[b],
            has_thrust, lagrangian, moving_rest, rows, own_node, other_node, rest_rows, length[b], rest_tangent[b],
            thrust_weights[b], tail_weight[b], thrust_weight_gradient[b], tail_weight_gradient[b], has_drag,
            drag_direction[b], drag_gradient[b], drag_row, tail_row, sensitivities, amplitude_sensitivity,
            parameter_terms, results[b], gradients[b])


def to_lanes(values: np.ndarray, blocks: int) -> np.ndarray:
    """(blocks, …, LANES) of a per-design array (B, …): design b in block b // LANES, lane b % LANES; the last
    block padded with copies of the last design."""
    index = np.minimum(np.arange(blocks * LANES), values.shape[0] - 1)
    grouped = values[index].reshape((blocks, LANES) + values.shape[1:])
    return np.ascontiguousarray(np.moveaxis(grouped, 1, -1))


def lane_arguments(arguments: tuple, batch: int) -> tuple:
    """``integrate_blocks``' arguments from ``Packed.arguments`` (``integrate_all``'s) of a batch."""
    scalars, settings, units, distance_mask, amplitude_mask, shared, per_design, flags = arguments
    if settings[3] > 0:
        raise ValueError("transition matrices are integrated per design")
    blocks = -(-batch // LANES)
    force_coefficients = shared[3]
    shared = shared[:5] + (np.ascontiguousarray(force_coefficients.T),) + shared[5:]
    per_design = tuple(to_lanes(values, blocks) for values in per_design)
    return scalars, settings, to_lanes(units, blocks), distance_mask, amplitude_mask, shared, per_design, flags


def part(arguments: tuple, rows: slice) -> tuple:
    """``Packed.arguments`` of the designs ``rows`` of a batch (its per-design arrays and activation units)."""
    scalars, settings, units, distance_mask, amplitude_mask, shared, per_design, flags = arguments
    return (scalars, settings, units[rows], distance_mask, amplitude_mask, shared,
            tuple(values[rows] for values in per_design), flags)


_integrate_blocks = TypedCall(integrate_blocks)
"""``integrate_blocks`` typed once per kind of arguments, not at every call (``machine_code.TypedCall``)."""


def integrate_lockstep(arguments: tuple, batch: int, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """(results (B, 3) = (distance, tail amplitude, status), gradients (B, columns)) of a batch's
    ``Packed.arguments``, its designs in blocks of ``LANES`` (the last block padded)."""
    blocks = -(-batch // LANES)
    results = np.zeros((blocks, LANES, 3))
    gradients = np.zeros((blocks, LANES, columns))
    _integrate_blocks(*lane_arguments(arguments, batch), results, gradients)
    return results.reshape(blocks * LANES, 3)[:batch], gradients.reshape(blocks * LANES, columns)[:batch]
