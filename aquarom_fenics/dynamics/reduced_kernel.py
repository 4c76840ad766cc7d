"""The batched reduced integration of :mod:`batched` compiled (numba): one design at a time, every step, every
Newton iteration and every sensitivity step in machine code.

numpy's batched solve spends its time in the calls, not in the arithmetic: an 8-unknown system takes
microseconds to assemble and solve, each numpy call about one. Here the same steps run as loops over
the design's arrays: the generalized-α modified Newton of ``integrator._Newton`` (the same refresh rules
and test ‖r‖ ≤ tol · max(scale, floor)) and the direct-differentiation sensitivities of
``reduced_dynamics.propagate_sensitivity``, on the terms that :class:`~.batched_system.BatchedSystem`
prepares per design (``pack`` reads them), so the physics is not written again but for the thrust's
segment law, which is evaluated here on *half-segments*:

    half-segment h: own node o (rear; the front for the trapezoid rule's mirrored half), other node x,
        t = t₀ + (W_x - W_o) η / ℓ₀,  ṫ = (W_x - W_o) η̇ / ℓ₀,  n = R t,  ṅ = R ṫ,  v = W_o η̇,  a = W_o η̈
    f_o += w [-ℓ₀ ((a·n + v·ṅ) n + (v·n) ṅ)] - w g,  f_x += w g,  g = (v·n) Rᵀ v (lagrangian form only)
    f_0 += m̃₀ ½ (v·n)² t  (segment 0's rear half: the tail)

with w the half-segment's virtual mass (½ m̃ of its node for the trapezoid rule), as ``thrust.py`` writes it,
and the Jacobian blocks of ``thrust_jacobians.py`` on (o, x), projected Wᵀ J W. The tests compare the
kernel with ``simulate_reduced`` to 1e-12 on every thrust variant.

A design whose step fails (no convergence, a non-finite residual, a singular matrix) is reported failed; the
caller integrates it alone with the step control (as the numpy batch does). Compiled once per machine into
numba's cache beside this file (``python -m aquarom_fenics.dynamics.reduced_kernel``, which ``make setup``
runs): about half a minute.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

OK, FAILED = 0, 1


try:
    import numba
except ImportError:          # the numpy engine serves; ``available()`` says which
    numba = None


def _jit(function):
    """numba.njit with the kernel's options, cached on disk beside this file (identity without numba)."""
    if numba is None:
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


def available() -> bool:
    """Whether numba can be imported (Debian's python3-numba)."""
    return numba is not None


def kernel() -> SimpleNamespace:
    """The compiled functions (compiled on their first call, or loaded from numba's cache)."""
    return SimpleNamespace(integrate_all=integrate_all)


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
def design_elastic(weights, weight_derivatives, force_coefficients, tangent_coefficients, m):
    """F (n_mono, m), T (n_t, m m), G (p, n_mono, m) of one design: Σ_j c_j of the Taylor terms' coefficients
    and Σ_j ∂c_j/∂ξ_k of their forces."""
    n_terms, p = weights.size, weight_derivatives.shape[0]
    n_mono, n_t = force_coefficients.shape[0], tangent_coefficients.shape[0]
    force = np.zeros((n_mono, m))
    tangent = np.zeros((n_t, m * m))
    gradient = np.zeros((p, n_mono, m))
    for j in range(n_terms):
        c = weights[j]
        for q in range(n_mono):
            for i in range(m):
                value = force_coefficients[q, j * m + i]
                force[q, i] += c * value
                for k in range(p):
                    gradient[k, q, i] += weight_derivatives[k, j] * value
        if c != 0.0:
            for q in range(n_t):
                for i in range(m * m):
                    tangent[q, i] += c * tangent_coefficients[q, j * m * m + i]
    return force, tangent, gradient

@_jit
def half_state(eta, eta_dot, eta_ddot, rows, own_node, other_node, length, rest_tangent, state):
    """Per half-segment h: state[h] = (t, n, ṅ, v, a) as 10 numbers (x, y each), from the points' kinematics
    (W η, W η̇, W η̈) computed once per point."""
    n_points, m = rows.shape[0], eta.size
    kinematics = np.empty((3, n_points, 2))
    for point in range(n_points):
        for c in range(2):
            position, velocity, acceleration = 0.0, 0.0, 0.0
            for k in range(m):
                position += rows[point, c, k] * eta[k]
                velocity += rows[point, c, k] * eta_dot[k]
                acceleration += rows[point, c, k] * eta_ddot[k]
            kinematics[0, point, c], kinematics[1, point, c], kinematics[2, point, c] = position, velocity, acceleration
    for h in range(own_node.size):
        o, x = own_node[h], other_node[h]
        for c in range(2):
            state[h, c] = rest_tangent[h, c] + (kinematics[0, x, c] - kinematics[0, o, c]) / length[h]    # t
            state[h, 4 + c] = (kinematics[1, x, c] - kinematics[1, o, c]) / length[h]                      # ṫ
            state[h, 6 + c] = kinematics[1, o, c]                                                          # v
            state[h, 8 + c] = kinematics[2, o, c]                                                          # a
        state[h, 2], state[h, 3] = -state[h, 1], state[h, 0]                  # n = R t
        rate_x, rate_y = state[h, 4], state[h, 5]
        state[h, 4], state[h, 5] = -rate_y, rate_x                            # ṅ = R ṫ

