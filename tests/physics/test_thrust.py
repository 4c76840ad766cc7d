"""Lighthill thrust (SPEC §5): forces, exact Jacobians, virtual-mass derivative, physical checks."""

import numpy as np
import pytest

from aquarom_fenics.physics.thrust import (
    ROTATION_90,
    SpineGeometry,
    derivative_weights,
    segment_frame,
    segment_state,
    segment_weighted_force,
    thrust_force,
    thrust_force_per_virtual_mass,
    virtual_mass,
)
from aquarom_fenics.physics.thrust_jacobians import thrust_jacobians

N_NODES = 12
FISH_LENGTH = 0.2
JACOBIAN_TOLERANCE = 1e-9


def make_geometry(rng: np.random.Generator, n_nodes: int = N_NODES) -> SpineGeometry:
    """Spine along x ∈ [-0.2, 0] with slightly perturbed y, positive virtual masses."""
    x = np.linspace(-FISH_LENGTH, 0.0, n_nodes)
    y = 1e-3 * rng.standard_normal(n_nodes)
    dorsal_z = rng.uniform(0.02, 0.05, n_nodes - 1)
    return SpineGeometry(np.column_stack([x, y]), virtual_mass(dorsal_z, 1000.0))


def make_state(rng: np.random.Generator, n_nodes: int = N_NODES):
    """Displacement ~1 cm, velocity ~0.1 m/s, acceleration ~1 m/s²."""
    displacement = 1e-2 * rng.standard_normal((n_nodes, 2))
    velocity = 1e-1 * rng.standard_normal((n_nodes, 2))
    acceleration = rng.standard_normal((n_nodes, 2))
    return displacement, velocity, acceleration


@pytest.fixture
def geometry():
    return make_geometry(np.random.default_rng(20240611))


@pytest.fixture
def state():
    return make_state(np.random.default_rng(7))


def central_difference_jacobian(force_of, field: np.ndarray, step: float) -> np.ndarray:
    """∂force/∂field by central differences, columns in dof order (x0, y0, x1, y1, ...)."""
    flat = field.ravel()
    columns = []
    for dof in range(flat.size):
        shift = np.zeros_like(flat)
        shift[dof] = step
        plus = force_of((flat + shift).reshape(field.shape))
        minus = force_of((flat - shift).reshape(field.shape))
        columns.append(((plus - minus) / (2.0 * step)).ravel())
    return np.column_stack(columns)


def relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    return np.max(np.abs(actual - expected)) / np.max(np.abs(expected))


# f is a polynomial of degree <= 3 in u and <= 2 in (u̇, ü): the u-step is small against the
# segment length (truncation ~ (h/ℓ_0)²), the others are exact up to round-off.
@pytest.mark.parametrize("spine_force", ["source", "lagrangian"])
@pytest.mark.parametrize(
    "which, step",
    [("displacement", 1e-6), ("velocity", 1e-3), ("acceleration", 1e-3)],
)
def test_jacobians_match_central_differences(geometry, state, which, step, spine_force):
    geometry = SpineGeometry(geometry.rest_xy, geometry.virtual_mass, spine_force)
    displacement, velocity, acceleration = state
    fields = {"displacement": displacement, "velocity": velocity, "acceleration": acceleration}
    jacobian = dict(zip(fields, thrust_jacobians(geometry, *state)))[which]

    def force_of(field):
        return thrust_force(geometry, **{**fields, which: field})

    expected = central_difference_jacobian(force_of, fields[which], step)
    assert relative_error(jacobian, expected) < JACOBIAN_TOLERANCE


def test_jacobians_are_block_tridiagonal(geometry, state):
    """Node r couples with r and r + 1 only (block upper-bidiagonal, a subset of tridiagonal)."""
    node = np.repeat(np.arange(N_NODES), 2)
    outside_band = (node[None, :] < node[:, None]) | (node[None, :] > node[:, None] + 1)
    for jacobian in thrust_jacobians(geometry, *state):
        assert jacobian.shape == (2 * N_NODES, 2 * N_NODES)
        assert np.all(jacobian[outside_band] == 0.0)
        assert np.any(jacobian[~outside_band] != 0.0)


