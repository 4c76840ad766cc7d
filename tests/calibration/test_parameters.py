"""The reduced model's derivatives with respect to the calibration parameters θ: a Taylor test against
the PROM itself per parameter (the remainder of the first-order expansion falls as h², order 2), and
finite differences of the FOM for E and the thrust factor."""
import numpy as np
import pytest

from aquarom_fenics.calibration.parameters import (CALIBRATION_KEYS, CalibratedSystem, check_keys, scene_value,
                                                   simulate_parameters, with_values)
from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene

FITTED = [key for key in CALIBRATION_KEYS if key != "actuation.amplitude"]
"""Every parameter but A (k·A enters once; A is tested on its own below)."""


@pytest.fixture(scope="module")
def scene():
    return coarse_scene(solver={"duration": 0.3})


@pytest.fixture(scope="module")
def prom(scene):
    return build_prom(scene, parametric=False, head_share=True)


@pytest.fixture(scope="module")
def point(scene):
    """θ 10 % above the scene's values, where the PROM was built: the derivatives away from θ_0."""
    return {key: 1.1 * scene_value(scene, key) for key in FITTED}


def test_at_the_building_values_the_system_is_the_reduced_model(scene, prom):
    swim = simulate_parameters(prom, scene, {key: scene_value(scene, key) for key in FITTED}, sensitivities=False)
    reference = simulate_reduced(prom, scene).trajectory.arrays()
    for column, name in enumerate(("head_x", "tail_y", "com_x")):
        np.testing.assert_allclose(swim.observed[:, column], reference[name], rtol=1e-12,
                                   atol=1e-12 * np.abs(reference[name]).max())


@pytest.mark.parametrize("key", FITTED)
def test_taylor_remainder_of_each_parameter_is_second_order(scene, prom, point, key):
    """‖y(θ + h e_k) - y(θ) - h dy/dθ_k‖ for h and h/2: ratio ≈ 4."""
    base = simulate_parameters(prom, scene, point)
    column = base.keys.index(key)
    remainders = []
    for relative in (0.1, 0.05):
        step = relative * point[key]
        moved = simulate_parameters(prom, scene, point | {key: point[key] + step}, sensitivities=False)
        linear = step * base.derivative[:, :, column]
        remainders.append(np.linalg.norm(moved.observed - base.observed - linear))
        assert remainders[-1] < 0.2 * np.linalg.norm(linear)
    assert 3.5 < remainders[0] / remainders[1] < 4.5, remainders


