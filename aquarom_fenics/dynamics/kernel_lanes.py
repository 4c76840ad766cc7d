"""The reduced terms of ``kernel_terms`` and ``kernel_thrust`` on a block of ``LANES`` designs at once: every
per-design array carries the lane (design) axis last and contiguous, (…, LANES); the arrays that all designs
share (W, the Taylor terms' coefficients, the monomials' indices) have no lane axis. Each function computes what
its per-design namesake does, lane by lane (the same formulas; sums in another order, so equal to rounding).

What runs on vectors across the lanes: numba's compiler does not vectorise a loop over the lanes of arrays it
cannot prove apart (a loop of eight is unrolled, then left scalar), so the hot parts hold the eight lanes in
values: the contractions with one accumulator per lane (``contract_first``, ``contract_second``, ``times_lanes``)
and the thrust's half-segments on lane tuples (``lane_values``).
"""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.lane_values import add, add_to, load, load3, mul, neg, splat, store3, sub

LANES = 8
"""Designs advanced together (a compile-time constant of the loops over the lanes; ``contract_first`` and
``contract_second`` spell out its eight accumulators)."""


@_jit
def contract_first(matrix, vector, out):
    """out[r, l] += Σ_k A[k, r, l] x[k, l] of every lane (A (K, R, LANES), x (K, LANES)): eight accumulators,
    one per lane, so that the eight lanes' products run as vectors."""
    for r in range(matrix.shape[1]):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 0.0
        for k in range(matrix.shape[0]):
            a0 += matrix[k, r, 0] * vector[k, 0]
            a1 += matrix[k, r, 1] * vector[k, 1]
            a2 += matrix[k, r, 2] * vector[k, 2]
            a3 += matrix[k, r, 3] * vector[k, 3]
            a4 += matrix[k, r, 4] * vector[k, 4]
            a5 += matrix[k, r, 5] * vector[k, 5]
            a6 += matrix[k, r, 6] * vector[k, 6]
            a7 += matrix[k, r, 7] * vector[k, 7]
        out[r, 0] += a0
        out[r, 1] += a1
        out[r, 2] += a2
        out[r, 3] += a3
        out[r, 4] += a4
        out[r, 5] += a5
        out[r, 6] += a6
        out[r, 7] += a7


@_jit
def contract_second(matrix, vector, out):
    """out[r, l] += Σ_k A[r, k, l] x[k, l] of every lane (A (R, K, LANES), x (K, LANES)), as ``contract_first``."""
    for r in range(matrix.shape[0]):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 0.0
        for k in range(matrix.shape[1]):
            a0 += matrix[r, k, 0] * vector[k, 0]
            a1 += matrix[r, k, 1] * vector[k, 1]
            a2 += matrix[r, k, 2] * vector[k, 2]
            a3 += matrix[r, k, 3] * vector[k, 3]
            a4 += matrix[r, k, 4] * vector[k, 4]
            a5 += matrix[r, k, 5] * vector[k, 5]
            a6 += matrix[r, k, 6] * vector[k, 6]
            a7 += matrix[r, k, 7] * vector[k, 7]
        out[r, 0] += a0
        out[r, 1] += a1
        out[r, 2] += a2
        out[r, 3] += a3
        out[r, 4] += a4
        out[r, 5] += a5
        out[r, 6] += a6
        out[r, 7] += a7


@_jit
def between_lanes(old, new, alpha, out):
    """x_{n+1-α} = (1 - α) x_{n+1} + α x_n of every lane, (m, LANES)."""
    for i in range(new.shape[0]):
        for l in range(LANES):
            out[i, l] = new[i, l] if alpha == 0.0 else (1.0 - alpha) * new[i, l] + alpha * old[i, l]


