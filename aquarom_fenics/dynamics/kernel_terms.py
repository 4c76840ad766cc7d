"""The compiled kernel's linear algebra and the reduced terms but the thrust at one design: the residual
r_r = M η̈ + C η̇ + f_int(η) + Σ_j a_j (b_j + B_j η) - f_thrust - f_drag, its tangents and ξ-derivative, as
``batched_system.BatchedSystem`` computes them for a batch (the tests hold the two to 1e-12)."""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.kernel_thrust import force_gradients, thrust_force


@_jit
def lu_factor(matrix, pivots):
    """In-place LU with partial pivoting; False when a pivot is zero or not finite."""
    size = matrix.shape[0]
    for column in range(size):
        best, row = abs(matrix[column, column]), column
        for candidate in range(column + 1, size):
            if abs(matrix[candidate, column]) > best:
                best, row = abs(matrix[candidate, column]), candidate
        if not (best > 0.0) or not math.isfinite(best):
            return False
        pivots[column] = row
        if row != column:
            for k in range(size):
                matrix[column, k], matrix[row, k] = matrix[row, k], matrix[column, k]
        inverse = 1.0 / matrix[column, column]
        for below in range(column + 1, size):
            factor = matrix[below, column] * inverse
            matrix[below, column] = factor
            for k in range(column + 1, size):
                matrix[below, k] -= factor * matrix[column, k]
    return True

GROWTH_LIMIT = 100.0
"""The largest entry of the eliminated matrices that an LU without pivoting may reach, relative to the largest
|S_ij| (Wilkinson's growth factor): its backward error is about m ε times that. The reduced Newton matrices reach
0.73 (SO1, 459 matrices); a matrix that exceeds the limit is factorised with partial pivoting."""


@_jit
def lu_unpivoted(matrix, factors, pivots):
    """factors = LU of matrix (m, m) without pivoting (pivots[k] = k, so ``lu_solve`` applies); False when a pivot
    is zero or not finite or the growth exceeds ``GROWTH_LIMIT``. ``lane_lu.factor_lanes`` does the same arithmetic
    on eight matrices at once."""
    size = matrix.shape[0]
    largest = 0.0
    for i in range(size):
        pivots[i] = i
        for k in range(size):
            factors[i, k] = matrix[i, k]
            largest = max(largest, abs(matrix[i, k]))
    grown = 0.0
    for column in range(size):
        pivot = factors[column, column]
        if not (abs(pivot) > 0.0) or not math.isfinite(pivot):
            return False
        inverse = 1.0 / pivot
        for below in range(column + 1, size):
            factor = factors[below, column] * inverse
            factors[below, column] = factor
            for k in range(column + 1, size):
                value = factors[below, k] - factor * factors[column, k]
                factors[below, k] = value
                grown = max(grown, abs(value))
    return grown <= GROWTH_LIMIT * largest


@_jit
def factorize(matrix, factors, pivots):
    """factors, pivots = LU of S = matrix (m, m) for ``lu_solve``: without pivoting when ``lu_unpivoted`` accepts
    it, else ``lu_factor``'s partial pivoting; False if S is singular (matrix is kept)."""
    if lu_unpivoted(matrix, factors, pivots):
        return True
    factors[:] = matrix
    return lu_factor(factors, pivots)


@_jit
def lu_solve(factors, pivots, rhs):
    """Solve in place for the columns of rhs (m, c) with the factors of ``lu_factor``."""
    size, columns = rhs.shape
    for row in range(size):
        if pivots[row] != row:
            for c in range(columns):
                rhs[row, c], rhs[pivots[row], c] = rhs[pivots[row], c], rhs[row, c]
    for c in range(columns):
        for row in range(size):
            total = rhs[row, c]
            for k in range(row):
                total -= factors[row, k] * rhs[k, c]
            rhs[row, c] = total
        for row in range(size - 1, -1, -1):
            total = rhs[row, c]
            for k in range(row + 1, size):
                total -= factors[row, k] * rhs[k, c]
            rhs[row, c] = total / factors[row, row]

