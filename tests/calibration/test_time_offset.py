"""--fit time_offset: the model sampled at t + τ, its derivative the model's velocity (a Taylor test against
the PROM), a fit that finds a shift put into a FOM swim, and the refusals of its bounds."""
import json
import tomllib

import numpy as np
import pytest

from aquarom_fenics.calibration.fit import model_at, sample_trajectory
from aquarom_fenics.calibration.parameters import TIME_OFFSET, with_values
from aquarom_fenics.dynamics.trajectory import OBSERVED
from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.io.swim_data import SwimData
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene, one_line, write_short_scene

DURATION = 0.4
E0 = 260e3


@pytest.fixture(scope="module")
def scene():
    return coarse_scene(solver={"duration": DURATION})


@pytest.fixture(scope="module")
def prom(scene):
    return build_prom(scene, parametric=False)


def test_the_offset_s_derivative_is_the_model_s_velocity_taylor(scene, prom):
    """‖y(τ + h) - y(τ) - h dy/dτ‖ for h = 8, 4, 2 ms (a few time steps): ratios near 4 (second order)."""
    times = np.linspace(0.05, 0.35, 61)
    data = SwimData(times, np.zeros((times.size, 3)), ("head_x", "tail_y", "com_x"), "<test>")
    columns = [OBSERVED.index(name) for name in data.observables]
    keys = ["material.young_modulus", TIME_OFFSET]
    theta = np.array([E0, 0.013])
    base, jacobian = model_at(prom, scene, data, columns, keys, theta)
    remainders = []
    for step in (8e-3, 4e-3, 2e-3):
        moved, _ = model_at(prom, scene, data, columns, keys, theta + np.array([0.0, step]))
        linear = step * jacobian[:, 1].reshape(base.shape)
        remainders.append(np.linalg.norm(moved - base - linear))
        assert remainders[-1] < 0.2 * np.linalg.norm(linear)
    ratios = np.array(remainders[:-1]) / np.array(remainders[1:])
    assert np.all((3.0 < ratios) & (ratios < 5.0)), ratios
    remainders = []                          # E's column, sampled between the grid's times alike
    for relative in (0.1, 0.05):
        moved, _ = model_at(prom, scene, data, columns, keys, theta + np.array([relative * E0, 0.0]))
        remainders.append(np.linalg.norm(moved - base - relative * E0 * jacobian[:, 0].reshape(base.shape)))
    assert 3.3 < remainders[0] / remainders[1] < 4.5, remainders


def test_before_the_start_the_model_is_at_rest(scene, prom):
    times = np.array([0.01, 0.02, 0.03])
    data = SwimData(times, np.zeros((3, 1)), ("tail_y",), "<test>")
    model, jacobian = model_at(prom, scene, data, [OBSERVED.index("tail_y")], [TIME_OFFSET], np.array([-0.05]))
    np.testing.assert_array_equal(model, 0.0)
    np.testing.assert_array_equal(jacobian, 0.0)


