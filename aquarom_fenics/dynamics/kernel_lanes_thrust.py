"""The thrust's Jacobian blocks, their banded products with the shared W, the thrust's ξ-derivative and the
Newton matrix on a block of ``LANES`` designs (lane axis last; ``kernel_lanes``): ``kernel_thrust``'s
``half_blocks``, ``banded_times``, ``banded_tangents``, ``force_gradients`` and ``reduced_kernel``'s
``newton_matrix_into`` lane by lane. Banded matrices J are stored by block rows as (n_points, 3, 2, 2, LANES):
block (a, b) at [a, b - a + 1]."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.kernel_lanes import LANES


@_jit
def half_blocks_lanes(state, length, weights, tail_weight, lagrangian, own_node, other_node, stiffness, damping,
                      mass):
    """The points' block-tridiagonal stiffness, damping and added mass per lane (``kernel_thrust.half_blocks``)."""
    stiffness[:] = 0.0
    damping[:] = 0.0
    mass[:] = 0.0
    for h in range(state.shape[0]):
        o, x = own_node[h], other_node[h]
        s = state[h]
        k_ox, k_oo, k_xo, k_xx = stiffness[o, x - o + 1], stiffness[o, 1], stiffness[x, o - x + 1], stiffness[x, 1]
        c_ox, c_oo, c_xo, m_oo = damping[o, x - o + 1], damping[o, 1], damping[x, o - x + 1], mass[o, 1]
        for l in range(LANES):
            tx, ty, nx, ny, ndx, ndy = s[0, l], s[1, l], s[2, l], s[3, l], s[4, l], s[5, l]
            vx, vy, ax, ay = s[6, l], s[7, l], s[8, l], s[9, l]
            w, ell = weights[h, l], length[h, l]
            a_n = ax * nx + ay * ny
            v_nd = vx * ndx + vy * ndy
            v_n = vx * nx + vy * ny
            b00 = a_n + v_nd + nx * ax + ndx * vx
            b01 = nx * ay + ndx * vy
            b10 = ny * ax + ndy * vx
            b11 = a_n + v_nd + ny * ay + ndy * vy
            k00, k01, k10, k11 = -w * b01, w * b00, -w * b11, w * b10
            if h == 0:
                scale = tail_weight[l] / ell
                half = 0.5 * v_n * v_n
                k00 += scale * (v_n * tx * vy + half)
                k01 += scale * (v_n * tx * -vx)
                k10 += scale * (v_n * ty * vy)
                k11 += scale * (v_n * ty * -vx + half)
                normal_mass = tail_weight[l] * v_n
                c_oo[0, 0, l] += normal_mass * tx * nx
                c_oo[0, 1, l] += normal_mass * tx * ny
                c_oo[1, 0, l] += normal_mass * ty * nx
                c_oo[1, 1, l] += normal_mass * ty * ny
            k_ox[0, 0, l] += k00
            k_ox[0, 1, l] += k01
            k_ox[1, 0, l] += k10
            k_ox[1, 1, l] += k11
            k_oo[0, 0, l] -= k00
            k_oo[0, 1, l] -= k01
            k_oo[1, 0, l] -= k10
            k_oo[1, 1, l] -= k11
            c00, c01 = -w * (nx * vy), w * (nx * vx + v_n)
            c10, c11 = -w * (ny * vy + v_n), w * (ny * vx)
            c_ox[0, 0, l] += c00
            c_ox[0, 1, l] += c01
            c_ox[1, 0, l] += c10
            c_ox[1, 1, l] += c11
            c_oo[0, 0, l] += -w * ell * (2.0 * nx * ndx) - c00
            c_oo[0, 1, l] += -w * ell * (nx * ndy + ndx * ny) - c01
            c_oo[1, 0, l] += -w * ell * (ny * ndx + ndy * nx) - c10
            c_oo[1, 1, l] += -w * ell * (2.0 * ny * ndy) - c11
            mass_scale = -w * ell
            m_oo[0, 0, l] += mass_scale * (nx * nx)
            m_oo[0, 1, l] += mass_scale * (nx * ny)
            m_oo[1, 0, l] += mass_scale * (ny * nx)
            m_oo[1, 1, l] += mass_scale * (ny * ny)
            if lagrangian:
                rx, ry = vy, -vx
                scale = w / ell
                p00, p01, p11 = scale * rx * rx, scale * rx * ry, scale * ry * ry
                k_oo[0, 0, l] += p00
                k_oo[0, 1, l] += p01
                k_oo[1, 0, l] += p01
                k_oo[1, 1, l] += p11
                k_ox[0, 0, l] -= p00
                k_ox[0, 1, l] -= p01
                k_ox[1, 0, l] -= p01
                k_ox[1, 1, l] -= p11
                k_xo[0, 0, l] -= p00
                k_xo[0, 1, l] -= p01
                k_xo[1, 0, l] -= p01
                k_xo[1, 1, l] -= p11
                k_xx[0, 0, l] += p00
                k_xx[0, 1, l] += p01
                k_xx[1, 0, l] += p01
                k_xx[1, 1, l] += p11
                g00, g01, g10, g11 = w * (rx * nx), w * (rx * ny + v_n), w * (ry * nx - v_n), w * (ry * ny)
                c_oo[0, 0, l] -= g00
                c_oo[0, 1, l] -= g01
                c_oo[1, 0, l] -= g10
                c_oo[1, 1, l] -= g11
                c_xo[0, 0, l] += g00
                c_xo[0, 1, l] += g01
                c_xo[1, 0, l] += g10
                c_xo[1, 1, l] += g11


