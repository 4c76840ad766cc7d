"""The thrust's Jacobian blocks, their banded products with the shared W, the thrust's ξ-derivative and the
Newton matrix on a block of ``LANES`` designs (lane axis last; ``kernel_lanes``): ``kernel_thrust``'s
``half_blocks``, ``banded_times``, ``banded_tangents``, ``force_gradients`` and ``reduced_kernel``'s
``newton_matrix_into`` lane by lane. Banded matrices J are stored by block rows as (n_points, 3, 2, 2, LANES):
block (a, b) at [a, b - a + 1]."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.kernel_lanes import LANES
from aquarom_fenics.dynamics.lane_values import add, add_to, div, load, load3, mul, neg, store, store3, sub


ENTRIES, LAGRANGIAN_ENTRIES = 15, 22
"""Values per half-segment and lane of ``half_entries``: K's block (4), C's block (4), C's own-node block (4),
the added mass's (3: symmetric); with the Lagrangian force also its projector (3) and damping block (4)."""


@_jit
def half_entries(state, length, weights, lagrangian, entries):
    """entries (E, H LANES) of every half-segment and lane (``ENTRIES``; the tail's terms not yet added), each
    half-segment's eight lanes on tuples (``lane_values``)."""
    halves = state.shape[1]
    values = entries.reshape((entries.shape[0], halves, LANES))
    for h in range(halves):
        nx, ny, ndx, ndy = load3(state, 2, h), load3(state, 3, h), load3(state, 4, h), load3(state, 5, h)
        vx, vy, ax, ay = load3(state, 6, h), load3(state, 7, h), load3(state, 8, h), load3(state, 9, h)
        w = load(weights, h)
        minus_w = neg(w)
        a_n = add(mul(ax, nx), mul(ay, ny))
        v_nd = add(mul(vx, ndx), mul(vy, ndy))
        v_n = add(mul(vx, nx), mul(vy, ny))
        both = add(a_n, v_nd)
        store3(values, 0, h, mul(minus_w, add(mul(nx, ay), mul(ndx, vy))))
        store3(values, 1, h, mul(w, add(add(both, mul(nx, ax)), mul(ndx, vx))))
        store3(values, 2, h, mul(minus_w, add(add(both, mul(ny, ay)), mul(ndy, vy))))
        store3(values, 3, h, mul(w, add(mul(ny, ax), mul(ndy, vx))))
        c00, c01 = mul(minus_w, mul(nx, vy)), mul(w, add(mul(nx, vx), v_n))
        c10, c11 = mul(minus_w, add(mul(ny, vy), v_n)), mul(w, mul(ny, vx))
        store3(values, 4, h, c00)
        store3(values, 5, h, c01)
        store3(values, 6, h, c10)
        store3(values, 7, h, c11)
        mass_scale = mul(minus_w, load(length, h))
        store3(values, 8, h, sub(mul(mass_scale, mul(add(nx, nx), ndx)), c00))
        store3(values, 9, h, sub(mul(mass_scale, add(mul(nx, ndy), mul(ndx, ny))), c01))
        store3(values, 10, h, sub(mul(mass_scale, add(mul(ny, ndx), mul(ndy, nx))), c10))
        store3(values, 11, h, sub(mul(mass_scale, mul(add(ny, ny), ndy)), c11))
        store3(values, 12, h, mul(mass_scale, mul(nx, nx)))
        store3(values, 13, h, mul(mass_scale, mul(nx, ny)))
        store3(values, 14, h, mul(mass_scale, mul(ny, ny)))
        if lagrangian:
            scale = div(w, load(length, h))
            rx, ry = vy, neg(vx)
            store3(values, 15, h, mul(mul(scale, rx), rx))
            store3(values, 16, h, mul(mul(scale, rx), ry))
            store3(values, 17, h, mul(mul(scale, ry), ry))
            store3(values, 18, h, mul(w, mul(rx, nx)))
            store3(values, 19, h, mul(w, add(mul(rx, ny), v_n)))
            store3(values, 20, h, mul(w, sub(mul(ry, nx), v_n)))
            store3(values, 21, h, mul(w, mul(ry, ny)))