@_jit
def elastic_lanes(weights, force_coefficients, tangent_coefficients, m, force, tangent):
    """force (m, n_mono, LANES), tangent (m m, n_t, LANES) = Σ_j c_j of the Taylor terms' coefficients per lane
    (``kernel_terms.design_elastic`` transposed: the monomial axis second, streamed by ``contract_second``);
    weights (n_terms, LANES)."""
    force[:] = 0.0
    tangent[:] = 0.0
    for j in range(weights.shape[0]):
        for q in range(force.shape[1]):
            for i in range(m):
                coefficient = force_coefficients[q, j * m + i]
                for l in range(LANES):
                    force[i, q, l] += weights[j, l] * coefficient
        for q in range(tangent.shape[1]):
            for i in range(m * m):
                coefficient = tangent_coefficients[q, j * m * m + i]
                for l in range(LANES):
                    tangent[i, q, l] += weights[j, l] * coefficient


@_jit
def monomials_lanes(eta, pairs, pair_of_triple, triples, out, tangent_out):
    """(η; η_k η_l; η_k η_l η_n) and (1; η; η_k η_l) per lane (``kernel_terms.monomials``)."""
    m, n2 = eta.shape[0], pairs.shape[0]
    for l in range(LANES):
        tangent_out[0, l] = 1.0
    for k in range(m):
        for l in range(LANES):
            out[k, l] = eta[k, l]
            tangent_out[1 + k, l] = eta[k, l]
    for q in range(n2):
        a, b = pairs[q, 0], pairs[q, 1]
        for l in range(LANES):
            product = eta[a, l] * eta[b, l]
            out[m + q, l] = product
            tangent_out[1 + m + q, l] = product
    for q in range(triples.shape[0]):
        a, b = m + pair_of_triple[q], triples[q, 2]
        for l in range(LANES):
            out[m + n2 + q, l] = out[a, l] * eta[b, l]


@_jit
def times_lanes(matrix, right, out):
    """out (r, LANES) = A X per lane of a shared A (r, c) and X (c, LANES), as ``contract_second``."""
    for row in range(matrix.shape[0]):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 0.0
        for k in range(matrix.shape[1]):
            entry = matrix[row, k]
            a0 += entry * right[k, 0]
            a1 += entry * right[k, 1]
            a2 += entry * right[k, 2]
            a3 += entry * right[k, 3]
            a4 += entry * right[k, 4]
            a5 += entry * right[k, 5]
            a6 += entry * right[k, 6]
            a7 += entry * right[k, 7]
        out[row, 0], out[row, 1], out[row, 2], out[row, 3] = a0, a1, a2, a3
        out[row, 4], out[row, 5], out[row, 6], out[row, 7] = a4, a5, a6, a7


@_jit
def point_kinematics_lanes(at_new, at_step, h, alpha_m, alpha_f, beta, gamma, out):
    """out (3, 2 n_points, LANES) = W (η, η̇, η̈) per lane at a Newton iterate's evaluation point, from W u_{n+1}
    (``at_new`` (2 n_points, LANES)) and W (u_n, v_n, a_n) (``at_step`` (3, 2 n_points, LANES)), all three affine
    in u_{n+1} (``kernel_thrust.point_kinematics``, on lane values)."""
    inverse, step, predicted = splat(1.0 / (beta * h * h)), splat(h), splat(h * h * (0.5 - beta))
    carried, corrected = splat(h * (1.0 - gamma)), splat(gamma * h)
    new_f, old_f, new_m, old_m = splat(1.0 - alpha_f), splat(alpha_f), splat(1.0 - alpha_m), splat(alpha_m)
    for r in range(at_new.shape[0]):
        u, v, a, u_new = load3(at_step, 0, r), load3(at_step, 1, r), load3(at_step, 2, r), load(at_new, r)
        a_new = mul(sub(u_new, add(add(u, mul(step, v)), mul(predicted, a))), inverse)
        v_new = add(add(v, mul(carried, a)), mul(corrected, a_new))
        if alpha_f == 0.0:
            store3(out, 0, r, u_new)
            store3(out, 1, r, v_new)
        else:
            store3(out, 0, r, add(mul(new_f, u_new), mul(old_f, u)))
            store3(out, 1, r, add(mul(new_f, v_new), mul(old_f, v)))
        store3(out, 2, r, a_new if alpha_m == 0.0 else add(mul(new_m, a_new), mul(old_m, a)))