@_jit
def banded_points_lanes(banded, points, out):
    """out (2 n_points, m, LANES) = J W per lane of the banded J and the shared W (2 n_points, m): per point row
    pair and column, eight accumulators a row (one per lane) over the neighbours' blocks."""
    n_points, m = banded.shape[0], points.shape[1]
    for a in range(n_points):
        first, last = max(a - 1, 0), min(a + 2, n_points)
        for k in range(m):
            t0 = t1 = t2 = t3 = t4 = t5 = t6 = t7 = 0.0
            b0 = b1 = b2 = b3 = b4 = b5 = b6 = b7 = 0.0
            for b in range(first, last):
                d = b - a + 1
                x, y = points[2 * b, k], points[2 * b + 1, k]
                t0 += banded[a, d, 0, 0, 0] * x + banded[a, d, 0, 1, 0] * y
                t1 += banded[a, d, 0, 0, 1] * x + banded[a, d, 0, 1, 1] * y
                t2 += banded[a, d, 0, 0, 2] * x + banded[a, d, 0, 1, 2] * y
                t3 += banded[a, d, 0, 0, 3] * x + banded[a, d, 0, 1, 3] * y
                t4 += banded[a, d, 0, 0, 4] * x + banded[a, d, 0, 1, 4] * y
                t5 += banded[a, d, 0, 0, 5] * x + banded[a, d, 0, 1, 5] * y
                t6 += banded[a, d, 0, 0, 6] * x + banded[a, d, 0, 1, 6] * y
                t7 += banded[a, d, 0, 0, 7] * x + banded[a, d, 0, 1, 7] * y
                b0 += banded[a, d, 1, 0, 0] * x + banded[a, d, 1, 1, 0] * y
                b1 += banded[a, d, 1, 0, 1] * x + banded[a, d, 1, 1, 1] * y
                b2 += banded[a, d, 1, 0, 2] * x + banded[a, d, 1, 1, 2] * y
                b3 += banded[a, d, 1, 0, 3] * x + banded[a, d, 1, 1, 3] * y
                b4 += banded[a, d, 1, 0, 4] * x + banded[a, d, 1, 1, 4] * y
                b5 += banded[a, d, 1, 0, 5] * x + banded[a, d, 1, 1, 5] * y
                b6 += banded[a, d, 1, 0, 6] * x + banded[a, d, 1, 1, 6] * y
                b7 += banded[a, d, 1, 0, 7] * x + banded[a, d, 1, 1, 7] * y
            out[2 * a, k, 0], out[2 * a, k, 1], out[2 * a, k, 2], out[2 * a, k, 3] = t0, t1, t2, t3
            out[2 * a, k, 4], out[2 * a, k, 5], out[2 * a, k, 6], out[2 * a, k, 7] = t4, t5, t6, t7
            out[2 * a + 1, k, 0], out[2 * a + 1, k, 1], out[2 * a + 1, k, 2], out[2 * a + 1, k, 3] = b0, b1, b2, b3
            out[2 * a + 1, k, 4], out[2 * a + 1, k, 5], out[2 * a + 1, k, 6], out[2 * a + 1, k, 7] = b4, b5, b6, b7