def test_a_fit_finds_the_shift_put_into_a_fom_swim(tmp_path, capsys):
    """Data y(t) = y_FOM(t + τ) at 50 Hz with τ = 12 ms and E 10 % above the scene's: both found."""
    truth_offset, truth_modulus = 0.012, 1.1 * E0
    run = simulate_fom(with_values(coarse_scene(solver={"duration": DURATION}),
                                   {"material.young_modulus": truth_modulus}), progress=False)
    times = np.arange(1, 19) / 50.0                           # up to 0.36 s: room for the shift within 0.4 s
    names = ("head_x", "tail_y", "com_x")
    shifted = sample_trajectory(run.trajectory, times + truth_offset, names)   # as the fit samples the FOM
    lines = ["time_s," + ",".join(f"{name}_m" for name in names)]
    lines += [f"{t:.6f}," + ",".join(f"{value:.12e}" for value in row) for t, row in zip(times, shifted)]
    (tmp_path / "swim.csv").write_text("\n".join(lines) + "\n")
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(f"[mesh]\nlevel = 1\n[solver]\nduration = {DURATION}\n")
    code = main(["calibrate", str(scene_file), "--data", str(tmp_path / "swim.csv"), "--fit", "material.young_modulus",
                 "--fit", "time_offset", "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    record = json.loads((tmp_path / "out" / "calibration.json").read_text())
    offset = record["parameters"]["time_offset"]
    assert offset["value"] == pytest.approx(truth_offset, abs=2e-4)
    assert record["parameters"]["material.young_modulus"]["value"] == pytest.approx(truth_modulus, rel=2e-3)
    assert "time_offset" not in (tmp_path / "out" / "calibrated.toml").read_text()


@pytest.mark.parametrize("fit, expected", [
    ("time_offset=0.01:0.02", ["LO ≤ 0 ≤ HI"]),
    ("time_offset=0.02", ["LO:HI in seconds"]),
    ("time_offset=0:0.05", ["no shift left", "duration"]),
])
def test_offset_bounds_are_checked_in_one_line(fit, expected, tmp_path, capsys):
    data = tmp_path / "swim.csv"
    data.write_text("time_s,tail_y_m\n0.1,0.001\n0.15,0.002\n0.2,0.003\n")
    scene = write_short_scene(tmp_path, duration=0.2)
    assert main(["calibrate", scene, "--data", str(data), "--fit", fit, "--out", str(tmp_path / "out")]) == 2
    line = one_line(capsys)
    for part in expected:
        assert part in line, line


def test_the_fit_s_iterations_have_a_progress_bar_unless_asked_not_to(capsys):
    from aquarom_fenics.cli.calibrate import IterationReport

    data = SwimData(np.array([0.1, 0.2]), np.zeros((2, 1)), ("tail_y",), "<test>")
    report = IterationReport(["material.young_modulus", TIME_OFFSET], data, "PROM", 30, shown=True)
    assert report.bar is not None and report.bar.total == 30      # drawn on a terminal only (tqdm disable=None)
    report(1, 1e-8, np.array([2.6e5, 0.01]))            # ½‖r‖² over 2 values: RMS 0.1 mm
    report.close()
    assert "PROM iteration 1: residual RMS 0.1000 mm; young_modulus 260000, time_offset 0.01" in capsys.readouterr().out
    assert IterationReport(["fluid.drag_factor"], data, "FOM", 6, shown=False).bar is None


def test_a_fit_of_the_head_factor_finds_it_in_a_noiseless_fom_swim(tmp_path, capsys):
    """E 10 % above and the head factor at 60 % of the scene's (level 1, 0.4 s, 50 Hz, no noise): the reduced
    model with the head's vectors drives the fit, the FOM's iterations end it at the truth."""
    truth = {"material.young_modulus": 1.1 * E0, "material.head_stiffness_factor": 60.0}
    run = simulate_fom(with_values(coarse_scene(solver={"duration": DURATION}), truth), progress=False)
    arrays = run.trajectory.arrays()
    times = np.arange(1, 21) / 50.0
    names = ("head_x", "tail_y", "com_x")
    lines = ["time_s," + ",".join(f"{name}_m" for name in names)]
    lines += [f"{t:.6f}," + ",".join(f"{np.interp(t, arrays['time'], arrays[name]):.12e}" for name in names)
              for t in times]
    (tmp_path / "swim.csv").write_text("\n".join(lines) + "\n")
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(f"[mesh]\nlevel = 1\n[solver]\nduration = {DURATION}\n")
    code = main(["calibrate", str(scene_file), "--data", str(tmp_path / "swim.csv"), "--fit", "material.young_modulus",
                 "--fit", "material.head_stiffness_factor", "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    record = json.loads((tmp_path / "out" / "calibration.json").read_text())
    for key, value in truth.items():
        assert record["parameters"][key]["value"] == pytest.approx(value, rel=5e-3), key
    calibrated = tomllib.loads((tmp_path / "out" / "calibrated.toml").read_text())
    assert calibrated["material"]["head_stiffness_factor"] == record["parameters"]["material.head_stiffness_factor"]["value"]
