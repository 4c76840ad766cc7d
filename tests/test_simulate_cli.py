"""The `aquarom simulate` command: outputs, MPI agreement, clean stops (SPEC §5–§6)."""
import json
import re
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.io.readback import read_trajectory_csv

SHORT_SCENE = """
[mesh]
level = 1
degree = {degree}
[solver]
duration = {duration}
{extra}
"""


def write_scene(directory: Path, duration=0.2, extra="", degree=1) -> Path:
    path = directory / "scene.toml"
    path.write_text(SHORT_SCENE.format(duration=duration, extra=extra, degree=degree))
    return path


def test_simulate_writes_trajectory_summary_and_plot(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", str(write_scene(tmp_path)), "--out", str(out), "--no-progress"]) == 0
    trajectory = read_trajectory_csv(out / "trajectory.csv")
    assert trajectory["time"].size == 11 and trajectory["time"][-1] == pytest.approx(0.2)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] and summary["cells"] == len(block_mesh(1).cells) and summary["steps"] == 10
    assert summary["distance"] == pytest.approx(trajectory["com_x"][-6:].mean())
    assert set(summary["versions"]) >= {"dolfinx", "petsc4py", "aquarom_fenics"}
    assert (out / "trajectory.png").stat().st_size > 10_000
    assert "distance" in capsys.readouterr().out


@pytest.mark.mpi
@pytest.mark.parametrize("degree", [1, 2])
def test_two_ranks_reproduce_the_serial_trajectory(tmp_path, degree):
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene = write_scene(tmp_path, degree=degree, extra="[output]\nxdmf = true")
    main(["simulate", str(scene), "--out", str(tmp_path / "serial"), "--no-progress"])
    aquarom = Path(sys.executable).with_name("aquarom")
    completed = subprocess.run(["mpirun", "-n", "2", str(aquarom), "simulate", str(scene), "--out",
                                str(tmp_path / "parallel"), "--no-progress"],
                               capture_output=True, text=True, timeout=600, env=os.environ)
    assert completed.returncode == 0, completed.stderr
    serial = read_trajectory_csv(tmp_path / "serial" / "trajectory.csv")
    parallel = read_trajectory_csv(tmp_path / "parallel" / "trajectory.csv")
    for name in ("head_x", "tail_y", "com_x"):
        error = np.linalg.norm(parallel[name] - serial[name]) / np.linalg.norm(serial[name])
        assert error < 1e-8, (name, error)
    assert json.loads((tmp_path / "parallel" / "summary.json").read_text())["mpi_ranks"] == 2
    assert (tmp_path / "parallel" / "displacement.xdmf").stat().st_size > 0


def test_diverging_actuation_stops_naming_the_step_and_keeps_the_trajectory(tmp_path, capsys):
    out = tmp_path / "run"
    scene = write_scene(tmp_path, duration=2.0, extra="[actuation]\nstiffness = 1e6")
    assert main(["simulate", str(scene), "--out", str(out), "--no-progress"]) == 3
    message = capsys.readouterr().err.strip()
    assert len(message.splitlines()) == 1
    # k·A near E: the muscles crush the body after the peak activation (t = 0.25 s), even in cut steps
    # (step 14 with the rear spine rule, 15 with the trapezoid rule)
    stop = re.search(r"at t = ([0-9.]+) s \(step (\d+) of 100\)", message)
    assert stop and "trajectory.csv" in message
    step = int(stop.group(2))
    assert float(stop.group(1)) == pytest.approx(0.02 * step) and 0.25 <= 0.02 * step <= 0.5
    trajectory = read_trajectory_csv(out / "trajectory.csv")
    np.testing.assert_allclose(trajectory["time"], 0.02 * np.arange(step))
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["completed"] and f"step {step}" in summary["error"] and summary["distance"] is None
    assert summary["cut_steps"] > 0         # earlier steps converged only when cut


@pytest.mark.parametrize("extra, named", [
    ("time_step = 0.0", "time_step"),
    ("time_step = -0.01", "time_step"),
    ("time_step = 0.03", "whole number"),
])
def test_bad_time_grid_is_refused(tmp_path, capsys, extra, named):
    scene = write_scene(tmp_path, duration=0.2, extra=extra)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "run"), "--no-progress"]) == 2
    message = capsys.readouterr().err.strip()
    assert len(message.splitlines()) == 1 and named in message
    assert not (tmp_path / "run").exists()


def test_horizon_shorter_than_the_distance_window_is_refused(tmp_path, capsys):
    scene = write_scene(tmp_path, duration=0.06)
    assert main(["simulate", str(scene), "--no-progress"]) == 2
    assert "0.1 s" in capsys.readouterr().err


def test_inverting_design_is_refused(tmp_path, capsys):
    scene = write_scene(tmp_path, extra="[shapes]\ny_thin = { bounds = [-0.15, 0.15] }")
    assert main(["simulate", str(scene), "--xi", "y_thin=1.5", "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 2
    assert "y_thin=1.5" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.mpi
def test_compare_and_check_under_two_ranks_end_and_agree_with_one(tmp_path):
    """Every rank takes part in the collective calls of `compare` (FOM, PROM, plot) and `check`
    (tensor and Taylor tests): both exit under mpirun, and compare's numbers are the serial ones."""
    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene = write_scene(tmp_path, extra='[shapes]\ny_thin = { bounds = [-0.15, 0.15] }')
    assert main(["compare", str(scene), "--out", str(tmp_path / "serial")]) == 0
    aquarom = Path(sys.executable).with_name("aquarom")
    for command in (["compare", str(scene), "--out", str(tmp_path / "parallel")], ["check", str(scene)]):
        completed = subprocess.run(["mpirun", "-n", "2", str(aquarom), *command],
                                   capture_output=True, text=True, timeout=600, env=os.environ)
        assert completed.returncode == 0, (command[0], completed.stderr[-2000:])
    serial, parallel = (json.loads((tmp_path / name / "compare.json").read_text()) for name in ("serial", "parallel"))
    for model in ("fom", "prom"):
        assert parallel[model]["distance"] == pytest.approx(serial[model]["distance"], rel=1e-7, abs=1e-12)
    assert "all checks passed" in completed.stdout
