"""Force terms (SPEC §5, §8): each law written in one module; the reduced terms' Jacobians and
ξ-derivatives against central differences of their own forces."""
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

import aquarom_fenics
import aquarom_fenics.forms
from aquarom_fenics.physics.drag import DragTensors, drag_force, drag_velocity_jacobian
from aquarom_fenics.physics.elastic import ElasticTensors
from aquarom_fenics.physics.inertia import InertiaTensors, rayleigh_damping
from aquarom_fenics.physics.muscle import ActivationLaw, MuscleTensors, activations, unit_activations
from aquarom_fenics.physics.thrust_reduced import ThrustTensors
from aquarom_fenics.physics.taylor import Taylor

PACKAGE_ROOTS = [Path(aquarom_fenics.__file__).parent, Path(aquarom_fenics.forms.__file__).parent]

LAWS = {
    # f_drag = g v_x² and its Jacobian 2 g v_x: a square or a doubling of the head's x-velocity
    "drag law": (r"(head|velocity_x)[^\n]*\*\*\s*2", "physics/drag.py"),
    "drag Jacobian": (r"2(\.0)?\s*\*\s*\(?\s*(self\.)?(head|velocity_x)", "physics/drag.py"),
    # (a_left, a_right) = A sin(2π f t) (1, -1)
    "activation law": (r"sin\(\s*2(\.0)?\s*\*\s*np\.pi", "physics/muscle.py"),
    # C = α_R M + β_R K_0 needs the scene's α_R, β_R (read as attributes; a key's name in quotes is no law)
    "Rayleigh damping": (r"\.rayleigh_(alpha|beta)\b(?![\"'])", "physics/inertia.py"),
}


def modules_matching(pattern: str, roots=PACKAGE_ROOTS) -> set[str]:
    """Package modules (paths relative to the package, forms/ included) whose source matches."""
    found = set()
    for root in roots:
        for path in root.rglob("*.py"):
            if re.search(pattern, path.read_text()):
                relative = path.relative_to(root)
                found.add(str(relative) if root == PACKAGE_ROOTS[0] else f"forms/{relative}")
    return found


@pytest.mark.parametrize("law", sorted(LAWS))
def test_each_law_is_written_in_exactly_one_module(law):
    pattern, module = LAWS[law]
    assert modules_matching(pattern) == {module}


def test_no_module_but_the_muscle_term_writes_the_activations():
    assert modules_matching(r"activations?\b[^\n]*\.value\s*=") == set()


def test_activation_law_and_its_amplitude_derivative():
    time, frequency = 0.3, 1.7
    value = np.sin(2 * np.pi * frequency * time)
    np.testing.assert_array_equal(activations(0.2, frequency, time), 0.2 * np.array([value, -value]))
    step = 1e-6
    central = (activations(0.2 + step, frequency, time) - activations(0.2 - step, frequency, time)) / (2 * step)
    np.testing.assert_allclose(unit_activations(frequency, time), central, rtol=1e-8)


def test_the_smooth_start_leaves_the_activation_at_rest_to_second_order_and_ends_at_the_ramp_time():
    """a(t) = A sin²(π t / 2τ) sin(2π f t) ~ t³ near t = 0: a, ȧ and ä vanish (a jump of ȧ rings the
    stiff modes); for t ≥ τ it is SPEC's law, and τ = 0 is SPEC's law everywhere."""
    frequency, ramp, step = 1.0, 0.5, 1e-4
    left = [activations(0.2, frequency, t, ramp)[0] for t in (0.0, step, 2 * step)]
    assert left[0] == 0.0
    assert abs(left[1]) < 1e-9 and abs(left[2] / left[1] - 8.0) < 1e-2      # cubic: doubling t multiplies by 8
    for time in (0.5, 0.73, 1.6):
        np.testing.assert_array_equal(activations(0.2, frequency, time, ramp), activations(0.2, frequency, time))
    np.testing.assert_array_equal(activations(0.2, frequency, 0.3, 0.0), activations(0.2, frequency, 0.3))
    assert 0.0 < activations(0.2, frequency, 0.2, ramp)[0] < activations(0.2, frequency, 0.2)[0]


def test_drag_jacobian_is_the_derivative_of_the_drag_law_in_the_head_velocity():
    direction, velocity, step = np.array([-0.3, 0.0, -1.2]), 0.07, 1e-7
    central = (drag_force(direction, velocity + step) - drag_force(direction, velocity - step)) / (2 * step)
    np.testing.assert_allclose(drag_velocity_jacobian(direction, velocity), central, rtol=1e-8)


def test_rayleigh_damping_combines_numpy_arrays():
    mass, stiffness = np.diag([1.0, 2.0]), np.array([[3.0, -1.0], [-1.0, 3.0]])
    np.testing.assert_array_equal(rayleigh_damping(0.5, mass, 2.0, stiffness), 0.5 * mass + 2.0 * stiffness)