def test_added_mass_block_is_block_diagonal_symmetric_negative_semidefinite(geometry, state):
    _, _, added_mass = thrust_jacobians(geometry, *state)
    node = np.repeat(np.arange(N_NODES), 2)
    assert np.all(added_mass[node[:, None] != node[None, :]] == 0.0)
    np.testing.assert_allclose(added_mass, added_mass.T, rtol=0, atol=0)
    assert np.all(np.linalg.eigvalsh(added_mass) <= 1e-15)


def test_lagrangian_jacobians_are_block_tridiagonal_with_lower_blocks(geometry, state):
    lagrangian = SpineGeometry(geometry.rest_xy, geometry.virtual_mass, "lagrangian")
    node = np.repeat(np.arange(N_NODES), 2)
    below = node[None, :] == node[:, None] - 1
    outside_band = np.abs(node[None, :] - node[:, None]) > 1
    stiffness, damping, _ = thrust_jacobians(lagrangian, *state)
    for jacobian in (stiffness, damping):
        assert np.all(jacobian[outside_band] == 0.0)
        assert np.any(jacobian[below] != 0.0)


@pytest.mark.parametrize("spine_force", ["source", "lagrangian"])
def test_force_per_virtual_mass_matches_differences_and_sums_to_force(geometry, state, spine_force):
    geometry = SpineGeometry(geometry.rest_xy, geometry.virtual_mass, spine_force)
    per_mass = thrust_force_per_virtual_mass(geometry, *state)
    assert per_mass.shape == (N_NODES - 1, N_NODES, 2)
    summed = np.einsum("i,ijk->jk", geometry.virtual_mass, per_mass)
    np.testing.assert_allclose(summed, thrust_force(geometry, *state), rtol=1e-13, atol=0)

    def force_of(segment_mass):
        return thrust_force(SpineGeometry(geometry.rest_xy, segment_mass, spine_force), *state)

    step = 1e-3 * np.min(geometry.virtual_mass)
    expected = central_difference_jacobian(force_of, geometry.virtual_mass, step)
    assert relative_error(per_mass.reshape(N_NODES - 1, -1).T, expected) < JACOBIAN_TOLERANCE


def test_zero_velocity_and_acceleration_give_zero_force(geometry, state):
    displacement, _, _ = state
    still = np.zeros((N_NODES, 2))
    assert np.all(thrust_force(geometry, displacement, still, still) == 0.0)


def straight_spine(n_nodes: int = N_NODES) -> np.ndarray:
    return np.column_stack([np.linspace(-FISH_LENGTH, 0.0, n_nodes), np.zeros(n_nodes)])


def test_normal_is_tangent_rotated_plus_90_degrees():
    geometry = SpineGeometry(straight_spine(), np.ones(N_NODES - 1))
    tangent, normal = segment_frame(geometry, np.zeros((N_NODES, 2)))
    np.testing.assert_allclose(tangent, np.tile([1.0, 0.0], (N_NODES - 1, 1)), atol=1e-15)
    np.testing.assert_allclose(normal, np.tile([0.0, 1.0], (N_NODES - 1, 1)), atol=1e-15)

    spine_along_y = SpineGeometry(np.array([[0.0, 0.0], [0.0, 0.1]]), np.ones(1))
    _, normal = segment_frame(spine_along_y, np.zeros((2, 2)))
    np.testing.assert_allclose(normal, [[-1.0, 0.0]], atol=1e-15)


def test_straight_fish_with_lateral_tail_velocity_is_pushed_forward():
    segment_mass = np.linspace(0.5, 2.0, N_NODES - 1)
    geometry = SpineGeometry(straight_spine(), segment_mass)
    lateral_speed = 0.3
    velocity = np.tile([0.0, lateral_speed], (N_NODES, 1))
    still = np.zeros((N_NODES, 2))

    force = thrust_force(geometry, still, velocity, still)

    expected = np.zeros((N_NODES, 2))
    expected[0] = [0.5 * segment_mass[0] * lateral_speed**2, 0.0]
    np.testing.assert_allclose(force, expected, rtol=1e-14, atol=1e-15)
    mirrored = thrust_force(geometry, still, -velocity, still)
    np.testing.assert_allclose(mirrored, expected, rtol=1e-14, atol=1e-15)


