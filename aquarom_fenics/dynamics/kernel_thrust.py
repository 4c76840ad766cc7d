"""The Lighthill thrust of ``physics/thrust.py`` on the reduced kinematics, compiled, per half-segment:

    half-segment h: own point o (rear; the front for the trapezoid rule's mirrored half), other point x,
        t = t₀ + (W_x - W_o) η / ℓ₀,  ṫ = (W_x - W_o) η̇ / ℓ₀,  n = R t,  ṅ = R ṫ,  v = W_o η̇,  a = W_o η̈
    f_o += w [-ℓ₀ ((a·n + v·ṅ) n + (v·n) ṅ)] - w g,  f_x += w g,  g = (v·n) Rᵀ v (lagrangian form only)
    f_0 += m̃₀ ½ (v·n)² t  (segment 0's rear half: the tail)

with w the half-segment's virtual mass (½ m̃ of its point for the trapezoid rule), and the Jacobian blocks of
``physics/thrust_jacobians.py`` on (o, x), projected Wᵀ J W through the points' block-tridiagonal matrix.
"""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.compiled import jit as _jit


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
def add_block(block, sign, b00, b01, b10, b11):
    """block (2, 2) += sign [[b00, b01], [b10, b11]]."""
    block[0, 0] += sign * b00
    block[0, 1] += sign * b01
    block[1, 0] += sign * b10
    block[1, 1] += sign * b11


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
            add_block(stiffness[h, 1], 1.0, tail00, tail01, tail10, tail11)
            add_block(stiffness[h, 0], -1.0, tail00, tail01, tail10, tail11)
            normal_mass = tail_weight * v_n
            add_block(damping[h, 0], 1.0, normal_mass * tx * nx, normal_mass * tx * ny, normal_mass * ty * nx,
                      normal_mass * ty * ny)
        if lagrangian:
            # g = w (v·n) Rᵀ v: ∂g/∂u_x = -∂g/∂u_o = (w/ℓ) (Rᵀ v)(Rᵀ v)ᵀ (front +g, own -g)
            rx, ry = vy, -vx
            scale = w / ell
            p00, p01, p11 = scale * rx * rx, scale * rx * ry, scale * ry * ry
            for pair, sign in ((0, 1.0), (1, -1.0), (2, -1.0), (3, 1.0)):     # oo, ox, xo, xx
                add_block(stiffness[h, pair], sign, p00, p01, p01, p11)
            # ∂g/∂v = w [Rᵀ v nᵀ + (v·n) Rᵀ], Rᵀ = [[0, 1], [-1, 0]]: own -, other +
            g00 = w * (rx * nx)
            g01 = w * (rx * ny + v_n)
            g10 = w * (ry * nx - v_n)
            g11 = w * (ry * ny)
            add_block(damping[h, 0], -1.0, g00, g01, g10, g11)
            add_block(damping[h, 2], 1.0, g00, g01, g10, g11)

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