# ---------------------------------------------------------------- reduced terms, central differences
M, P, STEP = 4, 2, 1e-6


def random_taylor(rng, shape, symmetric_axes=0):
    """Order-2 Taylor of random tensors, symmetric in their last ``symmetric_axes`` indices."""
    def tensor(*leading):
        values = rng.standard_normal(leading + shape)
        if symmetric_axes > 1:
            axes = list(range(values.ndim))
            tail = axes[-symmetric_axes:]
            values = sum(values.transpose(axes[:-symmetric_axes] + list(order))
                         for order in itertools.permutations(tail))
        return values
    second = tensor(P, P)
    return Taylor(tensor(), tensor(P), 0.5 * (second + second.swapaxes(0, 1)))


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def state(rng):
    return [0.1 * rng.standard_normal(M) for _ in range(3)]


def central_jacobian(function, x):
    """(n_out, n_in) central difference of a vector function."""
    columns = [(function(x + STEP * e) - function(x - STEP * e)) / (2 * STEP) for e in np.eye(x.size)]
    return np.column_stack(columns)


def central_parameter_derivative(residual_at):
    """(p, m) central difference of residual_at(Δξ) at Δξ = 0.2."""
    delta = np.full(P, 0.2)
    return np.stack([(residual_at(delta + STEP * e) - residual_at(delta - STEP * e)) / (2 * STEP)
                     for e in np.eye(P)])


def assert_close(actual, expected):
    assert np.linalg.norm(actual - expected) <= 1e-7 * np.linalg.norm(expected)


def test_reduced_elastic_tangent_and_xi_derivative(rng):
    tensors = ElasticTensors(random_taylor(rng, (M, M), 2), random_taylor(rng, (M, M, M), 2),
                             random_taylor(rng, (M, M, M, M), 3))
    eta = state(rng)[0]
    term = tensors.at(np.full(P, 0.2))
    assert_close(term.tangents(0.0, eta, eta, eta)[0], central_jacobian(term.force, eta))
    assert_close(term.parameter_derivative(0.0, eta, eta, eta),
                 central_parameter_derivative(lambda d: tensors.at(d).force(eta)))


@pytest.mark.parametrize("law", [ActivationLaw.antagonist(1.0),
                                 ActivationLaw((1.0, -0.5, 2.0), (0.0, 2.1, -1.0), (1.0, 1.0, 1.7), 0.2)])
def test_reduced_muscle_tangent_amplitude_and_xi_derivatives(rng, law):
    """The pair and three muscles of other scales, phases and frequencies (a ramp on)."""
    n = law.size
    tensors = MuscleTensors(random_taylor(rng, (n, M)), random_taylor(rng, (n, M, M)))
    eta, time = state(rng)[0], 0.13
    term = tensors.at(np.full(P, 0.2), 0.3, law)
    assert_close(term.tangents(time, eta, eta, eta)[0], central_jacobian(lambda x: -term.force(time, x), eta))
    assert_close(term.parameter_derivative(time, eta, eta, eta),
                 central_parameter_derivative(lambda d: -tensors.at(d, 0.3, law).force(time, eta)))
    by_amplitude = [-tensors.at(np.full(P, 0.2), 0.3 + s, law).force(time, eta) for s in (STEP, -STEP)]
    assert_close(term.amplitude_derivative(time, eta), (by_amplitude[0] - by_amplitude[1]) / (2 * STEP))


def test_the_activation_law_of_each_muscle_and_its_independent_patterns():
    """a_j = A s_j r(t) sin(2π f_j t + φ_j); the pair's law is the antagonist one bit for bit and has one
    pattern (1, -1); a travelling wave at one frequency has two (its sin and cos parts), which span a(t)."""
    time, frequency = 0.37, 1.3
    pair = ActivationLaw.antagonist(frequency)
    np.testing.assert_array_equal(pair.unit(time), unit_activations(frequency, time))
    assert len(pair.patterns()) == 1 and np.array_equal(pair.patterns()[0], [1.0, -1.0])
    by_phase = ActivationLaw((1.0, 1.0), (0.0, np.pi), (frequency, frequency))
    np.testing.assert_allclose(by_phase.unit(time), pair.unit(time), rtol=0, atol=1e-15)
    lags = np.arange(3) * 2 * np.pi / 3
    wave = ActivationLaw((1.0,) * 3 + (-1.0,) * 3, tuple(lags) * 2, (frequency,) * 6, 0.4)
    expected = [0.5 * 2.0 * np.sin(2 * np.pi * frequency * time + lag) * side for side in (1, -1) for lag in lags]
    ramp = np.sin(0.5 * np.pi * time / 0.4) ** 2
    np.testing.assert_allclose(wave.unit(time), ramp * np.array(expected), rtol=1e-14)
    patterns = wave.patterns()
    assert len(patterns) == 2
    coefficients, residual, *_ = np.linalg.lstsq(np.column_stack(patterns), wave.unit(time), rcond=None)
    assert residual.size == 0 or residual[0] < 1e-28
    np.testing.assert_allclose(np.column_stack(patterns) @ coefficients, wave.unit(time), atol=1e-14)
    two_frequencies = ActivationLaw((1.0, 1.0), (0.0, 0.5), (1.0, 2.0))
    assert len(two_frequencies.patterns()) == 2          # one muscle per frequency: sin and cos of each span 2