@_jit
def between(old, new, alpha, out):
    """x_{n+1-α} = (1 - α) x_{n+1} + α x_n (x_{n+1} itself when α = 0)."""
    if alpha == 0.0:
        out[:] = new
    else:
        for i in range(new.size):
            out[i] = (1.0 - alpha) * new[i] + alpha * old[i]

@_jit
def monomials(eta, pairs, pair_of_triple, triples, out, tangent_out):
    """(η; η_k η_l; η_k η_l η_n) and (1; η; η_k η_l) of ``batched_system.BatchedElastic``."""
    m, n2 = eta.size, pairs.shape[0]
    tangent_out[0] = 1.0
    for k in range(m):
        out[k] = eta[k]
        tangent_out[1 + k] = eta[k]
    for q in range(n2):
        product = eta[pairs[q, 0]] * eta[pairs[q, 1]]
        out[m + q] = product
        tangent_out[1 + m + q] = product
    for q in range(triples.shape[0]):
        out[m + n2 + q] = out[m + pair_of_triple[q]] * eta[triples[q, 2]]

@_jit
def design_elastic(weights, force_coefficients, tangent_coefficients, m):
    """F (n_mono, m), T (n_t, m m) of one design: Σ_j c_j of the Taylor terms' coefficients."""
    n_terms = weights.size
    n_mono, n_t = force_coefficients.shape[0], tangent_coefficients.shape[0]
    force = np.zeros((n_mono, m))
    tangent = np.zeros((n_t, m * m))
    for j in range(n_terms):
        c = weights[j]
        if c != 0.0:
            for q in range(n_mono):
                for i in range(m):
                    force[q, i] += c * force_coefficients[q, j * m + i]
            for q in range(n_t):
                for i in range(m * m):
                    tangent[q, i] += c * tangent_coefficients[q, j * m * m + i]
    return force, tangent


@_jit
def muscle_force(activations, muscle_constant, muscle_linear, eta, i):
    """Σ_j a_j (b_j + B_j η)_i: entry i of the muscles' reduced force for activations a (or of ∂/∂A for a = ∂a/∂A)."""
    total = 0.0
    for n in range(activations.size):
        column = muscle_constant[n, i]
        for k in range(eta.size):
            column += muscle_linear[n, i, k] * eta[k]
        total += activations[n] * column
    return total


@_jit
def residual_at(eu, ev, ea, out, activations, mono, tangent_mono, pairs, pair_of_triple, triples, elastic_force,
                mass, damping, muscle_constant, muscle_linear, has_thrust, lagrangian, kinematics, transposed, own_node,
                other_node, length, inverse_length, rest_tangent, thrust_weights, tail_weight, state, has_drag,
                drag_direction, drag_row):
    """out = r_r = M η̈ + C η̇ + f_int(η) - f_ext at the evaluation point; (‖r‖, the force scale of Newton's
    test max(‖f_int‖, ‖f_ext‖, ‖M η̈‖)). f_ext = -Σ_j a_j (b_j + B_j η) + f_thrust + f_drag; ``kinematics`` =
    W (η, η̇, η̈) (2 n_points, 3) of the thrust's points (``kernel_thrust.point_kinematics``), ``transposed`` = Wᵀ."""
    m = eu.size
    monomials(eu, pairs, pair_of_triple, triples, mono, tangent_mono)
    external = np.zeros(m)
    if has_thrust:
        thrust_force(kinematics, transposed, own_node, other_node, length, inverse_length, rest_tangent,
                     thrust_weights, tail_weight, lagrangian, state, external)
    speed = 0.0
    if has_drag:
        for k in range(m):
            speed += drag_row[k] * ev[k]
    internal_force = np.dot(mono, elastic_force)        # BLAS: n_mono = m + m(m+1)/2 + m(m+1)(m+2)/6 rows
    internal_norm, external_norm, inertia_norm, norm = 0.0, 0.0, 0.0, 0.0
    for i in range(m):
        internal = internal_force[i]
        muscle = muscle_force(activations, muscle_constant, muscle_linear, eu, i)
        force = external[i] - muscle
        if has_drag:
            force += drag_direction[i] * speed * speed
        inertia, viscous = 0.0, 0.0
        for k in range(m):
            inertia += mass[i, k] * ea[k]
            viscous += damping[i, k] * ev[k]
        out[i] = inertia + viscous + internal - force
        internal_norm += internal * internal
        external_norm += force * force
        inertia_norm += inertia * inertia
        norm += out[i] * out[i]
    return math.sqrt(norm), math.sqrt(max(max(internal_norm, external_norm), inertia_norm))