@_jit
def half_forces(state, length, lagrangian, per_mass):
    """Per-mass forces of each half-segment: per_mass[h] = (f_spine/m̃ on o (2), g/m̃ (2)), the tail's
    f_tail/m̃₀ = ½ (v·n)² t of half-segment 0 returned."""
    for h in range(state.shape[0]):
        tx, ty, nx, ny, ndx, ndy, vx, vy, ax, ay = state[h]
        a_n = ax * nx + ay * ny
        v_nd = vx * ndx + vy * ndy
        v_n = vx * nx + vy * ny
        per_mass[h, 0] = -length[h] * ((a_n + v_nd) * nx + v_n * ndx)
        per_mass[h, 1] = -length[h] * ((a_n + v_nd) * ny + v_n * ndy)
        if lagrangian:
            per_mass[h, 2] = v_n * vy          # (v·n) Rᵀ v, Rᵀ v = (v_y, -v_x)
            per_mass[h, 3] = -v_n * vx
        else:
            per_mass[h, 2] = 0.0
            per_mass[h, 3] = 0.0
    tx, ty, nx, ny = state[0, 0], state[0, 1], state[0, 2], state[0, 3]
    v_n = state[0, 6] * nx + state[0, 7] * ny
    return 0.5 * v_n * v_n * tx, 0.5 * v_n * v_n * ty

@_jit
def add_projected_force(per_mass, tail_x, tail_y, weights, tail_weight, rows, own_node, other_node, sign, out):
    """out += sign Wᵀ f of the forces ``per_mass`` weighted by ``weights`` (H,) and ``tail_weight``, assembled
    on the points first."""
    m, n_points = out.size, rows.shape[0]
    force = np.zeros((n_points, 2))
    for h in range(per_mass.shape[0]):
        w = weights[h]
        o, x = own_node[h], other_node[h]
        force[o, 0] += w * (per_mass[h, 0] - per_mass[h, 2])
        force[o, 1] += w * (per_mass[h, 1] - per_mass[h, 3])
        force[x, 0] += w * per_mass[h, 2]
        force[x, 1] += w * per_mass[h, 3]
    force[own_node[0], 0] += tail_weight * tail_x
    force[own_node[0], 1] += tail_weight * tail_y
    for k in range(m):
        total = 0.0
        for point in range(n_points):
            total += rows[point, 0, k] * force[point, 0] + rows[point, 1, k] * force[point, 1]
        out[k] += sign * total

