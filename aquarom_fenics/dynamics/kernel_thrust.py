"""The Lighthill thrust of ``physics/thrust.py`` on the reduced kinematics, compiled, per half-segment:

    half-segment h: own point o (rear; the front for the trapezoid rule's mirrored half), other point x,
        t = t₀ + (W_x - W_o) η / ℓ₀,  ṫ = (W_x - W_o) η̇ / ℓ₀,  n = R t,  ṅ = R ṫ,  v = W_o η̇,  a = W_o η̈
    f_o += w [-ℓ₀ ((a·n + v·ṅ) n + (v·n) ṅ)] - w g,  f_x += w g,  g = (v·n) Rᵀ v (lagrangian form only)
    f_0 += m̃₀ ½ (v·n)² t  (segment 0's rear half: the tail)

with w the half-segment's virtual mass (½ m̃ of its point for the trapezoid rule), and the Jacobian blocks of
``physics/thrust_jacobians.py`` on (o, x), assembled into the points' block-tridiagonal matrices J (stiffness,
damping, added mass) and projected as Wᵀ (J W): the banded product here, the product with Wᵀ one BLAS call.
"""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit


@_jit
def step_points(points, u, v, a, out):
    """out (2 n_points, 3) = W (u, v, a): the points' state at a step's start, one BLAS product."""
    stacked = np.empty((u.size, 3))
    for k in range(u.size):
        stacked[k, 0], stacked[k, 1], stacked[k, 2] = u[k], v[k], a[k]
    out[:] = np.dot(points, stacked)


@_jit
def point_kinematics(at_new, at_step, h, alpha_m, alpha_f, beta, gamma, out):
    """out (2 n_points, 3) = W (η, η̇, η̈) at a Newton iterate's evaluation point, from W u_{n+1} (``at_new``) and
    W (u_n, v_n, a_n) (``at_step``, (2 n_points, 3)). The generalized-α relations of ``reduced_kernel`` make all
    three affine in u_{n+1}: u_p = u_n + h v_n + h² (½ - β) a_n, v_p = v_n + h (1 - γ) a_n, a_{n+1} = (u_{n+1} -
    u_p) / (β h²), v_{n+1} = v_p + γ h a_{n+1}, then x_{n+1-α} = (1 - α) x_{n+1} + α x_n. So an iterate costs one
    product with W, not three."""
    inverse = 1.0 / (beta * h * h)
    for r in range(at_new.size):
        u, v, a = at_step[r, 0], at_step[r, 1], at_step[r, 2]
        u_p = u + h * v + h * h * (0.5 - beta) * a
        v_p = v + h * (1.0 - gamma) * a
        a_new = (at_new[r] - u_p) * inverse
        v_new = v_p + gamma * h * a_new
        out[r, 0] = at_new[r] if alpha_f == 0.0 else (1.0 - alpha_f) * at_new[r] + alpha_f * u
        out[r, 1] = v_new if alpha_f == 0.0 else (1.0 - alpha_f) * v_new + alpha_f * v
        out[r, 2] = a_new if alpha_m == 0.0 else (1.0 - alpha_m) * a_new + alpha_m * a