def test_spine_force_is_minus_virtual_mass_times_rate_of_lateral_momentum(geometry):
    """f_spine = -m̃ ℓ_0 d/dt[(v·n) n] along a smooth prescribed motion u(t)."""
    rng = np.random.default_rng(3)
    amplitude = 1e-2 * rng.standard_normal((N_NODES, 2))
    omega = 2.0 * np.pi * rng.uniform(0.5, 2.0, (N_NODES, 2))
    phase = rng.uniform(0.0, 2.0 * np.pi, (N_NODES, 2))

    def displacement(t):
        return amplitude * np.sin(omega * t + phase)

    def velocity(t):
        return amplitude * omega * np.cos(omega * t + phase)

    def acceleration(t):
        return -amplitude * omega**2 * np.sin(omega * t + phase)

    def lateral_momentum_per_mass(t):
        _, normal = segment_frame(geometry, displacement(t))
        rear_velocity = velocity(t)[:-1]
        return np.einsum("ij,ij->i", rear_velocity, normal)[:, None] * normal

    t, dt = 0.37, 1e-6
    rate = (lateral_momentum_per_mass(t + dt) - lateral_momentum_per_mass(t - dt)) / (2.0 * dt)
    expected_spine = -(geometry.virtual_mass * geometry.rest_length)[:, None] * rate

    force = thrust_force(geometry, displacement(t), velocity(t), acceleration(t))
    tangent, normal = segment_frame(geometry, displacement(t))
    tail = 0.5 * geometry.virtual_mass[0] * (velocity(t)[0] @ normal[0]) ** 2 * tangent[0]
    spine = force[:-1].copy()
    spine[0] -= tail

    assert relative_error(spine, expected_spine) < 1e-8


def periodic_motion(rng, period):
    """Smooth T-periodic spine motion: harmonics 1–3 of 2π/T per node and component."""
    amplitude = 1e-2 * rng.standard_normal((3, N_NODES, 2))
    phase = rng.uniform(0.0, 2.0 * np.pi, (3, N_NODES, 2))
    omega = 2.0 * np.pi / period * np.arange(1, 4)[:, None, None]

    def at(t):
        """(u, u̇, ü) at time t."""
        angle = omega * t + phase
        return ((amplitude * np.sin(angle)).sum(0), (amplitude * omega * np.cos(angle)).sum(0),
                (-amplitude * omega ** 2 * np.sin(angle)).sum(0))

    return at


def spine_power(geometry, motion, t):
    """Σ_nodes f·u̇ of the spine force (the tail force removed)."""
    u, v, a = motion(t)
    force = thrust_force(geometry, u, v, a)
    tangent, normal = segment_frame(geometry, u)
    force[0] -= 0.5 * geometry.virtual_mass[0] * (v[0] @ normal[0]) ** 2 * tangent[0]
    return float(np.sum(force * v))


def added_mass_energy(geometry, motion, t):
    """T_a = Σ ½ m̃ ℓ_0 (v_r·n)² [J]."""
    u, v, _ = motion(t)
    _, normal = segment_frame(geometry, u)
    return 0.5 * float(np.sum(geometry.virtual_mass * geometry.rest_length * np.einsum("ij,ij->i", v[:-1], normal) ** 2))


def test_lagrangian_spine_force_power_is_minus_the_rate_of_added_mass_energy(geometry):
    """f = -d/dt(∂T_a/∂v) + ∂T_a/∂x  ⇒  Σ f·u̇ = -dT_a/dt at every instant."""
    lagrangian = SpineGeometry(geometry.rest_xy, geometry.virtual_mass, "lagrangian")
    motion = periodic_motion(np.random.default_rng(11), 1.0)
    dt = 1e-6
    for t in (0.1, 0.37, 0.8):
        rate = (added_mass_energy(lagrangian, motion, t + dt) - added_mass_energy(lagrangian, motion, t - dt)) / (2 * dt)
        assert abs(spine_power(lagrangian, motion, t) + rate) < 1e-7 * abs(rate)