@_jit
def thrust_force_lanes(kinematics, transposed, own_node, other_node, length, inverse_length, rest_tangent, weights,
                       tail_weight, lagrangian, state, force, out):
    """out (m, LANES) += Wᵀ f_thrust per lane (``kernel_thrust.thrust_force``) from the points' kinematics
    (3, 2 n_points, LANES) (``point_kinematics_lanes``); state (10, H, LANES) kept for the blocks; force
    (2 n_points, LANES) a work array."""
    force[:] = 0.0
    for h in range(own_node.size):             # eight lanes as values (``lane_values``): run as vectors
        o, x = 2 * own_node[h], 2 * other_node[h]
        scale = load(inverse_length, h)
        tx = add(load3(rest_tangent, h, 0), mul(sub(load3(kinematics, 0, x), load3(kinematics, 0, o)), scale))
        ty = add(load3(rest_tangent, h, 1), mul(sub(load3(kinematics, 0, x + 1), load3(kinematics, 0, o + 1)), scale))
        nx, ny = neg(ty), tx
        ndx = neg(mul(sub(load3(kinematics, 1, x + 1), load3(kinematics, 1, o + 1)), scale))
        ndy = mul(sub(load3(kinematics, 1, x), load3(kinematics, 1, o)), scale)
        vx, vy = load3(kinematics, 1, o), load3(kinematics, 1, o + 1)
        ax, ay = load3(kinematics, 2, o), load3(kinematics, 2, o + 1)
        w, ell = load(weights, h), load(length, h)
        store3(state, 0, h, tx)
        store3(state, 1, h, ty)
        store3(state, 2, h, nx)
        store3(state, 3, h, ny)
        store3(state, 4, h, ndx)
        store3(state, 5, h, ndy)
        store3(state, 6, h, vx)
        store3(state, 7, h, vy)
        store3(state, 8, h, ax)
        store3(state, 9, h, ay)
        v_n = add(mul(vx, nx), mul(vy, ny))
        along = add(add(add(mul(ax, nx), mul(ay, ny)), mul(vx, ndx)), mul(vy, ndy))
        spine_x = mul(neg(ell), add(mul(along, nx), mul(v_n, ndx)))
        spine_y = mul(neg(ell), add(mul(along, ny), mul(v_n, ndy)))
        if lagrangian:
            g_x, g_y = mul(v_n, vy), neg(mul(v_n, vx))
            add_to(force, o, mul(w, sub(spine_x, g_x)))
            add_to(force, o + 1, mul(w, sub(spine_y, g_y)))
            add_to(force, x, mul(w, g_x))
            add_to(force, x + 1, mul(w, g_y))
        else:
            add_to(force, o, mul(w, spine_x))
            add_to(force, o + 1, mul(w, spine_y))
    o = 2 * own_node[0]
    for l in range(LANES):
        v_n = state[6, 0, l] * state[2, 0, l] + state[7, 0, l] * state[3, 0, l]
        force[o, l] += tail_weight[l] * 0.5 * v_n * v_n * state[0, 0, l]
        force[o + 1, l] += tail_weight[l] * 0.5 * v_n * v_n * state[1, 0, l]
    projected = np.dot(transposed, force)
    for k in range(out.shape[0]):
        for l in range(LANES):
            out[k, l] += projected[k, l]