@_jit
def banded_tangents_lanes(stiffness, damping, mass, right, out):
    """out (2 n_points, r, LANES) += K R₀ + C R₁ - M R₂ per lane, R = [R₀ R₁ R₂] (2 n_points, 3r, LANES)
    (``kernel_thrust.banded_tangents``)."""
    n_points, r = stiffness.shape[0], out.shape[1]
    for a in range(n_points):
        top, bottom = out[2 * a], out[2 * a + 1]
        for b in range(max(a - 1, 0), min(a + 2, n_points)):
            d = b - a + 1
            k_block, c_block = stiffness[a, d], damping[a, d]
            x, y = right[2 * b], right[2 * b + 1]
            for j in range(r):
                for l in range(LANES):
                    x0, y0, x1, y1 = x[j, l], y[j, l], x[r + j, l], y[r + j, l]
                    top[j, l] += (k_block[0, 0, l] * x0 + k_block[0, 1, l] * y0 + c_block[0, 0, l] * x1
                                  + c_block[0, 1, l] * y1)
                    bottom[j, l] += (k_block[1, 0, l] * x0 + k_block[1, 1, l] * y0 + c_block[1, 0, l] * x1
                                     + c_block[1, 1, l] * y1)
        m_block = mass[a, 1]
        x, y = right[2 * a], right[2 * a + 1]
        for j in range(r):
            for l in range(LANES):
                x2, y2 = x[2 * r + j, l], y[2 * r + j, l]
                top[j, l] -= m_block[0, 0, l] * x2 + m_block[0, 1, l] * y2
                bottom[j, l] -= m_block[1, 0, l] * x2 + m_block[1, 1, l] * y2


@_jit
def force_gradients_lanes(state, length, lagrangian, weight_gradients, tail_gradient, own_node, other_node, forces):
    """forces (2 n_points, p, LANES) = ∂f/∂ξ_k on the points per lane (``kernel_thrust.force_gradients``);
    weight_gradients (p, H, LANES), tail_gradient (p, LANES)."""
    forces[:] = 0.0
    p = forces.shape[1]
    for h in range(state.shape[0]):
        o, x = 2 * own_node[h], 2 * other_node[h]
        for c in range(p):
            for l in range(LANES):
                nx, ny, ndx, ndy = state[h, 2, l], state[h, 3, l], state[h, 4, l], state[h, 5, l]
                vx, vy, ax, ay = state[h, 6, l], state[h, 7, l], state[h, 8, l], state[h, 9, l]
                v_n = vx * nx + vy * ny
                along = ax * nx + ay * ny + vx * ndx + vy * ndy
                spine_x = -length[h, l] * (along * nx + v_n * ndx)
                spine_y = -length[h, l] * (along * ny + v_n * ndy)
                g_x, g_y = (v_n * vy, -v_n * vx) if lagrangian else (0.0, 0.0)
                w = weight_gradients[c, h, l]
                forces[o, c, l] += w * (spine_x - g_x)
                forces[o + 1, c, l] += w * (spine_y - g_y)
                forces[x, c, l] += w * g_x
                forces[x + 1, c, l] += w * g_y
    o = 2 * own_node[0]
    for c in range(p):
        for l in range(LANES):
            v_n = state[0, 6, l] * state[0, 2, l] + state[0, 7, l] * state[0, 3, l]
            forces[o, c, l] += tail_gradient[c, l] * (0.5 * v_n * v_n * state[0, 0, l])
            forces[o + 1, c, l] += tail_gradient[c, l] * (0.5 * v_n * v_n * state[0, 1, l])


@_jit
def newton_matrix_lanes(k_u, k_v, k_a, stiffness, damping, mass, has_thrust, k_banded, c_banded, m_banded,
                        s_banded, points, transposed, work, out):
    """out (m, m, LANES) = S = k_u K_t + k_v C_t + k_a M_t per lane, the thrust's -Wᵀ J W with J W banded
    (``banded_points_lanes`` into work (2 n_points, m, LANES)) and one BLAS product with Wᵀ for all lanes."""
    m = out.shape[0]
    for i in range(m):
        for k in range(m):
            for l in range(LANES):
                out[i, k, l] = k_u * stiffness[i, k, l] + k_v * damping[i, k, l] + k_a * mass[i, k, l]
    if has_thrust:
        for a in range(k_banded.shape[0]):
            for d in range(3):
                for i in range(2):
                    for j in range(2):
                        for l in range(LANES):
                            s_banded[a, d, i, j, l] = (k_u * k_banded[a, d, i, j, l] + k_v * c_banded[a, d, i, j, l]
                                                       + k_a * m_banded[a, d, i, j, l])
        banded_points_lanes(s_banded, points, work)
        projected = np.dot(transposed, work.reshape((work.shape[0], m * LANES))).reshape((m, m, LANES))
        for i in range(m):
            for k in range(m):
                for l in range(LANES):
                    out[i, k, l] -= projected[i, k, l]