@_jit
def thrust_force(kinematics, transposed, own_node, other_node, length, inverse_length, rest_tangent, weights,
                 tail_weight, lagrangian, state, out):
    """out += Wᵀ f_thrust: per half-segment h its state[h] = (t, n, ṅ, v, a) (10 numbers, x and y each; kept for
    the Jacobian blocks at this point) from the points' kinematics (W η, W η̇, W η̈) as (2 n_points, 3), rows (x, y)
    of each point (``point_kinematics``), and its weighted forces assembled on the points in the same pass (the
    module's law; ``force_gradients`` weights the same per-mass forces by their ξ-derivatives). ``transposed`` =
    Wᵀ; ``inverse_length`` 1/ℓ₀ per half-segment."""
    m, n_rows = transposed.shape[0], kinematics.shape[0]
    force = np.zeros(n_rows)
    for h in range(own_node.size):
        o, x = 2 * own_node[h], 2 * other_node[h]
        scale = inverse_length[h]
        tx = rest_tangent[h, 0] + (kinematics[x, 0] - kinematics[o, 0]) * scale
        ty = rest_tangent[h, 1] + (kinematics[x + 1, 0] - kinematics[o + 1, 0]) * scale
        nx, ny = -ty, tx                                                      # n = R t
        ndx = -(kinematics[x + 1, 1] - kinematics[o + 1, 1]) * scale         # ṅ = R ṫ
        ndy = (kinematics[x, 1] - kinematics[o, 1]) * scale
        vx, vy, ax, ay = kinematics[o, 1], kinematics[o + 1, 1], kinematics[o, 2], kinematics[o + 1, 2]
        state[h, 0], state[h, 1], state[h, 2], state[h, 3], state[h, 4] = tx, ty, nx, ny, ndx
        state[h, 5], state[h, 6], state[h, 7], state[h, 8], state[h, 9] = ndy, vx, vy, ax, ay
        v_n = vx * nx + vy * ny
        along = ax * nx + ay * ny + vx * ndx + vy * ndy
        w = weights[h]
        spine_x = -length[h] * (along * nx + v_n * ndx)
        spine_y = -length[h] * (along * ny + v_n * ndy)
        if lagrangian:
            g_x, g_y = v_n * vy, -v_n * vx                                    # (v·n) Rᵀ v
            force[o] += w * (spine_x - g_x)
            force[o + 1] += w * (spine_y - g_y)
            force[x] += w * g_x
            force[x + 1] += w * g_y
        else:
            force[o] += w * spine_x
            force[o + 1] += w * spine_y
    v_n = state[0, 6] * state[0, 2] + state[0, 7] * state[0, 3]
    o = 2 * own_node[0]
    force[o] += tail_weight * 0.5 * v_n * v_n * state[0, 0]                  # the tail: ½ m̃₀ (v·n)² t
    force[o + 1] += tail_weight * 0.5 * v_n * v_n * state[0, 1]
    projected = np.dot(transposed, force)
    for k in range(m):
        out[k] += projected[k]


@_jit
def force_gradients(state, length, lagrangian, weight_gradients, tail_gradient, own_node, other_node, forces):
    """forces (p, 2 n_points) = ∂f/∂ξ_k on the points at fixed kinematics: the half-segments' per-mass forces
    (f_spine/m̃ on o, g/m̃ on x and -g/m̃ on o, the tail's ½ (v·n)² t) weighted by ∂w_h/∂ξ_k (p, H) and
    ∂m̃₀/∂ξ_k (p,)."""
    forces[:] = 0.0
    p = forces.shape[0]
    for h in range(state.shape[0]):
        tx, ty, nx, ny, ndx, ndy = state[h, 0], state[h, 1], state[h, 2], state[h, 3], state[h, 4], state[h, 5]
        vx, vy, ax, ay = state[h, 6], state[h, 7], state[h, 8], state[h, 9]      # not a row's unpacking: slower
        o, x = 2 * own_node[h], 2 * other_node[h]
        v_n = vx * nx + vy * ny
        along = ax * nx + ay * ny + vx * ndx + vy * ndy
        spine_x = -length[h] * (along * nx + v_n * ndx)
        spine_y = -length[h] * (along * ny + v_n * ndy)
        g_x, g_y = (v_n * vy, -v_n * vx) if lagrangian else (0.0, 0.0)      # (v·n) Rᵀ v
        for c in range(p):
            w = weight_gradients[c, h]
            forces[c, o] += w * (spine_x - g_x)
            forces[c, o + 1] += w * (spine_y - g_y)
            forces[c, x] += w * g_x
            forces[c, x + 1] += w * g_y
    v_n = state[0, 6] * state[0, 2] + state[0, 7] * state[0, 3]
    tail_x, tail_y = 0.5 * v_n * v_n * state[0, 0], 0.5 * v_n * v_n * state[0, 1]
    o = 2 * own_node[0]
    for c in range(p):
        forces[c, o] += tail_gradient[c] * tail_x
        forces[c, o + 1] += tail_gradient[c] * tail_y


@_jit
def scatter(banded, a, b, sign, b00, b01, b10, b11):
    """J's block (a, b) += sign [[b00, b01], [b10, b11]], J stored by block rows: banded[a, b - a + 1] (|a - b| ≤ 1)."""
    d = b - a + 1
    banded[a, d, 0, 0] += sign * b00
    banded[a, d, 0, 1] += sign * b01
    banded[a, d, 1, 0] += sign * b10
    banded[a, d, 1, 1] += sign * b11