def test_only_the_lagrangian_spine_force_does_no_net_work_over_a_closed_cycle(geometry):
    motion = periodic_motion(np.random.default_rng(12), 1.0)
    times = np.linspace(0.0, 1.0, 2000, endpoint=False)     # the rectangle rule is spectral for periodic data
    work = {}
    for form in ("source", "lagrangian"):
        form_geometry = SpineGeometry(geometry.rest_xy, geometry.virtual_mass, form)
        powers = np.array([spine_power(form_geometry, motion, t) for t in times])
        work[form] = (powers.mean(), np.abs(powers).mean())
    assert abs(work["lagrangian"][0]) < 1e-10 * work["lagrangian"][1]
    assert abs(work["source"][0]) > 1e-2 * work["source"][1]


def test_virtual_mass_formula():
    dorsal_z = np.array([0.05, 0.025, 0.0])
    expected = np.pi / 4.0 * 1000.0 * (2.0 * dorsal_z) ** 2
    np.testing.assert_allclose(virtual_mass(dorsal_z, 1000.0), expected, rtol=1e-15)
    assert virtual_mass(0.05, 1000.0) == pytest.approx(np.pi * 1000.0 * 0.05**2, rel=1e-15)


def test_rest_length_and_shape_checks():
    geometry = SpineGeometry(straight_spine(), np.ones(N_NODES - 1))
    np.testing.assert_allclose(geometry.rest_length, FISH_LENGTH / (N_NODES - 1), rtol=1e-14)
    with pytest.raises(ValueError, match="one per segment"):
        SpineGeometry(straight_spine(), np.ones(N_NODES))
    with pytest.raises(ValueError, match="zero rest length"):
        SpineGeometry(np.zeros((3, 2)), np.ones(2))
    with pytest.raises(ValueError, match="spine nodal field"):
        thrust_force(geometry, np.zeros((N_NODES, 3)), np.zeros((N_NODES, 2)), np.zeros((N_NODES, 2)))


# ---------------------------------------------------------------------- the trapezoid rule
def trapezoid(geometry: SpineGeometry, spine_force: str = "source", seed: int = 3) -> SpineGeometry:
    front = virtual_mass(np.random.default_rng(seed).uniform(0.02, 0.05, geometry.n_nodes - 1), 1000.0)
    return SpineGeometry(geometry.rest_xy, geometry.virtual_mass, spine_force, front_mass=front)


def test_trapezoid_rule_shares_each_segment_between_its_two_nodes(geometry, state):
    """f = ½ (rear rule with m̃_r) + ½ (the same law at the front node with m̃_f) + f_tail (whole)."""
    trap = trapezoid(geometry)
    u, v, a = state
    tangent, normal = segment_frame(trap, u)
    normal_rate = (v[1:] - v[:-1]) @ ROTATION_90.T / trap.rest_length[:, None]
    expected = np.zeros((N_NODES, 2))
    for s in range(N_NODES - 1):
        for node, mass in ((s, trap.virtual_mass[s]), (s + 1, trap.front_mass[s])):
            bracket = ((a[node] @ normal[s] + v[node] @ normal_rate[s]) * normal[s]
                       + (v[node] @ normal[s]) * normal_rate[s])
            expected[node] -= 0.5 * mass * trap.rest_length[s] * bracket
    expected[0] += 0.5 * trap.virtual_mass[0] * (v[0] @ normal[0]) ** 2 * tangent[0]
    np.testing.assert_allclose(thrust_force(trap, u, v, a), expected, rtol=1e-13, atol=1e-16)


@pytest.mark.parametrize("spine_force", ["source", "lagrangian"])
@pytest.mark.parametrize("which, step", [("displacement", 1e-6), ("velocity", 1e-3), ("acceleration", 1e-3)])
def test_trapezoid_jacobians_match_central_differences(geometry, state, which, step, spine_force):
    trap = trapezoid(geometry, spine_force)
    displacement, velocity, acceleration = state
    fields = {"displacement": displacement, "velocity": velocity, "acceleration": acceleration}
    jacobian = dict(zip(fields, thrust_jacobians(trap, *state)))[which]
    expected = central_difference_jacobian(lambda field: thrust_force(trap, **{**fields, which: field}),
                                           fields[which], step)
    assert relative_error(jacobian, expected) < JACOBIAN_TOLERANCE


