"""The distance's gradient by the discrete adjoint of the compiled kernel's sensitivity step: one reverse sweep over
the stored forward trajectory instead of one forward column per parameter.

The forward sensitivity step of ``reduced_kernel`` (generalized-α, s_n = (η'_n, η̇'_n, η̈'_n), per column k):

    u_p = η'_n + h η̇'_n + h² (½ - β) η̈'_n,   v_p = η̇'_n + h (1 - γ) η̈'_n,   b = (1 - α_f) v_p + α_f η̇'_n - k_v u_p
    S x = T = -g_k - C b + k_a M u_p - α_f K η'_n - α_m M η̈'_n        (g_k = ∂r/∂ξ_k - Wᵀ K_J ∂x_rest/∂ξ_k)
    η''_{n+1} = (x - u_p) / (β h²),  η̇'_{n+1} = v_p + γ h η''_{n+1},  η'_{n+1} = x

with the full tangents K = K_t - Wᵀ K_J W, C = C_t - Wᵀ C_J W, M = M_t - Wᵀ M_J W (dense terms and the thrust's
banded point matrices J) and S = k_u K + k_v C + k_a M, the exact Newton matrix at the converged point. The
distance d = (1/N_w) Σ_{n ∈ window} c · η_n gives dd/dξ_k = (1/N_w) Σ_n (c · η'_{n,k} + ∂c/∂ξ_k · η_n). Its
transpose, from ŝ_N = (c [N ∈ window], 0, 0) backwards:

    â = ŝ₂ + γ h ŝ₁,   x̂ = ŝ₀ + â / (β h²),   Sᵀ λ = x̂,   û_p = -â / (β h²) + k_a Mᵀλ + k_v Cᵀλ,
    v̂_p = ŝ₁ - (1 - α_f) Cᵀλ,   ŝ_{n} = (-α_f Kᵀλ + û_p,  -α_f Cᵀλ + h û_p + v̂_p,
                                         -α_m Mᵀλ + h² (½ - β) û_p + h (1 - γ) v̂_p) + (c [n ∈ window], 0, 0)

and dd/dξ_k = (1/N_w) Σ_n (-λ_n · g_k,n + ∂c/∂ξ_k · η_n): one transposed solve per step whatever the number of
parameters. The products λ · g_k are summed over the steps before they meet the parameters' coefficients
(``parameter_contractions``): Σ_n λ_n · ∂f_int/∂ξ_k = Σ_j ∂c_j/∂ξ_k Σ_{q,i} F_j[q, i] (Σ_n mono_{n,q} λ_{n,i}),
one product of the stored monomials with the stored λ instead of one 454 × 108 product per step (SO3).
"""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.kernel_terms import monomials, muscle_force


@_jit
def lu_solve_transposed(factors, pivots, rhs):
    """Solve Sᵀ y = rhs (m,) in place with ``lu_solve``'s factors of S = P⁻¹ L U: Uᵀ z = rhs, Lᵀ w = z, y = Pᵀ w
    (the row swaps undone in reverse order)."""
    size = rhs.size
    for row in range(size):
        total = rhs[row]
        for k in range(row):
            total -= factors[k, row] * rhs[k]
        rhs[row] = total / factors[row, row]
    for row in range(size - 1, -1, -1):
        total = rhs[row]
        for k in range(row + 1, size):
            total -= factors[k, row] * rhs[k]
        rhs[row] = total
    for row in range(size - 1, -1, -1):
        if pivots[row] != row:
            rhs[row], rhs[pivots[row]] = rhs[pivots[row]], rhs[row]


@_jit
def banded_transposed_times(stiffness, damping, mass, right, out):
    """out (2 n_points, 3) = [K_Jᵀ y, C_Jᵀ y, M_Jᵀ y] of the points' block-tridiagonal stiffness and damping and
    block-diagonal added mass (``kernel_thrust.scatter``'s storage) in one pass: block (a, b)ᵀ applied to point
    a's two rows of y, added to point b's."""
    n_points = stiffness.shape[0]
    out[:] = 0.0
    for a in range(n_points):
        x, y = right[2 * a], right[2 * a + 1]
        for b in range(max(a - 1, 0), min(a + 2, n_points)):
            d = b - a + 1
            out[2 * b, 0] += stiffness[a, d, 0, 0] * x + stiffness[a, d, 1, 0] * y
            out[2 * b + 1, 0] += stiffness[a, d, 0, 1] * x + stiffness[a, d, 1, 1] * y
            out[2 * b, 1] += damping[a, d, 0, 0] * x + damping[a, d, 1, 0] * y
            out[2 * b + 1, 1] += damping[a, d, 0, 1] * x + damping[a, d, 1, 1] * y
        out[2 * a, 2] += mass[a, 1, 0, 0] * x + mass[a, 1, 1, 0] * y
        out[2 * a + 1, 2] += mass[a, 1, 0, 1] * x + mass[a, 1, 1, 1] * y