def test_amplitude_and_stiffness_enter_as_their_product(scene, prom, point):
    """dy/dA · A = dy/dk · k, and the swim at (k, A) equals the swim at (k·A/A_0, A_0)."""
    values = point | {"actuation.amplitude": 1.1 * scene.actuation.amplitude}
    values.pop("actuation.stiffness")
    by_amplitude = simulate_parameters(prom, scene, values)
    by_stiffness = simulate_parameters(prom, scene, point)
    k, a = point["actuation.stiffness"], values["actuation.amplitude"]
    np.testing.assert_allclose(by_amplitude.derivative[:, :, -1] * a,
                               by_stiffness.derivative[:, :, FITTED.index("actuation.stiffness")] * k,
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(by_amplitude.observed, by_stiffness.observed, rtol=1e-12, atol=1e-15)


def test_a_fit_of_both_k_and_a_or_an_unknown_key_is_refused():
    with pytest.raises(InputError, match=r"product k·A"):
        check_keys(["actuation.stiffness", "actuation.amplitude"])
    with pytest.raises(InputError, match="not a calibration parameter"):
        check_keys(["material.poisson_ratio"])
    with pytest.raises(InputError, match="twice"):
        check_keys(["fluid.drag_factor", "fluid.drag_factor"])


@pytest.mark.parametrize("key", ["material.young_modulus", "fluid.thrust_factor", "material.head_stiffness_factor"])
def test_the_derivative_matches_central_differences_of_the_fom(scene, prom, key):
    """dy/dθ of the PROM at θ_0 against (y_FOM(θ_0 + h) - y_FOM(θ_0 - h)) / 2h, h = 2 % of θ_0, over the
    swim (0.3 s, level 1), in the max norm of each point's FOM difference: head x and centre of mass within
    3 %, the tail's y within 12 % (without the head's vectors in the basis: 1.2–1.8 %, and 3.7 % for E, 9.6 %
    for c_T on the tail's y; with them, the fixture's, 0.2–0.7 % and at most 1.4 % on the tail's y; the head's
    factor 0.6 %, 1.1 %, 0.7 %)."""
    value = scene_value(scene, key)
    swim = simulate_parameters(prom, scene, {key: value})
    fish = load_fish(scene)
    step = 0.02 * value
    plus, minus = (simulate_fom(with_values(scene, {key: value + sign * step}), fish=fish, progress=False)
                   for sign in (1, -1))
    assert plus.completed and minus.completed
    for column, name in enumerate(("head_x", "tail_y", "com_x")):
        difference = (np.asarray(plus.trajectory.arrays()[name]) - np.asarray(minus.trajectory.arrays()[name])) / (2 * step)
        scale = np.abs(difference).max()
        assert scale > 0
        error = np.abs(swim.derivative[:, column, 0] - difference).max() / scale
        assert error < (0.12 if name == "tail_y" else 0.03), (name, error)


def test_the_head_share_is_what_a_projection_at_another_head_factor_adds(scene, prom):
    """On the same basis, the elastic tensors projected at h = 2 h_0 equal all + (2 - 1) head (the head's
    factor scales its cells' share only), and the system at h = 2 h_0 runs on them."""
    doubled = with_values(scene, {"material.head_stiffness_factor": 2 * scene.material.head_stiffness_factor})
    again = build_prom(doubled, parametric=False, basis_from=prom)
    head = prom.head_elastic
    assert np.abs(head.linear.constant).max() > 1e-3 * np.abs(prom.elastic.linear.constant).max()
    for name in ("linear", "quadratic", "cubic"):
        total = getattr(prom.elastic, name).constant + getattr(head, name).constant
        expected = getattr(again.elastic, name).constant
        np.testing.assert_allclose(total, expected, rtol=1e-10, atol=1e-10 * np.abs(expected).max())
    system = CalibratedSystem(prom, scene, {"material.head_stiffness_factor": 2 * scene.material.head_stiffness_factor},
                              TimeScheme.from_solver(scene.solver))
    np.testing.assert_allclose(system.rest_stiffness, again.elastic.linear.constant, rtol=1e-10,
                               atol=1e-10 * np.abs(again.elastic.linear.constant).max())


def test_a_reduced_model_without_the_head_share_refuses_the_head_factor(scene):
    plain = build_prom(scene, parametric=False)
    assert plain.head_elastic is None
    with pytest.raises(InputError, match="head_share"):
        CalibratedSystem(plain, scene, {"material.head_stiffness_factor": 50.0}, TimeScheme.from_solver(scene.solver))


def test_the_system_tangents_are_the_derivatives_of_its_residual(scene, prom, point):
    """K_t, C_t, M_t of the scaled system against central differences of its residual."""
    system = CalibratedSystem(prom, scene, point, TimeScheme.from_solver(scene.solver))
    rng = np.random.default_rng(5)
    m = prom.size
    eta, eta_dot, eta_ddot = (1e-3 * rng.standard_normal(m), 1e-2 * rng.standard_normal(m), rng.standard_normal(m))
    tangents = system.tangents(0.13, eta, eta_dot, eta_ddot)
    for slot, scale in enumerate((1e-3, 1e-2, 1.0)):
        direction = scale * rng.standard_normal(m)
        h = 1e-5                      # the residual is nearly linear in each slot: round-off, not truncation, limits h

        def residual(sign):
            state = [eta, eta_dot, eta_ddot]
            state[slot] = state[slot] + sign * h * direction
            return system.residual(0.13, *state)[0]

        expected = (residual(1) - residual(-1)) / (2 * h)
        np.testing.assert_allclose(tangents[slot] @ direction, expected, rtol=1e-5, atol=1e-7 * np.abs(expected).max())


def test_the_frequency_of_a_gait_whose_start_moves_with_it_is_refused():
    from aquarom_fenics.calibration.parameters import check_fit
    from aquarom_fenics.io.scene import Scene

    wave = Scene.load("fish_wave")            # phase-shifted muscles: an automatic start of a quarter period
    with pytest.raises(InputError, match="start_ramp"):
        check_fit(["actuation.frequency"], wave)
    check_fit(["actuation.frequency"], wave.replace("actuation", start_ramp=0.25))
    check_fit(["actuation.frequency"], coarse_scene())


def test_a_prom_with_the_head_share_saves_and_loads_it(prom, tmp_path):
    from aquarom_fenics.reduction.prom import ReducedModel

    prom.save(tmp_path / "head.npz")
    loaded = ReducedModel.load(tmp_path / "head.npz")
    assert loaded.labels == prom.labels and any(label.startswith("head_") for label in loaded.labels)
    for name in ("linear", "quadratic", "cubic"):
        np.testing.assert_array_equal(getattr(loaded.head_elastic, name).constant, getattr(prom.head_elastic, name).constant)
