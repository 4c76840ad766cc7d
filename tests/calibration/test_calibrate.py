"""`aquarom calibrate` on synthetic swims of the FOM (level 1, 0.4 s, sampled at 60 Hz: not the time
step's rate): the fitted values, the files it writes, the parameters it cannot tell apart, exit 3 when
the fit does not converge."""
import json
import tomllib

import numpy as np
import pytest

from aquarom_fenics.calibration.fit import sample_trajectory
from aquarom_fenics.calibration.parameters import with_values
from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.io.scene import Scene
from conftest import coarse_scene

DURATION = 0.4
TRUTH = {"material.young_modulus": 1.15 * 260e3, "fluid.thrust_factor": 0.85}


@pytest.fixture(scope="module")
def swim():
    """The FOM's head x, tail y and centre-of-mass x at the :data:`TRUTH` values, at 60 Hz (sampled as the fit
    samples the FOM), no noise."""
    run = simulate_fom(with_values(coarse_scene(solver={"duration": DURATION}), TRUTH), progress=False)
    times = np.arange(1, int(DURATION * 60) + 1) / 60.0
    names = ("head_x", "tail_y", "com_x")
    return times, dict(zip(names, sample_trajectory(run.trajectory, times, names).T))


def write_swim(path, swim, names):
    times, columns = swim
    lines = ["time_s," + ",".join(f"{name}_m" for name in names)]
    lines += [f"{t:.8f}," + ",".join(f"{columns[name][i]:.10e}" for name in names) for i, t in enumerate(times)]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def write_scene(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(f"[mesh]\nlevel = 1\n[solver]\nduration = {DURATION}\n")
    return str(path)


def calibrate(tmp_path, swim, names, fits, *extra):
    data = write_swim(tmp_path / "swim.csv", swim, names)
    arguments = [item for fit in fits for item in ("--fit", fit)]
    return main(["calibrate", write_scene(tmp_path), "--data", data, *arguments, "--out", str(tmp_path / "out"),
                 "--no-progress", *extra])


def test_a_noiseless_swim_gives_back_the_values_it_was_made_with(tmp_path, swim, capsys):
    assert calibrate(tmp_path, swim, ["head_x", "tail_y", "com_x"], list(TRUTH)) == 0
    out = tmp_path / "out"
    record = json.loads((out / "calibration.json").read_text())
    assert record["converged"] is True and record["columns"] == ["head_x_m", "tail_y_m", "com_x_m"]
    for key, truth in TRUTH.items():
        entry = record["parameters"][key]
        assert entry["value"] == pytest.approx(truth, rel=2e-4), key
        assert entry["ci95"][0] <= entry["value"] <= entry["ci95"][1]
        assert entry["std"] < 1e-3 * truth                 # no noise: the interval closes on the value
    assert record["fom"]["residual_rms"]["overall"] < 1e-6
    assert set(record["residual_rms_m"]) == {"head_x", "tail_y", "com_x", "overall"}
    assert 0 < max(record["fom"]["prom_distance"].values()) < 0.03
    correlation = np.array(record["correlation"]["matrix"])
    np.testing.assert_allclose(np.diag(correlation), 1.0, rtol=1e-12)
    assert record["not_identifiable"] == []
    calibrated = Scene.load(out / "calibrated.toml")
    assert calibrated.material.young_modulus == record["parameters"]["material.young_modulus"]["value"]
    assert calibrated.fluid.thrust_factor == record["parameters"]["fluid.thrust_factor"]["value"]
    assert (out / "fit.png").stat().st_size > 10_000 and (out / "manifest.json").is_file()
    printed = capsys.readouterr().out
    assert "PROM iteration 1" in printed and "FOM iteration 1" in printed and "95 % interval" in printed


def test_parameters_one_point_cannot_tell_apart_are_named(tmp_path, swim, capsys):
    """The centre of mass alone: E and the thrust factor move it alike (correlation above 0.95)."""
    code = calibrate(tmp_path, swim, ["com_x"], list(TRUTH))
    assert code in (0, 3)
    record = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert any("material.young_modulus and fluid.thrust_factor" in item for item in record["not_identifiable"])
    warning = [line for line in capsys.readouterr().out.splitlines() if "cannot tell apart" in line]
    assert len(warning) == 1 and "material.young_modulus and fluid.thrust_factor" in warning[0]


def test_a_fit_that_does_not_converge_exits_3_with_its_best_point(tmp_path, swim, capsys):
    assert calibrate(tmp_path, swim, ["head_x", "tail_y"], list(TRUTH), "--max-iterations", "1") == 3
    assert "did not converge" in capsys.readouterr().err
    record = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert record["converged"] is False
    start = tomllib.loads((tmp_path / "scene.toml").read_text())
    assert start["solver"]["duration"] == DURATION
    assert record["parameters"]["material.young_modulus"]["value"] != 260e3      # it moved towards the data


def test_a_dry_run_checks_the_data_and_writes_nothing(tmp_path, swim, capsys):
    assert calibrate(tmp_path, swim, ["tail_y"], ["fluid.drag_factor"], "--dry-run") == 0
    printed = capsys.readouterr().out
    assert "Levenberg–Marquardt" in printed and "FOM" in printed and "estimate" in printed
    assert not (tmp_path / "out").exists()