@_jit
def half_blocks(state, length, weights, tail_weight, lagrangian, stiffness, damping, mass):
    """The Jacobian blocks of ``thrust_jacobians`` per half-segment on (o, x): stiffness and damping
    (H, 4, 2, 2) in the order (oo, ox, xo, xx), the added mass on oo only."""
    stiffness[:] = 0.0
    damping[:] = 0.0
    mass[:] = 0.0
    for h in range(state.shape[0]):
        tx, ty, nx, ny, ndx, ndy, vx, vy, ax, ay = state[h]
        w, ell = weights[h], length[h]
        a_n = ax * nx + ay * ny
        v_nd = vx * ndx + vy * ndy
        v_n = vx * nx + vy * ny
        # ∂B/∂n = (a·n + v·ṅ) I + n aᵀ + ṅ vᵀ; ∂f/∂u_x = -w (∂B/∂n) R = -∂f/∂u_o
        b00 = a_n + v_nd + nx * ax + ndx * vx
        b01 = nx * ay + ndx * vy
        b10 = ny * ax + ndy * vx
        b11 = a_n + v_nd + ny * ay + ndy * vy
        # M R = [[M01, -M00], [M11, -M10]]
        stiffness[h, 1, 0, 0], stiffness[h, 1, 0, 1] = -w * b01, w * b00
        stiffness[h, 1, 1, 0], stiffness[h, 1, 1, 1] = -w * b11, w * b10
        for i in range(2):
            for j in range(2):
                stiffness[h, 0, i, j] = -stiffness[h, 1, i, j]
        # ∂B/∂ṅ = n vᵀ + (v·n) I; ∂f/∂u̇_x = -w (∂B/∂ṅ) R; ∂f/∂u̇_o = -w ℓ (n ṅᵀ + ṅ nᵀ) - ∂f/∂u̇_x
        c00 = nx * vx + v_n
        c01 = nx * vy
        c10 = ny * vx
        c11 = ny * vy + v_n
        damping[h, 1, 0, 0], damping[h, 1, 0, 1] = -w * c01, w * c00
        damping[h, 1, 1, 0], damping[h, 1, 1, 1] = -w * c11, w * c10
        damping[h, 0, 0, 0] = -w * ell * (2.0 * nx * ndx) - damping[h, 1, 0, 0]
        damping[h, 0, 0, 1] = -w * ell * (nx * ndy + ndx * ny) - damping[h, 1, 0, 1]
        damping[h, 0, 1, 0] = -w * ell * (ny * ndx + ndy * nx) - damping[h, 1, 1, 0]
        damping[h, 0, 1, 1] = -w * ell * (2.0 * ny * ndy) - damping[h, 1, 1, 1]
        mass[h, 0, 0, 0], mass[h, 0, 0, 1] = -w * ell * nx * nx, -w * ell * nx * ny
        mass[h, 0, 1, 0], mass[h, 0, 1, 1] = -w * ell * ny * nx, -w * ell * ny * ny
        if h == 0:
            # f_tail = ½ m̃₀ (v·n)² t: ∂/∂u_x = -∂/∂u_o = (m̃₀/ℓ) [(v·n) t (Rᵀ v)ᵀ + ½ (v·n)² I]; ∂/∂u̇_o = m̃₀ (v·n) t nᵀ
            scale = tail_weight / ell
            half = 0.5 * v_n * v_n
            tail00 = scale * (v_n * tx * vy + half)
            tail01 = scale * (v_n * tx * -vx)
            tail10 = scale * (v_n * ty * vy)
            tail11 = scale * (v_n * ty * -vx + half)
            stiffness[h, 1, 0, 0] += tail00
            stiffness[h, 1, 0, 1] += tail01
            stiffness[h, 1, 1, 0] += tail10
            stiffness[h, 1, 1, 1] += tail11
            stiffness[h, 0, 0, 0] -= tail00
            stiffness[h, 0, 0, 1] -= tail01
            stiffness[h, 0, 1, 0] -= tail10
            stiffness[h, 0, 1, 1] -= tail11
            damping[h, 0, 0, 0] += tail_weight * v_n * tx * nx
            damping[h, 0, 0, 1] += tail_weight * v_n * tx * ny
            damping[h, 0, 1, 0] += tail_weight * v_n * ty * nx
            damping[h, 0, 1, 1] += tail_weight * v_n * ty * ny
        if lagrangian:
            # g = w (v·n) Rᵀ v: ∂g/∂u_x = -∂g/∂u_o = (w/ℓ) (Rᵀ v)(Rᵀ v)ᵀ (front +g, own -g)
            rx, ry = vy, -vx
            scale = w / ell
            p00, p01, p11 = scale * rx * rx, scale * rx * ry, scale * ry * ry
            stiffness[h, 0, 0, 0] += p00
            stiffness[h, 0, 0, 1] += p01
            stiffness[h, 0, 1, 0] += p01
            stiffness[h, 0, 1, 1] += p11
            stiffness[h, 1, 0, 0] -= p00
            stiffness[h, 1, 0, 1] -= p01
            stiffness[h, 1, 1, 0] -= p01
            stiffness[h, 1, 1, 1] -= p11
            stiffness[h, 2, 0, 0] -= p00
            stiffness[h, 2, 0, 1] -= p01
            stiffness[h, 2, 1, 0] -= p01
            stiffness[h, 2, 1, 1] -= p11
            stiffness[h, 3, 0, 0] += p00
            stiffness[h, 3, 0, 1] += p01
            stiffness[h, 3, 1, 0] += p01
            stiffness[h, 3, 1, 1] += p11
            # ∂g/∂v = w [Rᵀ v nᵀ + (v·n) Rᵀ], Rᵀ = [[0, 1], [-1, 0]]: own -, other +
            g00 = w * (rx * nx)
            g01 = w * (rx * ny + v_n)
            g10 = w * (ry * nx - v_n)
            g11 = w * (ry * ny)
            damping[h, 0, 0, 0] -= g00
            damping[h, 0, 0, 1] -= g01
            damping[h, 0, 1, 0] -= g10
            damping[h, 0, 1, 1] -= g11
            damping[h, 2, 0, 0] += g00
            damping[h, 2, 0, 1] += g01
            damping[h, 2, 1, 0] += g10
            damping[h, 2, 1, 1] += g11