@_jit
def muscle_lanes(activations, muscle_constant, muscle_linear, eta, out):
    """out (m, LANES) += Σ_j a_j (b_j + B_j η) per lane (``kernel_terms.muscle_force``; for a = ∂a/∂A its
    A-derivative)."""
    column = np.empty((eta.shape[0], LANES))
    for n in range(activations.shape[0]):
        column[:] = muscle_constant[n]
        contract_second(muscle_linear[n], eta, column)
        for i in range(eta.shape[0]):
            for l in range(LANES):
                out[i, l] += activations[n, l] * column[i, l]


@_jit
def residual_lanes(eu, ev, ea, out, activations, mono, tangent_mono, pairs, pair_of_triple, triples, elastic_force,
                   mass, damping, muscle_constant, muscle_linear, has_thrust, lagrangian, transposed,
                   own_node, other_node, length, inverse_length, rest_tangent, thrust_weights, tail_weight, state,
                   has_drag, drag_direction, drag_row, kinematics, force, norm, scale):
    """out (m, LANES) = r_r per lane, norm and scale (LANES,) Newton's ‖r‖ and force scale
    (``kernel_terms.residual_at``); kinematics (3, 2 n_points, LANES) the thrust points' (η, η̇, η̈)."""
    m = eu.shape[0]
    monomials_lanes(eu, pairs, pair_of_triple, triples, mono, tangent_mono)
    external = np.zeros((m, LANES))
    if has_thrust:
        thrust_force_lanes(kinematics, transposed, own_node, other_node, length, inverse_length, rest_tangent,
                           thrust_weights, tail_weight, lagrangian, state, force, external)
    speed = np.zeros(LANES)
    if has_drag:
        for k in range(m):
            for l in range(LANES):
                speed[l] += drag_row[k] * ev[k, l]
    internal, inertia = np.zeros((m, LANES)), np.zeros((m, LANES))
    viscous, muscle = np.zeros((m, LANES)), np.zeros((m, LANES))
    contract_second(elastic_force, mono, internal)
    contract_second(mass, ea, inertia)
    contract_second(damping, ev, viscous)
    muscle_lanes(activations, muscle_constant, muscle_linear, eu, muscle)
    norms = np.zeros((4, LANES))             # ‖f_int‖², ‖f_ext‖², ‖M η̈‖², ‖r‖²
    for i in range(m):
        for l in range(LANES):
            applied = external[i, l] - muscle[i, l]
            if has_drag:
                applied += drag_direction[i, l] * speed[l] * speed[l]
            out[i, l] = inertia[i, l] + viscous[i, l] + internal[i, l] - applied
            norms[0, l] += internal[i, l] * internal[i, l]
            norms[1, l] += applied * applied
            norms[2, l] += inertia[i, l] * inertia[i, l]
            norms[3, l] += out[i, l] * out[i, l]
    for l in range(LANES):
        norm[l] = math.sqrt(norms[3, l])
        scale[l] = math.sqrt(max(max(norms[0, l], norms[1, l]), norms[2, l]))


@_jit
def tangents_lanes(ev, activations, tangent_mono, elastic_tangent, mass, damping, muscle_linear, has_drag,
                   drag_direction, drag_row, stiffness, damping_out, mass_out):
    """(K_t, C_t, M_t) (m, m, LANES) of every term but the thrust per lane (``kernel_terms.tangents_at``)."""
    m = ev.shape[0]
    flat = stiffness.reshape((m * m, LANES))
    flat[:] = 0.0
    contract_second(elastic_tangent, tangent_mono, flat)
    contract_first(muscle_linear.reshape((muscle_linear.shape[0], m * m, LANES)), activations, flat)
    damping_out[:] = damping
    mass_out[:] = mass
    if has_drag:
        speed = np.zeros(LANES)
        for k in range(m):
            for l in range(LANES):
                speed[l] += drag_row[k] * ev[k, l]
        twice = mul(splat(2.0), load(speed.reshape((1, LANES)), 0))
        for i in range(m):
            direction = mul(twice, load(drag_direction, i))
            for k in range(m):
                store3(damping_out, i, k, sub(load3(damping_out, i, k), mul(direction, splat(drag_row[k]))))