@_jit
def tail_entries(state, length, tail_weight, entries):
    """The tail's terms added to the first half-segment's entries (lanes 0..LANES-1 of ``half_entries``)."""
    for l in range(LANES):
        tx, ty, nx, ny, vx, vy = state[0, 0, l], state[1, 0, l], state[2, 0, l], state[3, 0, l], state[6, 0, l], \
            state[7, 0, l]
        v_n = vx * nx + vy * ny
        scale = tail_weight[l] / length[0, l]
        half = 0.5 * v_n * v_n
        entries[0, l] += scale * (v_n * tx * vy + half)
        entries[1, l] += scale * (v_n * tx * -vx)
        entries[2, l] += scale * (v_n * ty * vy)
        entries[3, l] += scale * (v_n * ty * -vx + half)
        normal_mass = tail_weight[l] * v_n
        entries[8, l] += normal_mass * tx * nx
        entries[9, l] += normal_mass * tx * ny
        entries[10, l] += normal_mass * ty * nx
        entries[11, l] += normal_mass * ty * ny


@_jit
def half_blocks_lanes(state, length, weights, tail_weight, lagrangian, own_node, other_node, stiffness, damping,
                      mass, entries):
    """The points' block-tridiagonal stiffness, damping and added mass per lane (``kernel_thrust.half_blocks``):
    the half-segments' entries (``half_entries``, ``tail_entries``; work array (``LAGRANGIAN_ENTRIES``, H LANES))
    added into the blocks eight lanes at a time (``lane_values``)."""
    halves, n_points = state.shape[1], stiffness.shape[0]
    half_entries(state, length, weights, lagrangian, entries)
    tail_entries(state, length, tail_weight, entries)
    values = entries.reshape((entries.shape[0], halves, LANES))
    k4, c4, m4 = (stiffness.reshape((n_points, 3, 4, LANES)), damping.reshape((n_points, 3, 4, LANES)),
                  mass.reshape((n_points, 3, 4, LANES)))
    stiffness[:] = 0.0
    damping[:] = 0.0
    mass[:] = 0.0
    for h in range(halves):
        o, x = own_node[h], other_node[h]
        k_ox, k_oo, c_ox, c_oo, m_oo = k4[o, x - o + 1], k4[o, 1], c4[o, x - o + 1], c4[o, 1], m4[o, 1]
        for e in range(4):
            k = load3(values, e, h)
            add_to(k_ox, e, k)
            add_to(k_oo, e, neg(k))
            add_to(c_ox, e, load3(values, 4 + e, h))
            add_to(c_oo, e, load3(values, 8 + e, h))
        add_to(m_oo, 0, load3(values, 12, h))
        add_to(m_oo, 1, load3(values, 13, h))
        add_to(m_oo, 2, load3(values, 13, h))
        add_to(m_oo, 3, load3(values, 14, h))
        if lagrangian:
            k_xo, k_xx, c_xo = k4[x, o - x + 1], k4[x, 1], c4[x, o - x + 1]
            for e in range(4):
                projector = load3(values, 15 + (e + 1) // 2, h)      # p00, p01, p01, p11
                add_to(k_oo, e, projector)
                add_to(k_ox, e, neg(projector))
                add_to(k_xo, e, neg(projector))
                add_to(k_xx, e, projector)
                g = load3(values, 18 + e, h)
                add_to(c_oo, e, neg(g))
                add_to(c_xo, e, g)


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
    (``kernel_thrust.banded_tangents``): a point's two rows of one column on lane tuples (``lane_values``)."""
    n_points, r = stiffness.shape[0], out.shape[1]
    for a in range(n_points):
        top, bottom = out[2 * a], out[2 * a + 1]
        m_block = mass[a, 1]
        for j in range(r):
            upper, lower = load(top, j), load(bottom, j)
            for b in range(max(a - 1, 0), min(a + 2, n_points)):
                k_block, c_block = stiffness[a, b - a + 1], damping[a, b - a + 1]
                x, y = right[2 * b], right[2 * b + 1]
                x0, y0, x1, y1 = load(x, j), load(y, j), load(x, r + j), load(y, r + j)
                upper = add(upper, add(add(add(mul(load3(k_block, 0, 0), x0), mul(load3(k_block, 0, 1), y0)),
                                           mul(load3(c_block, 0, 0), x1)), mul(load3(c_block, 0, 1), y1)))
                lower = add(lower, add(add(add(mul(load3(k_block, 1, 0), x0), mul(load3(k_block, 1, 1), y0)),
                                           mul(load3(c_block, 1, 0), x1)), mul(load3(c_block, 1, 1), y1)))
            x2, y2 = load(right[2 * a], 2 * r + j), load(right[2 * a + 1], 2 * r + j)
            store(top, j, sub(upper, add(mul(load3(m_block, 0, 0), x2), mul(load3(m_block, 0, 1), y2))))
            store(bottom, j, sub(lower, add(mul(load3(m_block, 1, 0), x2), mul(load3(m_block, 1, 1), y2))))


@_jit
def force_gradients_lanes(state, length, lagrangian, weight_gradients, tail_gradient, own_node, other_node, forces):
    """forces (2 n_points, p, LANES) = ∂f/∂ξ_k on the points per lane (``kernel_thrust.force_gradients``);
    weight_gradients (p, H, LANES), tail_gradient (p, LANES); each half-segment's force per unit weight once,
    on lane tuples (``lane_values``)."""
    forces[:] = 0.0
    p = forces.shape[1]
    for h in range(state.shape[1]):
        o, x = 2 * own_node[h], 2 * other_node[h]
        nx, ny, ndx, ndy = load3(state, 2, h), load3(state, 3, h), load3(state, 4, h), load3(state, 5, h)
        vx, vy, ax, ay = load3(state, 6, h), load3(state, 7, h), load3(state, 8, h), load3(state, 9, h)
        v_n = add(mul(vx, nx), mul(vy, ny))
        along = add(add(add(mul(ax, nx), mul(ay, ny)), mul(vx, ndx)), mul(vy, ndy))
        ell = neg(load(length, h))
        spine_x = mul(ell, add(mul(along, nx), mul(v_n, ndx)))
        spine_y = mul(ell, add(mul(along, ny), mul(v_n, ndy)))
        own_x, own_y = forces[o], forces[o + 1]
        if lagrangian:
            g_x, g_y = mul(v_n, vy), neg(mul(v_n, vx))
            spine_x, spine_y = sub(spine_x, g_x), sub(spine_y, g_y)
            other_x, other_y = forces[x], forces[x + 1]
            for c in range(p):
                w = load3(weight_gradients, c, h)
                add_to(other_x, c, mul(w, g_x))
                add_to(other_y, c, mul(w, g_y))
        for c in range(p):
            w = load3(weight_gradients, c, h)
            add_to(own_x, c, mul(w, spine_x))
            add_to(own_y, c, mul(w, spine_y))
    o = 2 * own_node[0]
    for c in range(p):
        for l in range(LANES):
            v_n = state[6, 0, l] * state[2, 0, l] + state[7, 0, l] * state[3, 0, l]
            forces[o, c, l] += tail_gradient[c, l] * (0.5 * v_n * v_n * state[0, 0, l])
            forces[o + 1, c, l] += tail_gradient[c, l] * (0.5 * v_n * v_n * state[1, 0, l])


@_jit
def combine(k_u, k_v, k_a, first, second, third, out):
    """out = k_u first + k_v second + k_a third of flat arrays: one loop of a runtime count, which the compiler
    vectorises (a loop nest over the lanes it leaves scalar)."""
    for q in range(out.size):
        out[q] = k_u * first[q] + k_v * second[q] + k_a * third[q]


@_jit
def newton_matrix_lanes(k_u, k_v, k_a, stiffness, damping, mass, has_thrust, k_banded, c_banded, m_banded,
                        s_banded, points, transposed, work, out):
    """out (m, m, LANES) = S = k_u K_t + k_v C_t + k_a M_t per lane, the thrust's -Wᵀ J W with J W banded
    (``banded_points_lanes`` into work (2 n_points, m, LANES)) and one BLAS product with Wᵀ for all lanes."""
    m = out.shape[0]
    combine(k_u, k_v, k_a, stiffness.reshape(-1), damping.reshape(-1), mass.reshape(-1), out.reshape(-1))
    if has_thrust:
        combine(k_u, k_v, k_a, k_banded.reshape(-1), c_banded.reshape(-1), m_banded.reshape(-1), s_banded.reshape(-1))
        banded_points_lanes(s_banded, points, work)
        projected = np.dot(transposed, work.reshape((work.shape[0], m * LANES))).reshape((m, m, LANES))
        flat, subtracted = out.reshape(-1), projected.reshape(-1)
        for q in range(flat.size):                 # one flat loop: vectorised (a loop nest over the lanes is not)
            flat[q] -= subtracted[q]