@_jit
def project_blocks(blocks, n_pairs, rows, own_node, other_node, right, factor, out):
    """out (m, r) += factor Wᵀ J R: the first ``n_pairs`` of the blocks (oo, ox, xo, xx) of every half-segment
    assembled into the points' block-tridiagonal J (n_points, 3, 2, 2), then Y = J R of the right rows R
    (n_points, 2, r) and Wᵀ Y, W the points' rows (n_points, 2, m)."""
    n_points, m, r = rows.shape[0], out.shape[0], out.shape[1]
    nodal = np.zeros((n_points, 3, 2, 2))
    for h in range(blocks.shape[0]):
        for pair in range(n_pairs):
            a = own_node[h] if pair < 2 else other_node[h]
            b = own_node[h] if pair % 2 == 0 else other_node[h]
            for i in range(2):
                for j in range(2):
                    nodal[a, b - a + 1, i, j] += blocks[h, pair, i, j]
    product = np.empty((2, r))
    for a in range(n_points):
        product[:] = 0.0
        for d in range(3):
            b = a + d - 1
            if b < 0 or b >= n_points:
                continue
            for i in range(2):
                for j in range(r):
                    product[i, j] += nodal[a, d, i, 0] * right[b, 0, j] + nodal[a, d, i, 1] * right[b, 1, j]
        for k in range(m):
            l0, l1 = factor * rows[a, 0, k], factor * rows[a, 1, k]
            for j in range(r):
                out[k, j] += l0 * product[0, j] + l1 * product[1, j]

@_jit
def rows_times(rows, values, out):
    """out (n_points, 2, c) = W (n_points, 2, m) @ values (m, c)."""
    out[:] = 0.0
    for point in range(rows.shape[0]):
        for i in range(2):
            for k in range(rows.shape[2]):
                weight = rows[point, i, k]
                for j in range(values.shape[1]):
                    out[point, i, j] += weight * values[k, j]

@_jit
def residual_at(eu, ev, ea, out, activations, mono, tangent_mono, pairs, pair_of_triple, triples, elastic_force,
                mass, damping, muscle_constant, muscle_linear, has_thrust, lagrangian, rows, own_node, other_node, length,
                rest_tangent, thrust_weights, tail_weight, state, per_mass, has_drag, drag_direction, drag_row):
    """out = r_r = M η̈ + C η̇ + f_int(η) - f_ext at the evaluation point; (‖r‖, the force scale of Newton's
    test max(‖f_int‖, ‖f_ext‖, ‖M η̈‖)). f_ext = -Σ_j a_j (b_j + B_j η) + f_thrust + f_drag."""
    m = eu.size
    monomials(eu, pairs, pair_of_triple, triples, mono, tangent_mono)
    external = np.zeros(m)
    if has_thrust:
        half_state(eu, ev, ea, rows, own_node, other_node, length, rest_tangent, state)
        tail_x, tail_y = half_forces(state, length, lagrangian, per_mass)
        add_projected_force(per_mass, tail_x, tail_y, thrust_weights, tail_weight, rows, own_node, other_node, 1.0,
                            external)
    speed = 0.0
    if has_drag:
        for k in range(m):
            speed += drag_row[k] * ev[k]
    internal_force = np.dot(mono, elastic_force)        # BLAS: n_mono = m + m(m+1)/2 + m(m+1)(m+2)/6 rows
    internal_norm, external_norm, inertia_norm, norm = 0.0, 0.0, 0.0, 0.0
    for i in range(m):
        internal = internal_force[i]
        muscle = 0.0
        for n in range(activations.size):
            total = muscle_constant[n, i]
            for k in range(m):
                total += muscle_linear[n, i, k] * eu[k]
            muscle += activations[n] * total
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
def derivative_at(parameter_terms, eu, ev, ea, activations, units, mono, elastic_gradient, mass_gradient,
                  damping_gradient, muscle_constant, muscle_linear, muscle_constant_gradient,
                  muscle_linear_gradient, has_thrust, moving_rest, rows, own_node, other_node, rest_rows, state,
                  per_mass, length, thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient,
                  lagrangian, k_blocks, c_blocks, m_blocks, has_drag, drag_gradient, drag_row, sensitivities,
                  amplitude_sensitivity, out):
    """out (m, columns) = ∂r/∂ξ_k (and ∂r/∂A) at fixed (η, η̇, η̈), as ``BatchedSystem.parameter_derivative``."""
    m = eu.size
    p = elastic_gradient.shape[0]
    out[:] = 0.0
    if sensitivities and parameter_terms:
        speed = 0.0
        if has_drag:
            for k in range(m):
                speed += drag_row[k] * ev[k]
        column = np.zeros(m)
        tail_x, tail_y = 0.0, 0.0
        if has_thrust:
            tail_x, tail_y = half_forces(state, length, lagrangian, per_mass)
        for c in range(p):
            elastic = np.dot(mono, elastic_gradient[c])        # BLAS, as the force
            for i in range(m):
                total = elastic[i]
                for n in range(activations.size):
                    muscle = muscle_constant_gradient[c, n, i]
                    for k in range(m):
                        muscle += muscle_linear_gradient[c, n, i, k] * eu[k]
                    total += activations[n] * muscle
                for k in range(m):
                    total += mass_gradient[c, i, k] * ea[k] + damping_gradient[c, i, k] * ev[k]
                if has_drag:
                    total -= drag_gradient[c, i] * speed * speed
                out[i, c] = total
            if has_thrust:
                column[:] = 0.0
                add_projected_force(per_mass, tail_x, tail_y, thrust_weight_gradient[c], tail_weight_gradient[c],
                                    rows, own_node, other_node, -1.0, column)
                for i in range(m):
                    out[i, c] += column[i]
        if has_thrust and moving_rest:
            project_blocks(k_blocks, 4 if lagrangian else 2, rows, own_node, other_node, rest_rows, -1.0, out[:, :p])
    if amplitude_sensitivity:
        c = out.shape[1] - 1
        for i in range(m):
            total = 0.0
            for n in range(units.size):
                muscle = muscle_constant[n, i]
                for k in range(m):
                    muscle += muscle_linear[n, i, k] * eu[k]
                total += units[n] * muscle
            out[i, c] = total