@_jit
def half_blocks(state, length, weights, tail_weight, lagrangian, own_node, other_node, stiffness, damping, mass):
    """The Jacobian blocks of ``thrust_jacobians`` per half-segment on (o, x), assembled into the points'
    block-tridiagonal stiffness, damping and added-mass matrices (n_points, 3, 2, 2) (``scatter``'s storage)."""
    stiffness[:] = 0.0
    damping[:] = 0.0
    mass[:] = 0.0
    for h in range(state.shape[0]):
        tx, ty, nx, ny, ndx, ndy = state[h, 0], state[h, 1], state[h, 2], state[h, 3], state[h, 4], state[h, 5]
        vx, vy, ax, ay = state[h, 6], state[h, 7], state[h, 8], state[h, 9]      # not a row's unpacking: slower
        o, x = own_node[h], other_node[h]
        w, ell = weights[h], length[h]
        a_n = ax * nx + ay * ny
        v_nd = vx * ndx + vy * ndy
        v_n = vx * nx + vy * ny
        # ∂B/∂n = (a·n + v·ṅ) I + n aᵀ + ṅ vᵀ; ∂f/∂u_x = -w (∂B/∂n) R = -∂f/∂u_o, with M R = [[M01, -M00], [M11, -M10]]
        b00 = a_n + v_nd + nx * ax + ndx * vx
        b01 = nx * ay + ndx * vy
        b10 = ny * ax + ndy * vx
        b11 = a_n + v_nd + ny * ay + ndy * vy
        k00, k01, k10, k11 = -w * b01, w * b00, -w * b11, w * b10
        if h == 0:
            # f_tail = ½ m̃₀ (v·n)² t: ∂/∂u_x = -∂/∂u_o = (m̃₀/ℓ) [(v·n) t (Rᵀ v)ᵀ + ½ (v·n)² I]; ∂/∂u̇_o = m̃₀ (v·n) t nᵀ
            scale = tail_weight / ell
            half = 0.5 * v_n * v_n
            k00 += scale * (v_n * tx * vy + half)
            k01 += scale * (v_n * tx * -vx)
            k10 += scale * (v_n * ty * vy)
            k11 += scale * (v_n * ty * -vx + half)
            normal_mass = tail_weight * v_n
            scatter(damping, o, o, 1.0, normal_mass * tx * nx, normal_mass * tx * ny, normal_mass * ty * nx,
                    normal_mass * ty * ny)
        scatter(stiffness, o, x, 1.0, k00, k01, k10, k11)
        scatter(stiffness, o, o, -1.0, k00, k01, k10, k11)
        # ∂B/∂ṅ = n vᵀ + (v·n) I; ∂f/∂u̇_x = -w (∂B/∂ṅ) R; ∂f/∂u̇_o = -w ℓ (n ṅᵀ + ṅ nᵀ) - ∂f/∂u̇_x
        c00, c01 = -w * (nx * vy), w * (nx * vx + v_n)
        c10, c11 = -w * (ny * vy + v_n), w * (ny * vx)
        scatter(damping, o, x, 1.0, c00, c01, c10, c11)
        scatter(damping, o, o, 1.0, -w * ell * (2.0 * nx * ndx) - c00, -w * ell * (nx * ndy + ndx * ny) - c01,
                -w * ell * (ny * ndx + ndy * nx) - c10, -w * ell * (2.0 * ny * ndy) - c11)
        scatter(mass, o, o, -w * ell, nx * nx, nx * ny, ny * nx, ny * ny)
        if lagrangian:
            # g = w (v·n) Rᵀ v: ∂g/∂u_x = -∂g/∂u_o = (w/ℓ) (Rᵀ v)(Rᵀ v)ᵀ (front +g, own -g)
            rx, ry = vy, -vx
            scale = w / ell
            p00, p01, p11 = scale * rx * rx, scale * rx * ry, scale * ry * ry
            scatter(stiffness, o, o, 1.0, p00, p01, p01, p11)
            scatter(stiffness, o, x, -1.0, p00, p01, p01, p11)
            scatter(stiffness, x, o, -1.0, p00, p01, p01, p11)
            scatter(stiffness, x, x, 1.0, p00, p01, p01, p11)
            # ∂g/∂v = w [Rᵀ v nᵀ + (v·n) Rᵀ], Rᵀ = [[0, 1], [-1, 0]]: own -, other +
            g00, g01, g10, g11 = w * (rx * nx), w * (rx * ny + v_n), w * (ry * nx - v_n), w * (ry * ny)
            scatter(damping, o, o, -1.0, g00, g01, g10, g11)
            scatter(damping, x, o, 1.0, g00, g01, g10, g11)