def test_trapezoid_derivative_weights_give_the_virtual_mass_derivative(geometry, state):
    """∂f/∂ξ through m̃_r(ξ) and m̃_f(ξ) (linear here): segment_weighted_force with derivative_weights."""
    trap = trapezoid(geometry)
    rng = np.random.default_rng(5)
    rear_gradient, front_gradient = rng.standard_normal((2, N_NODES - 1, 2))
    weights = derivative_weights(trap, rear_gradient, front_mass_gradient=front_gradient)
    derivative = segment_weighted_force(trap, segment_state(trap, *state), *weights)

    def force_at(xi):
        moved = SpineGeometry(trap.rest_xy, trap.virtual_mass + rear_gradient @ xi, "source",
                              front_mass=trap.front_mass + front_gradient @ xi)
        return thrust_force(moved, *state)
    for k in range(2):
        step = np.eye(2)[k]
        np.testing.assert_allclose(derivative[k], force_at(step) - force_at(0 * step), rtol=1e-10, atol=1e-14)


def test_trapezoid_lagrangian_power_is_minus_the_rate_of_its_added_mass_energy(geometry):
    """T_a = Σ ¼ ℓ_0 [m̃_r (v_r·n)² + m̃_f (v_f·n)²]; with ∂T_a/∂x the spine force's power is -dT_a/dt."""
    trap = trapezoid(geometry, "lagrangian")
    motion = periodic_motion(np.random.default_rng(11), 1.0)

    def energy(t):
        u, v, _ = motion(t)
        _, normal = segment_frame(trap, u)
        rear, front = np.einsum("ij,ij->i", v[:-1], normal), np.einsum("ij,ij->i", v[1:], normal)
        return 0.25 * float(np.sum(trap.rest_length * (trap.virtual_mass * rear ** 2 + trap.front_mass * front ** 2)))

    def power(t):
        u, v, a = motion(t)
        force = thrust_force(trap, u, v, a)
        tangent, normal = segment_frame(trap, u)
        force[0] -= 0.5 * trap.virtual_mass[0] * (v[0] @ normal[0]) ** 2 * tangent[0]
        return float(np.sum(force * v))
    dt = 1e-6
    for t in (0.1, 0.37, 0.8):
        rate = (energy(t + dt) - energy(t - dt)) / (2 * dt)
        assert abs(power(t) + rate) < 1e-7 * abs(rate)


def test_the_trapezoid_spine_force_converges_at_second_order_the_rear_rule_at_first():
    """A smooth travelling wave on a straight spine of uniform m̃: the total spine force of N segments
    against Lighthill's line integral (the N = 1280 trapezoid value): the error falls ~4x per halving of
    the segment length with the trapezoid rule, ~2x with the rear rule."""
    def total_force(n_segments, rule):
        x = np.linspace(-FISH_LENGTH, 0.0, n_segments + 1)
        s = (x + FISH_LENGTH) / FISH_LENGTH                       # 0 at the tail, 1 at the head
        phase = 2.0 * np.pi * s - 1.3
        u = np.column_stack([np.zeros_like(x), 0.02 * (1 - s) ** 2 * np.sin(phase)])
        v = np.column_stack([np.zeros_like(x), 0.2 * (1 - s) ** 2 * np.cos(phase)])
        a = np.column_stack([np.zeros_like(x), -2.0 * (1 - s) ** 2 * np.sin(phase)])
        mass = np.full(n_segments, 2.0)
        spine = SpineGeometry(np.column_stack([x, np.zeros_like(x)]), mass,
                              front_mass=mass if rule == "trapezoid" else None)
        force = thrust_force(spine, u, v, a)
        tangent, normal = segment_frame(spine, u)
        force[0] -= 0.5 * mass[0] * (v[0] @ normal[0]) ** 2 * tangent[0]          # the spine force only
        return force.sum(axis=0)

    reference = total_force(1280, "trapezoid")
    for rule, ratio in (("trapezoid", 4.0), ("rear", 2.0)):
        errors = [np.linalg.norm(total_force(n, rule) - reference) for n in (20, 40, 80)]
        observed = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
        assert np.all(np.abs(observed - np.log2(ratio)) < 0.25), (rule, observed)