@_jit
def integrate_design(  # noqa: PLR0913 (the packed arrays of one design)
        n_steps, h, alpha_m, alpha_f, beta, gamma, tolerance, max_iterations, contraction, per_factorization,
        floor, units, distance_mask, amplitude_mask,
        pairs, pair_of_triple, triples, force_coefficients, tangent_coefficients,
        weights, weight_derivatives, mass, damping, mass_gradient, damping_gradient, com_weights, com_gradient,
        amplitude, muscle_constant, muscle_linear, muscle_constant_gradient, muscle_linear_gradient,
        has_thrust, lagrangian, moving_rest, rows, own_node, other_node, rest_rows, length, rest_tangent,
        thrust_weights, tail_weight, thrust_weight_gradient, tail_weight_gradient,
        has_drag, drag_direction, drag_gradient, drag_row, tail_row,
        sensitivities, amplitude_sensitivity, parameter_terms, result, gradient_out):
    """Integrate one design; result = (distance, tail amplitude, status), gradient_out (columns,)."""
    m = mass.shape[0]
    p = weight_derivatives.shape[0]
    n_muscles = muscle_constant.shape[0]
    halves = own_node.size
    columns = (p if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    k_u = 1.0 - alpha_f
    k_v = (1.0 - alpha_f) * gamma / (beta * h)
    k_a = (1.0 - alpha_m) / (beta * h * h)
    elastic_force, elastic_tangent, elastic_gradient = design_elastic(
        weights, weight_derivatives, force_coefficients, tangent_coefficients, m)
    n_mono, n_t = force_coefficients.shape[0], tangent_coefficients.shape[0]
    mono, tangent_mono = np.empty(n_mono), np.empty(n_t)
    state = np.zeros((halves, 10))
    per_mass = np.zeros((halves, 4))
    k_blocks, c_blocks, m_blocks = (np.zeros((halves, 4, 2, 2)), np.zeros((halves, 4, 2, 2)),
                                    np.zeros((halves, 4, 2, 2)))
    s_blocks = np.zeros((halves, 4, 2, 2))
    n_pairs = 4 if lagrangian else 2
    u, v, a = np.zeros(m), np.zeros(m), np.zeros(m)
    u_new, v_new, a_new = np.zeros(m), np.zeros(m), np.zeros(m)
    u_pred, v_pred = np.zeros(m), np.zeros(m)
    eu, ev, ea = np.zeros(m), np.zeros(m), np.zeros(m)
    residual = np.zeros((m, 1))
    matrix = np.zeros((m, m))
    pivots = np.zeros(m, np.int64)
    exact, exact_pivots = np.zeros((m, m)), np.zeros(m, np.int64)      # S at the converged point
    stiffness, damping_t, mass_t = np.zeros((m, m)), np.zeros((m, m)), np.zeros((m, m))
    activations = np.zeros(n_muscles)
    sens = np.zeros((3, m, columns))
    sens_new = np.zeros((3, m, columns))
    rhs = np.zeros((m, columns))
    thrust_rhs = np.zeros((m, columns))
    right = np.zeros((rows.shape[0], 2, max(columns, 1)))
    combination = np.zeros((m, columns))
    have_factors = False
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
            norm, scale = residual_at(eu, ev, ea, residual[:, 0], activations, mono, tangent_mono, pairs,
                                      pair_of_triple, triples, elastic_force, mass, damping, muscle_constant,
                                      muscle_linear, has_thrust, lagrangian, rows, own_node, other_node, length, rest_tangent,
                                      thrust_weights, tail_weight, state, per_mass, has_drag, drag_direction,
                                      drag_row)
            if not math.isfinite(norm):
                result[2] = FAILED
                return
            if norm <= tolerance * max(scale, floor):
                converged = True
                break
            if iteration == max_iterations:
                break
            slow = norm > contraction * previous_norm
            worn = with_factors >= per_factorization
            if not have_factors or slow or worn:
                tangents_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear,
                            has_drag, drag_direction, drag_row, stiffness, damping_t, mass_t)
                for i in range(m):
                    for k in range(m):
                        matrix[i, k] = k_u * stiffness[i, k] + k_v * damping_t[i, k] + k_a * mass_t[i, k]
                if has_thrust:
                    half_blocks(state, length, thrust_weights, tail_weight, lagrangian, k_blocks, c_blocks,
                                m_blocks)
                    for hh in range(halves):
                        for pair in range(4):
                            for i in range(2):
                                for j in range(2):
                                    s_blocks[hh, pair, i, j] = (k_u * k_blocks[hh, pair, i, j]
                                                                + k_v * c_blocks[hh, pair, i, j]
                                                                + k_a * m_blocks[hh, pair, i, j])
                    project_blocks(s_blocks, n_pairs, rows, own_node, other_node, rows, -1.0, matrix)
                if not lu_factor(matrix, pivots):
                    result[2] = FAILED
                    return
                have_factors = True
                with_factors = 0
            with_factors += 1
            previous_norm = norm
            lu_solve(matrix, pivots, residual)
            for i in range(m):
                u_new[i] -= residual[i, 0]
        if not converged:
            result[2] = FAILED
            return
        for i in range(m):
            a_new[i] = (u_new[i] - u_pred[i]) * (1.0 / (beta * h * h))
            v_new[i] = v_pred[i] + gamma * h * a_new[i]
        if columns:
            # the converged step differentiated (reduced_dynamics.propagate_sensitivity) at its evaluation point
            # (eu, ev, ea), where the last residual was evaluated: its monomials and thrust state are current
            tangents_at(eu, ev, activations, tangent_mono, pairs, elastic_tangent, mass, damping, muscle_linear,
                        has_drag, drag_direction, drag_row, stiffness, damping_t, mass_t)
            if has_thrust:
                half_blocks(state, length, thrust_weights, tail_weight, lagrangian, k_blocks, c_blocks, m_blocks)
            derivative_at(parameter_terms, eu, ev, ea, activations, units[step], mono, elastic_gradient, mass_gradient,
                          damping_gradient, muscle_constant, muscle_linear, muscle_constant_gradient,
                          muscle_linear_gradient, has_thrust, moving_rest, rows, own_node, other_node, rest_rows,
                          state, per_mass, length, thrust_weights, tail_weight, thrust_weight_gradient,
                          tail_weight_gradient, lagrangian, k_blocks, c_blocks, m_blocks, has_drag,
                          drag_gradient, drag_row, sensitivities, amplitude_sensitivity, rhs)
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
            for i in range(m):
                for k in range(m):
                    exact[i, k] = k_u * stiffness[i, k] + k_v * damping_t[i, k] + k_a * mass_t[i, k]
            if has_thrust:
                # the thrust's tangents -Wᵀ J W applied to the same columns, and in S
                if alpha_f != 0.0:
                    rows_times(rows, sens[0], right)
                    project_blocks(k_blocks, n_pairs, rows, own_node, other_node, right, alpha_f, thrust_rhs)
                rows_times(rows, combination, right)
                project_blocks(c_blocks, n_pairs, rows, own_node, other_node, right, 1.0, thrust_rhs)
                for i in range(m):
                    for c in range(columns):
                        combination[i, c] = k_a * sens_new[0, i, c] - alpha_m * sens[2, i, c]
                rows_times(rows, combination, right)
                project_blocks(m_blocks, 1, rows, own_node, other_node, right, -1.0, thrust_rhs)
                for hh in range(halves):
                    for pair in range(4):
                        for i in range(2):
                            for j in range(2):
                                s_blocks[hh, pair, i, j] = (k_u * k_blocks[hh, pair, i, j]
                                                            + k_v * c_blocks[hh, pair, i, j]
                                                            + k_a * m_blocks[hh, pair, i, j])
                project_blocks(s_blocks, n_pairs, rows, own_node, other_node, rows, -1.0, exact)
            if not lu_factor(exact, exact_pivots):
                result[2] = FAILED
                return
            lu_solve(exact, exact_pivots, thrust_rhs)
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
                    total += com_weights[i] * sens[0, i, c]
                    if c < p and sensitivities:
                        total += com_gradient[c, i] * u[i]
                gradient_sum[c] += total
        if amplitude_mask[step]:
            tail = 0.0
            for i in range(m):
                tail += tail_row[i] * u[i]
            amplitude_max = max(amplitude_max, abs(tail))
    result[0] = distance_sum / distance_count
    result[1] = amplitude_max
    for c in range(columns):
        gradient_out[c] = gradient_sum[c] / distance_count