@_jit
def banded_times(banded, right, first, factor, out):
    """out (2 n_points, r) += factor J R of the block-tridiagonal J (``scatter``'s storage) and the columns
    first … first + r - 1 of R (2 n_points, ·): a point's two rows at once from each neighbour's two."""
    n_points, r = banded.shape[0], out.shape[1]
    for a in range(n_points):
        top, bottom = out[2 * a], out[2 * a + 1]
        for b in range(max(a - 1, 0), min(a + 2, n_points)):
            d = b - a + 1
            j00, j01 = factor * banded[a, d, 0, 0], factor * banded[a, d, 0, 1]
            j10, j11 = factor * banded[a, d, 1, 0], factor * banded[a, d, 1, 1]
            x, y = right[2 * b, first:first + r], right[2 * b + 1, first:first + r]
            for j in range(r):
                top[j] += j00 * x[j] + j01 * y[j]
                bottom[j] += j10 * x[j] + j11 * y[j]


@_jit
def banded_tangents(stiffness, damping, mass, right, out):
    """out (2 n_points, r) += K R₀ + C R₁ - M R₂ of the points' stiffness, damping and added mass (``scatter``'s
    storage; M block-diagonal) and the column sets R = [R₀ R₁ R₂] (2 n_points, 3r): ``banded_times`` of the three
    in one pass."""
    n_points, r = stiffness.shape[0], out.shape[1]
    for a in range(n_points):
        top, bottom = out[2 * a], out[2 * a + 1]
        for b in range(max(a - 1, 0), min(a + 2, n_points)):
            d = b - a + 1
            k00, k01 = stiffness[a, d, 0, 0], stiffness[a, d, 0, 1]
            k10, k11 = stiffness[a, d, 1, 0], stiffness[a, d, 1, 1]
            c00, c01, c10, c11 = damping[a, d, 0, 0], damping[a, d, 0, 1], damping[a, d, 1, 0], damping[a, d, 1, 1]
            x, y = right[2 * b], right[2 * b + 1]
            for j in range(r):
                x0, y0, x1, y1 = x[j], y[j], x[r + j], y[r + j]
                top[j] += k00 * x0 + k01 * y0 + c00 * x1 + c01 * y1
                bottom[j] += k10 * x0 + k11 * y0 + c10 * x1 + c11 * y1
        m00, m01, m10, m11 = mass[a, 1, 0, 0], mass[a, 1, 0, 1], mass[a, 1, 1, 0], mass[a, 1, 1, 1]
        x, y = right[2 * a], right[2 * a + 1]
        for j in range(r):
            x2, y2 = x[2 * r + j], y[2 * r + j]
            top[j] -= m00 * x2 + m01 * y2
            bottom[j] -= m10 * x2 + m11 * y2


@_jit
def newton_matrix_into(k_u, k_v, k_a, stiffness, damping, mass, has_thrust, k_banded, c_banded, m_banded, s_banded,
                       points, transposed, work, out):
    """out = S = k_u K_t + k_v C_t + k_a M_t (``reduced_dynamics.newton_matrix``): the dense tangents of every term
    but the thrust, and the thrust's point matrices (``half_blocks``) combined before their one projection
    -Wᵀ J W (J W banded, then one BLAS product with Wᵀ; ``work`` (2 n_points, m))."""
    m = out.shape[0]
    for i in range(m):
        for k in range(m):
            out[i, k] = k_u * stiffness[i, k] + k_v * damping[i, k] + k_a * mass[i, k]
    if has_thrust:
        for a in range(k_banded.shape[0]):
            for d in range(3):
                for i in range(2):
                    for j in range(2):
                        s_banded[a, d, i, j] = (k_u * k_banded[a, d, i, j] + k_v * c_banded[a, d, i, j]
                                                + k_a * m_banded[a, d, i, j])
        work[:] = 0.0
        banded_times(s_banded, points, 0, 1.0, work)
        projected = np.dot(transposed, work)
        for i in range(m):
            for k in range(m):
                out[i, k] -= projected[i, k]
