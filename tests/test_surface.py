"""What a user sees at the surface is what ran: the design of every model of a command, the
geometry of the XDMF output, the names and units of the output files (issue 26)."""
import json
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.cli import main

START_SCENE = """
[mesh]
level = 1
[solver]
duration = 0.2
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], start = 0.1 }}
{extra}
"""


def start_scene(directory: Path, extra: str = "") -> Path:
    path = directory / "start.toml"
    path.write_text(START_SCENE.format(extra=extra))
    return path


def test_compare_without_xi_runs_the_start_design_on_both_sides(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["compare", str(scene), "--out", str(tmp_path / "compare"), "--no-progress"]) == 0
    compare = json.loads((tmp_path / "compare" / "compare.json").read_text())
    assert compare["design"] == {"z_tail": 0.1}
    fom, prom = (json.loads((tmp_path / "compare" / model / "summary.json").read_text()) for model in ("fom", "prom"))
    assert fom["xi"] == prom["xi"] == {"z_tail": 0.1}
    assert "z_tail = 0.1" in capsys.readouterr().out


def test_simulate_fom_without_xi_runs_the_start_design(tmp_path):
    scene = start_scene(tmp_path)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "fom"), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "fom" / "summary.json").read_text())
    assert summary["xi"] == {"z_tail": 0.1}
    assert summary["units"]["distance"] == "m" and summary["units"]["wall_time"] == "s"
    header = (tmp_path / "fom" / "trajectory.csv").read_text().splitlines()[0]
    assert header == "time_s,head_x_m,tail_y_m,com_x_m,newton_iterations"


def test_the_fom_check_names_the_start_design_not_the_nominal_one():
    import dataclasses

    from aquarom_fenics.optimization.study import FomCheck

    names = {field.name for field in dataclasses.fields(FomCheck)}
    assert {"start_distance", "prom_start_distance"} <= names
    assert not any("nominal" in name for name in names)
    check = FomCheck(start_distance=0.02, optimal_distance=0.03, prom_start_distance=0.021,
                     prom_optimal_distance=0.031, time=1.0)
    assert check.ratio == pytest.approx(1.5)