@_jit
def integrate_all(scalars, settings, units, distance_mask, amplitude_mask, shared, per_design, flags, results,
                  gradients):
    """Every design of the batch in turn (``Packed``'s arrays); results (B, 3), gradients (B, columns)."""
    n_steps, max_iterations, per_factorization = settings
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
            floor, units, distance_mask, amplitude_mask, pairs, pair_of_triple, triples, force_coefficients,
            tangent_coefficients, weights[b], weight_derivatives[b], mass[b], damping[b], mass_gradient[b],
            damping_gradient[b], com_weights[b], com_gradient[b], amplitudes[b], muscle_constant[b],
            muscle_linear[b], muscle_constant_gradient[b], muscle_linear_gradient[b], has_thrust, lagrangian,
            moving_rest, rows, own_node, other_node, rest_rows, length[b], rest_tangent[b], thrust_weights[b],
            tail_weight[b], thrust_weight_gradient[b], tail_weight_gradient[b], has_drag, drag_direction[b],
            drag_gradient[b], drag_row, tail_row, sensitivities, amplitude_sensitivity, parameter_terms,
            results[b], gradients[b])



@dataclass
class Packed:
    """The arguments of the compiled ``integrate_all`` for one batch (contiguous float64/int64 arrays)."""

    arguments: tuple
    columns: int
    batch: int