@_jit
def derivative_lanes(parameter_terms, eu, ev, ea, activations, units, mono, coefficients_t, weight_derivatives,
                     mass_gradient, damping_gradient, muscle_constant, muscle_linear, muscle_constant_gradient,
                     muscle_linear_gradient, has_thrust, thrust_forces, transposed, has_drag, drag_gradient,
                     drag_row, sensitivities, amplitude_sensitivity, out):
    """out (m, columns, LANES) = ∂r/∂ξ_k (and ∂r/∂A) per lane (``kernel_terms.derivative_at``); thrust_forces
    (2 n_points, p, LANES) = ∂f/∂ξ_k on the points (``force_gradients_lanes``), coefficients_t (n_terms m, n_mono)
    the Taylor terms' shared force coefficients transposed: their forces for all lanes in one BLAS product."""
    m = eu.shape[0]
    p, n_terms = weight_derivatives.shape[0], weight_derivatives.shape[1]
    out[:] = 0.0
    total = np.empty((m, LANES))
    if sensitivities and parameter_terms:
        speed = np.zeros(LANES)
        if has_drag:
            for k in range(m):
                for l in range(LANES):
                    speed[l] += drag_row[k] * ev[k, l]
        thrust = np.zeros((m, p * LANES))
        if has_thrust:
            thrust = np.dot(transposed, thrust_forces.reshape((thrust_forces.shape[0], p * LANES)))
        terms = np.dot(coefficients_t, mono).reshape((n_terms, m, LANES))     # the Taylor terms' forces f_j(η)
        for c in range(p):
            total[:] = 0.0
            contract_first(terms, weight_derivatives[c], total)
            muscle_lanes(activations, muscle_constant_gradient[c], muscle_linear_gradient[c], eu, total)
            contract_second(mass_gradient[c], ea, total)
            contract_second(damping_gradient[c], ev, total)
            for i in range(m):
                for l in range(LANES):
                    if has_drag:
                        total[i, l] -= drag_gradient[c, i, l] * speed[l] * speed[l]
                    if has_thrust:
                        total[i, l] -= thrust[i, c * LANES + l]
                    out[i, c, l] = total[i, l]
    if amplitude_sensitivity:
        c = out.shape[1] - 1
        total[:] = 0.0
        muscle_lanes(units, muscle_constant, muscle_linear, eu, total)
        for i in range(m):
            for l in range(LANES):
                out[i, c, l] = total[i, l]


@_jit
def sensitivity_terms_lanes(k_a, alpha_f, alpha_m, rhs, stiffness, damping, mass, combination, predicted, previous,
                            previous_acceleration, out):
    """out (m, c, LANES) = -∂r/∂ξ - C_t V + k_a M_t X̃₀ - α_f K_t X₀ - α_m M_t X₂ per lane: the sensitivity step's
    right-hand side without the thrust (V = ``combination``, X̃₀ the predicted sensitivities, X₀ and X₂ the last
    step's); each entry's eight lanes on tuples (``lane_values``)."""
    m, columns = out.shape[0], out.shape[1]
    k_a_lanes, alpha_f_lanes, alpha_m_lanes = splat(k_a), splat(alpha_f), splat(alpha_m)
    for i in range(m):
        for c in range(columns):
            total = neg(load3(rhs, i, c))
            for k in range(m):
                inertia = load3(mass, i, k)
                total = add(total, sub(sub(add(mul(neg(load3(damping, i, k)), load3(combination, k, c)),
                                               mul(mul(k_a_lanes, inertia), load3(predicted, k, c))),
                                           mul(mul(alpha_f_lanes, load3(stiffness, i, k)), load3(previous, k, c))),
                                       mul(mul(alpha_m_lanes, inertia), load3(previous_acceleration, k, c))))
            store3(out, i, c, total)