@_jit
def tangents_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear,
                has_drag, drag_direction, drag_row, stiffness, damping_out, mass_out):
    """(K_t, C_t, M_t) of every term but the thrust (whose blocks ``half_blocks`` gives)."""
    m = eu.size
    elastic = np.dot(tangent_mono, elastic_tangent)    # BLAS: (1 + m + m(m+1)/2) × m² coefficients
    for i in range(m):
        for k in range(m):
            muscle = 0.0
            for n in range(activations.size):
                muscle += activations[n] * muscle_linear[n, i, k]
            stiffness[i, k] = elastic[i * m + k] + muscle
            damping_out[i, k] = damping[i, k]
            mass_out[i, k] = mass[i, k]
    if has_drag:
        speed = 0.0
        for k in range(m):
            speed += drag_row[k] * ev[k]
        for i in range(m):
            for k in range(m):
                damping_out[i, k] -= 2.0 * speed * drag_direction[i] * drag_row[k]

@_jit
def derivative_at(parameter_terms, eu, ev, ea, activations, units, mono, force_coefficients, weight_derivatives,
                  mass_gradient,
                  damping_gradient, muscle_constant, muscle_linear, muscle_constant_gradient,
                  muscle_linear_gradient, has_thrust, points, own_node, other_node, state, length,
                  thrust_weight_gradient, tail_weight_gradient, lagrangian, has_drag, drag_gradient, drag_row,
                  sensitivities, amplitude_sensitivity, out):
    """out (m, columns) = ∂r/∂ξ_k (and ∂r/∂A) at fixed (η, η̇, η̈), as ``BatchedSystem.parameter_derivative``,
    but for the thrust's part from rest stations that move with ξ, -Wᵀ K ∂x_rest/∂ξ_k (K the points' stiffness):
    the caller adds it with the thrust's tangents (``reduced_kernel``). The thrust's part here: -Wᵀ ∂f/∂ξ_k."""
    m = eu.size
    p = weight_derivatives.shape[0]
    out[:] = 0.0
    if sensitivities and parameter_terms:
        speed = 0.0
        if has_drag:
            for k in range(m):
                speed += drag_row[k] * ev[k]
        thrust = np.zeros((p, m))
        if has_thrust:
            forces = np.empty((p, points.shape[0]))        # ∂f/∂ξ_k on the points, then one projection
            force_gradients(state, length, lagrangian, thrust_weight_gradient, tail_weight_gradient, own_node,
                            other_node, forces)
            thrust = np.dot(forces, points)               # (p, m): (Wᵀ forces)ᵀ
        # ∂f_int/∂ξ_k = Σ_j ∂c_j/∂ξ_k f_j(η): the Taylor terms' forces f_j from one product with their shared
        # coefficients (BLAS, as the force), then the design's weights' derivatives (mostly zeros)
        terms = np.dot(mono, force_coefficients)               # (n_terms m,)
        elastic = np.zeros(p * m)
        for c in range(p):
            for j in range(weight_derivatives.shape[1]):
                factor = weight_derivatives[c, j]
                if factor != 0.0:
                    for i in range(m):
                        elastic[c * m + i] += factor * terms[j * m + i]
        for c in range(p):
            for i in range(m):
                total = elastic[c * m + i]
                for n in range(activations.size):
                    muscle = muscle_constant_gradient[c, n, i]
                    for k in range(m):
                        muscle += muscle_linear_gradient[c, n, i, k] * eu[k]
                    total += activations[n] * muscle
                for k in range(m):
                    total += mass_gradient[c, i, k] * ea[k] + damping_gradient[c, i, k] * ev[k]
                if has_drag:
                    total -= drag_gradient[c, i] * speed * speed
                if has_thrust:
                    total -= thrust[c, i]
                out[i, c] = total
    if amplitude_sensitivity:
        c = out.shape[1] - 1
        for i in range(m):
            out[i, c] = muscle_force(units, muscle_constant, muscle_linear, eu, i)