def _array(values, dtype=float) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=dtype)


def half_nodes(n_points: int, trapezoid: bool) -> tuple[np.ndarray, np.ndarray]:
    """(own, other) point of every half-segment: the rear half's rear and front points, then (trapezoid rule) the
    mirrored half's front and rear points, segments head -> tail (``thrust.SegmentState``'s rows)."""
    rear = np.arange(n_points - 1)
    if not trapezoid:
        return rear, rear + 1
    return np.concatenate([rear, rear[::-1] + 1]), np.concatenate([rear + 1, rear[::-1]])


def pack(system, scene, n_steps: int, sensitivities: bool, amplitude_sensitivity: bool) -> Packed:
    """The batch's arrays from a :class:`~.batched_system.BatchedSystem` (its per-design terms) and the scene."""
    from aquarom_fenics.dynamics.integrator import NewtonSettings
    from aquarom_fenics.dynamics.trajectory import AMPLITUDE_WINDOW, DISTANCE_WINDOW, window_mask

    scheme, prom = system.scheme, system.prom
    settings = NewtonSettings.from_solver(scene.solver)
    batch, m, p = system.size, prom.size, system.deltas.shape[1]
    h = scheme.time_step
    times = np.arange(n_steps + 1) * h
    units = np.zeros((n_steps + 1, system.law.size))
    for step in range(1, n_steps + 1):
        units[step] = system.law.unit(step * h - scheme.alpha_f * h)
    elastic = system.elastic
    thrust = system.thrust
    if thrust is not None:
        data, spine = prom.thrust, thrust.spine
        trapezoid = spine.trapezoid
        own_node, other_node = half_nodes(data.rows.shape[0], trapezoid)
        rows, rest_rows = data.rows, data.rest_xy_gradient
        masses = spine.virtual_mass
        spine_weight, tail_weight_gradient, front_weight = thrust.derivative_weights
        if trapezoid:
            masses = 0.5 * np.concatenate([masses, spine.front_mass[:, ::-1]], axis=1)
            spine_weight = 0.5 * np.concatenate([spine_weight, front_weight[..., ::-1]], axis=-1)
        thrust_arrays = (_array(thrust.half_rest_length), _array(thrust.half_rest_tangent), _array(masses),
                         _array(spine.virtual_mass[:, 0]), _array(spine_weight), _array(tail_weight_gradient))
    else:
        own_node = other_node = np.zeros(0, np.int64)
        rows, rest_rows = np.zeros((0, 2, m)), np.zeros((0, 2, p))
        thrust_arrays = (np.zeros((batch, 0)), np.zeros((batch, 0, 2)), np.zeros((batch, 0)), np.zeros(batch),
                         np.zeros((batch, p, 0)), np.zeros((batch, p)))
    if system.drag is not None:
        drag_direction, drag_gradient, drag_row = system.drag
    else:
        drag_direction, drag_gradient, drag_row = np.zeros((batch, m)), np.zeros((batch, p, m)), np.zeros(m)
    columns = (p if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    scalars = (float(h), float(scheme.alpha_m), float(scheme.alpha_f), float(scheme.beta), float(scheme.gamma),
               float(settings.tolerance), float(settings.contraction_to_refactor), float(settings.force_floor))
    integers = (int(n_steps), int(settings.max_iterations), int(settings.iterations_per_factorization))
    shared = (_array(elastic.pairs, np.int64), _array(elastic.pair_of_triple, np.int64),
              _array(elastic.triples, np.int64), _array(elastic.force_coefficients),
              _array(elastic.tangent_coefficients), _array(rows), _array(own_node, np.int64),
              _array(other_node, np.int64), _array(rest_rows),
              _array(drag_row), _array(system.tail_row))
    per_design = (_array(elastic.weights), _array(elastic.weight_derivatives), _array(system.mass),
                  _array(system.damping), _array(system.mass_gradient), _array(system.damping_gradient),
                  _array(system.com_weights), _array(system.com_gradient), _array(system.amplitudes),
                  _array(system.muscle_constant), _array(system.muscle_linear),
                  _array(system.muscle_constant_gradient), _array(system.muscle_linear_gradient),
                  *thrust_arrays, _array(drag_direction), _array(drag_gradient))
    flags = (thrust is not None, bool(thrust is not None and thrust.spine.lagrangian),
             bool(thrust is not None and thrust.moving_rest), system.drag is not None, bool(sensitivities),
             bool(amplitude_sensitivity), bool(p and prom.inertia.mass.first is not None))
    arguments = (scalars, integers, units, _array(window_mask(times, DISTANCE_WINDOW), np.bool_),
                 _array(window_mask(times, AMPLITUDE_WINDOW), np.bool_), shared, per_design, flags)
    return Packed(arguments, columns, batch)


def integrate_packed(packed: Packed):
    """(distance (B,), tail amplitude (B,), failed (B,) bool, distance gradient (B, columns) or None)."""
    results = np.zeros((packed.batch, 3))
    gradients = np.zeros((packed.batch, packed.columns))
    kernel().integrate_all(*packed.arguments, results, gradients)
    failed = results[:, 2] != OK
    distance, amplitude = results[:, 0].copy(), results[:, 1].copy()
    distance[failed] = amplitude[failed] = np.nan
    return distance, amplitude, failed, gradients if packed.columns else None


def synthetic(m: int = 2, p: int = 1, halves: int = 1, n_steps: int = 2) -> Packed:
    """A small well-posed batch of one design (unit mass and stiffness, one muscle, one thrust half-segment), for
    compiling the kernel's signature without a PROM."""
    from aquarom_fenics.dynamics.batched_system import monomial_indices

    pairs, _ = monomial_indices(m, 2)
    triples, _ = monomial_indices(m, 3)
    index = {tuple(pair): n for n, pair in enumerate(pairs.tolist())}
    pair_of_triple = np.array([index[(k, l)] for k, l, _ in triples.tolist()], dtype=np.int64)
    n_mono, n_t, terms = m + len(pairs) + len(triples), 1 + m + len(pairs), 1 + p
    force_coefficients = np.zeros((n_mono, terms * m))
    force_coefficients[:m, :m] = np.eye(m)
    tangent_coefficients = np.zeros((n_t, terms * m * m))
    tangent_coefficients[0, :m * m] = np.eye(m).ravel()
    rows = np.zeros((halves + 1, 2, m))
    rows[:, 1, 0] = np.arange(halves + 1)
    own_node, other_node = half_nodes(halves + 1, False)
    shared = (pairs.astype(np.int64), pair_of_triple, triples.astype(np.int64), force_coefficients,
              tangent_coefficients, rows, own_node, other_node, np.zeros((halves + 1, 2, p)), np.zeros(m), np.ones(m))
    eye = np.eye(m)[None]
    per_design = (np.ones((1, terms)), np.zeros((1, p, terms)), eye.copy(), 0.1 * eye, np.zeros((1, p, m, m)),
                  np.zeros((1, p, m, m)), np.ones((1, m)), np.zeros((1, p, m)), np.ones(1), np.ones((1, 1, m)),
                  np.zeros((1, 1, m, m)), np.zeros((1, p, 1, m)), np.zeros((1, p, 1, m, m)), np.ones((1, halves)),
                  np.tile([1.0, 0.0], (1, halves, 1)), np.full((1, halves), 0.1), np.full(1, 0.1),
                  np.zeros((1, p, halves)), np.zeros((1, p)), np.zeros((1, m)), np.zeros((1, p, m)))
    masks = np.ones(n_steps + 1, np.bool_)
    arguments = ((1e-2, -0.5, 0.0, 0.5625, 1.0, 1e-8, 0.25, 1e-12), (n_steps, 30, 4),
                 np.ones((n_steps + 1, 1)), masks, masks.copy(), shared, per_design,
                 (True, True, True, False, True, True, True))
    return Packed(arguments, p + 1, 1)


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel's one signature on a small synthetic batch."""
    distance, _, failed, _ = integrate_packed(synthetic())
    if failed.any() or not np.isfinite(distance).all():
        raise RuntimeError("the compiled reduced kernel failed on its synthetic batch")


if __name__ == "__main__":
    import time as clock
    started = clock.perf_counter()
    warm_up()
    print(f"setup: compiled reduced kernel ready ({clock.perf_counter() - started:.1f} s)")