@_jit
def reverse_step(h, alpha_m, alpha_f, beta, gamma, k_v, k_a, factors, pivots, stiffness, damping, mass, k_banded,
                 c_banded, m_banded, has_thrust, points, transposed, hat, lam, moved, point_vectors):
    """One step of the transposed sensitivity recursion (module docstring): hat (3, m) = ŝ_{n+1} in, ŝ_n out (the
    window's seed not added); λ = S⁻ᵀ x̂ and ``moved`` = W λ out, ``point_vectors`` (2 n_points, 3) = [K_Jᵀ, C_Jᵀ,
    M_Jᵀ] W λ (its first column the moving rest stations' part). The full tangents' transposes Kᵀλ = K_tᵀλ -
    Wᵀ K_Jᵀ W λ (and C, M): the dense parts in one loop, the thrust's in one banded pass and one BLAS product."""
    m = lam.size
    inverse = 1.0 / (beta * h * h)
    for i in range(m):
        a_hat = hat[2, i] + gamma * h * hat[1, i]
        lam[i] = hat[0, i] + a_hat * inverse
        hat[2, i] = -a_hat * inverse                       # û_p's first part, kept in ŝ₂'s place
    lu_solve_transposed(factors, pivots, lam)
    products = np.zeros((m, 3))
    if has_thrust:
        moved[:] = np.dot(points, lam)
        banded_transposed_times(k_banded, c_banded, m_banded, moved, point_vectors)
        products = -np.dot(transposed, point_vectors)
    for k in range(m):
        k_t, c_t, m_t = products[k, 0], products[k, 1], products[k, 2]
        for i in range(m):
            k_t += stiffness[i, k] * lam[i]
            c_t += damping[i, k] * lam[i]
            m_t += mass[i, k] * lam[i]
        u_p = hat[2, k] + k_a * m_t + k_v * c_t
        v_p = hat[1, k] - (1.0 - alpha_f) * c_t
        hat[0, k] = -alpha_f * k_t + u_p
        hat[1, k] = -alpha_f * c_t + h * u_p + v_p
        hat[2, k] = -alpha_m * m_t + h * h * (0.5 - beta) * u_p + h * (1.0 - gamma) * v_p


@_jit
def thrust_contraction(state, length, lagrangian, own_node, other_node, moved, per_half):
    """per_half (H + 1,) += (W λ) · (the half-segment's per-mass forces of ``kernel_thrust.force_gradients``), the
    last entry the tail's: Σ_n λ_n · Wᵀ ∂f/∂ξ_k = Σ_h ∂w_h/∂ξ_k per_half[h] + ∂m̃₀/∂ξ_k per_half[H]."""
    for h in range(state.shape[0]):
        nx, ny, ndx, ndy = state[h, 2], state[h, 3], state[h, 4], state[h, 5]
        vx, vy, ax, ay = state[h, 6], state[h, 7], state[h, 8], state[h, 9]
        o, x = 2 * own_node[h], 2 * other_node[h]
        v_n = vx * nx + vy * ny
        along = ax * nx + ay * ny + vx * ndx + vy * ndy
        spine_x = -length[h] * (along * nx + v_n * ndx)
        spine_y = -length[h] * (along * ny + v_n * ndy)
        g_x, g_y = (v_n * vy, -v_n * vx) if lagrangian else (0.0, 0.0)
        per_half[h] += (moved[o] * (spine_x - g_x) + moved[o + 1] * (spine_y - g_y) + moved[x] * g_x
                        + moved[x + 1] * g_y)
    v_n = state[0, 6] * state[0, 2] + state[0, 7] * state[0, 3]
    o = 2 * own_node[0]
    per_half[-1] += 0.5 * v_n * v_n * (moved[o] * state[0, 0] + moved[o + 1] * state[0, 1])