def test_reduced_inertia_xi_derivative_includes_the_rayleigh_damping(rng):
    stiffness = random_taylor(rng, (M, M), 2)
    tensors = InertiaTensors(random_taylor(rng, (M, M), 2), 3.1, 0.05, random_taylor(rng, (M,)),
                             Taylor(np.array(2.0), np.array([0.1, -0.2]), np.diag([0.05, 0.02])), random_taylor(rng, (M,)))
    _, eta_dot, eta_ddot = state(rng)

    def term_at(delta):
        return tensors.at(delta, stiffness, stiffness.at(delta))

    def residual_at(delta):
        term = term_at(delta)
        return term.mass @ eta_ddot + term.damping @ eta_dot

    term = term_at(np.full(P, 0.2))
    np.testing.assert_allclose(term.damping, 3.1 * term.mass + 0.05 * stiffness.at(np.full(P, 0.2)))
    assert_close(term.parameter_derivative(0.0, None, eta_dot, eta_ddot), central_parameter_derivative(residual_at))
    assert_close(term.com_weights_gradient(), central_parameter_derivative(lambda d: term_at(d).com_weights))


def test_reduced_drag_damping_and_xi_derivative(rng):
    tensors = DragTensors(random_taylor(rng, (M,)), rng.standard_normal(M))
    eta, eta_dot, eta_ddot = state(rng)
    term = tensors.at(np.full(P, 0.2))
    assert_close(term.tangents(0.0, eta, eta_dot, eta_ddot)[1], central_jacobian(lambda v: -term.force(v), eta_dot))
    assert_close(term.parameter_derivative(0.0, eta, eta_dot, eta_ddot),
                 central_parameter_derivative(lambda d: -tensors.at(d).force(eta_dot)))


@pytest.mark.parametrize("spine_force", ["source", "lagrangian"])
@pytest.mark.parametrize("rest_moves", [False, True])
@pytest.mark.parametrize("spine_rule", ["rear", "trapezoid"])
def test_reduced_thrust_tangents_and_xi_derivative(rng, spine_force, rest_moves, spine_rule):
    """The ξ-derivative through the virtual mass and, when the shape moves the rest stations
    (x̄_rest = B(X + U ξ), e.g. xz_concave_tail), through their positions and rest lengths; for the
    trapezoid rule through the front stations' virtual masses as well."""
    n_spine = 5
    rest_gradient = 0.005 * rng.standard_normal((n_spine, 2, P)) if rest_moves else np.zeros((n_spine, 2, P))
    front = {} if spine_rule == "rear" else {"front_dorsal_z": rng.uniform(0.02, 0.04, n_spine - 1),
                                             "front_dorsal_z_gradient": 0.01 * rng.standard_normal((n_spine - 1, P))}
    data = ThrustTensors(rows=0.1 * rng.standard_normal((n_spine, 2, M)),
                      rest_xy=np.column_stack([np.linspace(-0.2, 0.0, n_spine), np.zeros(n_spine)]),
                      rest_xy_gradient=rest_gradient,
                      dorsal_z=rng.uniform(0.02, 0.04, n_spine - 1),
                      dorsal_z_gradient=0.01 * rng.standard_normal((n_spine - 1, P)), fluid_density=1000.0, **front)
    eta, eta_dot, eta_ddot = (10 * x for x in state(rng))
    term = data.at(np.full(P, 0.2), spine_force)
    stiffness, damping, mass = term.tangents(0.0, eta, eta_dot, eta_ddot)
    assert_close(stiffness, central_jacobian(lambda x: -term.force(x, eta_dot, eta_ddot), eta))
    assert_close(damping, central_jacobian(lambda x: -term.force(eta, x, eta_ddot), eta_dot))
    assert_close(mass, central_jacobian(lambda x: -term.force(eta, eta_dot, x), eta_ddot))
    assert_close(term.parameter_derivative(0.0, eta, eta_dot, eta_ddot),
                 central_parameter_derivative(lambda d: -data.at(d, spine_force).force(eta, eta_dot, eta_ddot)))
