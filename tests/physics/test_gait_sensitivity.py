"""The PROM's sensitivities to the gait's design variables ([gait]): the activations' derivatives against
central differences of the law, a Taylor test of the reduced states (the remainder of the first-order
expansion falls as h², ratio ≈ 4), and the distance's gradient against finite differences of the FOM."""
import numpy as np
import pytest

from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene_gait import apply_gait
from aquarom_fenics.physics.gait import GaitRates, ramp_time_derivative
from aquarom_fenics.physics.muscle import ActivationLaw, start_ramp
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene

PAIRS = [{"region": f"{side}_{k}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (k - 1)}
         for k in (1, 2, 3) for side in ("left", "right")]
GAIT = {"frequency": {"bounds": [0.5, 2.0]}, "phase_lag": {"bounds": [0.0, 180.0]},
        "amplitude_2": {"bounds": [0.1, 0.3]}}
POINT = {"frequency": 1.2, "phase_lag": 100.0, "amplitude_2": 0.25}
"""A gait away from the scene's (1 Hz, 120°, 0.2), where the PROM was built."""
STEPS = {"frequency": 0.05, "phase_lag": 2.5, "amplitude_2": 0.03}


def wave_scene(duration=0.3, **sections):
    from aquarom_fenics.io.scene import scene_from_dict

    data = {"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "solver": {"duration": duration},
            "muscles": PAIRS, "gait": GAIT} | sections
    return scene_from_dict(data, source="<test>")


@pytest.fixture(scope="module")
def scene():
    return wave_scene()


@pytest.fixture(scope="module")
def prom(scene):
    return build_prom(scene, parametric=False)


def test_ramp_derivative_is_the_difference_quotient():
    for time in (0.01, 0.1, 0.2, 0.249):
        h = 1e-7
        expected = (start_ramp(time, 0.25 + h) - start_ramp(time, 0.25 - h)) / (2 * h)
        assert ramp_time_derivative(time, 0.25) == pytest.approx(expected, rel=1e-6, abs=1e-9)
    assert ramp_time_derivative(0.3, 0.25) == 0.0 and ramp_time_derivative(0.1, 0.0) == 0.0


@pytest.mark.parametrize("name", sorted(POINT))
def test_activation_rates_are_the_laws_difference_quotients(scene, name):
    """∂a_j/∂g against central differences of a_j = A u_j of the scene driven at g ± h (the ramp's τ = 1/(4f) moving)."""
    driven = apply_gait(scene, POINT)
    rates = GaitRates(driven, ActivationLaw.of(driven), driven.actuation.amplitude)
    column = driven.gait_names.index(name)
    h = 1e-6 * max(1.0, abs(POINT[name]))
    for time in (0.05, 0.15, 0.26):
        plus, minus = (apply_gait(scene, POINT | {name: POINT[name] + sign * h}) for sign in (1, -1))
        expected = (plus.actuation.amplitude * ActivationLaw.of(plus).unit(time)
                    - minus.actuation.amplitude * ActivationLaw.of(minus).unit(time)) / (2 * h)
        np.testing.assert_allclose(rates.at(time)[:, column], expected, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("name", sorted(POINT))
def test_taylor_remainder_of_each_gait_variable_is_second_order(scene, prom, name):
    """‖η(g + h e_q) - η(g) - h dη/dg_q‖ over the run for h and h/2: ratio ≈ 4, and the distance's too."""
    base = simulate_reduced(prom, apply_gait(scene, POINT), gait_sensitivity=True)
    column = scene.gait_names.index(name)
    remainders, distance_remainders = [], []
    for step in (STEPS[name], STEPS[name] / 2):
        moved = simulate_reduced(prom, apply_gait(scene, POINT | {name: POINT[name] + step}))
        linear = step * base.sensitivities[:, :, column]
        remainders.append(np.linalg.norm(moved.states - base.states - linear))
        assert remainders[-1] < 0.2 * np.linalg.norm(linear)
        distance_remainders.append(abs(moved.distance - base.distance - step * base.distance_gradient[column]))
    assert 3.5 < remainders[0] / remainders[1] < 4.5, remainders
    assert 3.0 < distance_remainders[0] / distance_remainders[1] < 5.0, distance_remainders


def test_the_patterns_span_the_gait_at_every_lag_and_pair_amplitude(scene):
    """With phase_lag or a pair's amplitude a variable, the basis' patterns hold each pair's: a(t) at other
    lags and amplitudes stays in their span; with the frequency alone the scene's two patterns."""
    patterns = np.array(ActivationLaw.of(scene).patterns())
    assert patterns.shape[0] == 3
    for values in ({"phase_lag": 37.0}, {"phase_lag": 180.0, "amplitude_2": 0.11}):
        law = ActivationLaw.of(apply_gait(scene, values))
        for time in (0.1, 0.37, 0.8):
            activations = law.unit(time)
            coefficients = np.linalg.lstsq(patterns.T, activations, rcond=None)[0]
            np.testing.assert_allclose(patterns.T @ coefficients, activations, atol=1e-12)
    frequency_only = wave_scene(gait={"frequency": {"bounds": [0.5, 2.0]}})
    assert len(ActivationLaw.of(frequency_only).patterns()) == 2


@pytest.fixture(scope="module")
def second_scene():
    """The wave over 1 s (the 0.3 s swim is mostly the smooth start: its distance is 1e-5 m)."""
    return wave_scene(duration=1.0)


@pytest.fixture(scope="module")
def second_prom(second_scene):
    return build_prom(second_scene, parametric=False)


@pytest.mark.parametrize("name, step, tolerance", [("phase_lag", 5.0, 0.02), ("frequency", 0.02, 0.02),
                                                   ("amplitude_2", 0.01, 0.1)])
def test_the_distance_gradient_matches_central_differences_of_the_fom(second_scene, second_prom, name, step,
                                                                     tolerance):
    """dd/dg of the PROM built at the scene's gait, at that gait, against (d_FOM(g + h) - d_FOM(g - h)) / 2h
    (level 1, 1 s): measured 0.08 % (lag), 0.10 % (f) and 6.7 % (pair 2's amplitude; 33 % with the
    scene's two patterns alone, docs/devlog.md)."""
    scene, prom = second_scene, second_prom
    start = {variable.name: variable.start for variable in scene.gait}
    reduced = simulate_reduced(prom, apply_gait(scene, start), gait_sensitivity=True)
    fish = load_fish(scene)
    plus, minus = (simulate_fom(apply_gait(scene, {name: start[name] + sign * step}), fish=fish, progress=False)
                   for sign in (1, -1))
    assert plus.completed and minus.completed
    difference = (plus.distance - minus.distance) / (2 * step)
    gradient = reduced.distance_gradient[scene.gait_names.index(name)]
    assert abs(gradient - difference) < tolerance * abs(difference), (gradient, difference)


def test_the_mean_positive_power_is_the_fom_muscles_power_at_the_reduced_states(scene, prom):
    """P̄ of the reduced run against f_act(V η) · V η̇ of the FOM's muscle term at the same states and times."""
    from aquarom_fenics.fem.fom import FullOrderModel
    from aquarom_fenics.dynamics.muscle_power import mean_positive_power

    driven = apply_gait(scene, POINT)
    run = simulate_reduced(prom, driven)
    power = mean_positive_power(prom, driven, run)
    model = FullOrderModel(driven, load_fish(driven), prom.xi_center)
    vectors = np.column_stack([model.owned_values(prom.basis[:, :, j]) for j in range(prom.size)])
    time = np.asarray(run.trajectory.arrays()["time"])
    window = time >= driven.solver.duration - 1.0 / POINT["frequency"] - 1e-9
    expected = []
    for t, eta, eta_dot in zip(time[window], run.states[window], run.velocities[window]):
        model.set_displacement(vectors @ eta)
        model.muscle.set_time(t)
        expected.append(max(0.0, float(model.muscle.force() @ (vectors @ eta_dot))))
    assert power > 0 and power == pytest.approx(np.mean(expected), rel=1e-8)


def test_the_power_gradient_matches_central_differences_of_the_power():
    """dP̄/dz of the reduced run over [ξ, A, gait] against central differences of P̄ (level 1, 0.3 s)."""
    from aquarom_fenics.dynamics.muscle_power import mean_positive_power, mean_positive_power_gradient

    scene = wave_scene(shapes={"z_tail": {"bounds": [-0.2, 0.2]}}, solver={"duration": 0.3, "tolerance": 1e-11})
    prom = build_prom(scene)
    z = {"xi": np.array([0.03]), "amplitude": 0.22} | POINT

    def run(values, sensitivities=False):
        driven = apply_gait(scene, {name: values[name] for name in POINT})
        result = simulate_reduced(prom, driven, values["xi"], sensitivities=sensitivities, amplitude=values["amplitude"],
                                  amplitude_sensitivity=sensitivities, gait_sensitivity=sensitivities)
        return driven, result

    driven, result = run(z, sensitivities=True)
    power, gradient = mean_positive_power_gradient(prom, driven, result, z["xi"], z["amplitude"], (True, True, True))
    assert power == pytest.approx(mean_positive_power(prom, driven, result, z["xi"], z["amplitude"]), rel=1e-12)
    steps = [("xi", 1e-5), ("amplitude", 1e-6)] + [(name, 1e-6 * max(1.0, POINT[name])) for name in POINT]
    for column, (name, step) in enumerate(steps):
        values = []
        for sign in (1, -1):
            moved = dict(z)
            moved[name] = z[name] + sign * step
            at, moved_run = run(moved)
            values.append(mean_positive_power(prom, at, moved_run, moved["xi"], moved["amplitude"]))
        central = (values[0] - values[1]) / (2 * step)
        assert gradient[column] == pytest.approx(central, rel=1e-4, abs=1e-6 * power), (name, gradient[column], central)