@_jit
def parameter_contractions(lams, evaluations, activations, mono_history, force_coefficients, weight_derivatives,
                           mass_gradient, damping_gradient, muscle_constant_gradient, muscle_linear_gradient,
                           has_drag, drag_gradient, drag_row, has_thrust, per_half, thrust_weight_gradient,
                           tail_weight_gradient, out):
    """out (p,) += -Σ_n λ_n · ∂r/∂ξ_k at the steps' converged points (``kernel_terms.derivative_at``'s terms), each
    sum over the steps taken once (BLAS) before its product with the parameters' coefficients: lams (N + 1, m),
    evaluations (N + 1, 3, m) = (η, η̇, η̈) at the evaluation points, activations (N + 1, muscles), mono_history
    (N + 1, n_mono); row 0 unused (zero)."""
    m = lams.shape[1]
    p = weight_derivatives.shape[0]
    products = np.dot(mono_history.T, lams)                       # (n_mono, m) = Σ_n mono_n λ_nᵀ
    n_terms = weight_derivatives.shape[1]
    terms = np.zeros(n_terms)
    for q in range(products.shape[0]):
        for j in range(n_terms):
            total = 0.0
            for i in range(m):
                total += force_coefficients[q, j * m + i] * products[q, i]
            terms[j] += total
    with_acceleration = np.dot(lams.T, np.ascontiguousarray(evaluations[:, 2, :]))      # Σ_n λ_n η̈_nᵀ
    with_velocity = np.dot(lams.T, np.ascontiguousarray(evaluations[:, 1, :]))
    with_activation = np.dot(activations.T, lams)                 # (muscles, m) = Σ_n a_n λ_nᵀ
    n_muscles = activations.shape[1]
    with_both = np.zeros((n_muscles, m, m))                       # Σ_n a_{n,j} λ_n η_nᵀ
    drag_sum = np.zeros(m)
    for n in range(1, lams.shape[0]):
        for j in range(n_muscles):
            a_n = activations[n, j]
            for i in range(m):
                factor = a_n * lams[n, i]
                for k in range(m):
                    with_both[j, i, k] += factor * evaluations[n, 0, k]
        if has_drag:
            speed = 0.0
            for k in range(m):
                speed += drag_row[k] * evaluations[n, 1, k]
            for i in range(m):
                drag_sum[i] += speed * speed * lams[n, i]
    for c in range(p):
        total = 0.0
        for j in range(n_terms):
            total += weight_derivatives[c, j] * terms[j]
        for i in range(m):
            for k in range(m):
                total += mass_gradient[c, i, k] * with_acceleration[i, k] + damping_gradient[c, i, k] * with_velocity[i, k]
            for j in range(n_muscles):
                total += muscle_constant_gradient[c, j, i] * with_activation[j, i]
                for k in range(m):
                    total += muscle_linear_gradient[c, j, i, k] * with_both[j, i, k]
            if has_drag:
                total -= drag_gradient[c, i] * drag_sum[i]
        if has_thrust:
            for h in range(thrust_weight_gradient.shape[1]):
                total -= thrust_weight_gradient[c, h] * per_half[h]
            total -= tail_weight_gradient[c] * per_half[-1]
        out[c] -= total


@_jit
def amplitude_contraction(lam, units, muscle_constant, muscle_linear, eta):
    """-λ · ∂r/∂A at one step: ∂r/∂A = Σ_j ∂a_j/∂A (b_j + B_j η)."""
    total = 0.0
    for i in range(lam.size):
        total += lam[i] * muscle_force(units, muscle_constant, muscle_linear, eta, i)
    return -total


@_jit
def reverse_sweep(n_steps, h, alpha_m, alpha_f, beta, gamma, k_v, k_a, distance_mask, com_weights, units, factors,
                  pivots, tangents, banded, has_thrust, points, transposed, moving_rest, rest_points, states, length,
                  lagrangian, own_node, other_node, evaluations, activations, monos, force_coefficients,
                  weight_derivatives, mass_gradient, damping_gradient, muscle_constant, muscle_linear,
                  muscle_constant_gradient, muscle_linear_gradient, has_drag, drag_gradient, drag_row,
                  thrust_weight_gradient, tail_weight_gradient, parameters, amplitude_sensitivity, gradient):
    """gradient (columns,) += N_w dd/dξ (and N_w dd/dA, last) less the direct term Σ_n ∂c/∂ξ · η_n: the reverse
    sweep from step N to 1 over ``record_step``'s stores (indexed by step), seeded with c at the distance window's
    steps; ``parameters``: the ξ columns (``derivative_at``'s condition), ``moving_rest``: their rest stations'
    part (K_Jᵀ W λ) · ∂x_rest/∂ξ_k."""
    m = com_weights.size
    p = weight_derivatives.shape[0]
    hat = np.zeros((3, m))
    lams = np.zeros((n_steps + 1, m))
    moved = np.zeros(points.shape[0])
    point_vectors = np.zeros((points.shape[0], 3))
    per_half = np.zeros(own_node.size + 1)
    rest_sum = np.zeros(points.shape[0])
    amplitude = 0.0
    for step in range(n_steps, 0, -1):
        if distance_mask[step]:
            for i in range(m):
                hat[0, i] += com_weights[i]
        reverse_step(h, alpha_m, alpha_f, beta, gamma, k_v, k_a, factors[step], pivots[step], tangents[step, 0],
                     tangents[step, 1], tangents[step, 2], banded[step, 0], banded[step, 1], banded[step, 2], has_thrust,
                     points, transposed, hat, lams[step], moved, point_vectors)
        if has_thrust and parameters:
            thrust_contraction(states[step], length, lagrangian, own_node, other_node, moved, per_half)
            if moving_rest:
                for row in range(rest_sum.size):
                    rest_sum[row] += point_vectors[row, 0]
        if amplitude_sensitivity:
            amplitude += amplitude_contraction(lams[step], units[step], muscle_constant, muscle_linear,
                                               evaluations[step, 0])
    if parameters:
        contributions = np.zeros(p)
        parameter_contractions(lams, evaluations, activations, monos, force_coefficients, weight_derivatives,
                               mass_gradient, damping_gradient, muscle_constant_gradient, muscle_linear_gradient,
                               has_drag, drag_gradient, drag_row, has_thrust, per_half, thrust_weight_gradient,
                               tail_weight_gradient, contributions)
        if moving_rest:
            for row in range(rest_sum.size):
                for c in range(p):
                    contributions[c] += rest_points[row, c] * rest_sum[row]
        for c in range(p):
            gradient[c] += contributions[c]
    if amplitude_sensitivity:
        gradient[gradient.size - 1] += amplitude
