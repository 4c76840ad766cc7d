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


def xdmf_arrays(h5_path: Path) -> dict:
    import h5py

    with h5py.File(h5_path) as data:
        steps = sorted(data["Function/displacement"], key=lambda name: float(name.replace("_", ".")))
        return {"geometry": data["Mesh/mesh/geometry"][:],
                "regions": data["MeshTags/regions/Values"][:] if "MeshTags/regions" in data else None,
                "first": data[f"Function/displacement/{steps[0]}"][:],
                "last": data[f"Function/displacement/{steps[-1]}"][:]}


@pytest.mark.parametrize("model", ["fom", "prom"])
def test_xdmf_shows_the_simulated_design_from_the_first_frame(tmp_path, model):
    """The mesh in displacement.h5 is the design x_0 + U ξ (z_tail = -0.3 widens the tail to
    z ∈ ±0.065 m), the displacement is zero at t = 0 and not later, and the regions are tagged."""
    scene = start_scene(tmp_path, extra="[output]\nxdmf = true")
    xi = "z_tail=-0.3" if model == "fom" else "z_tail=0.05"
    assert main(["simulate", str(scene), "--model", model, "--xi", xi, "--out", str(tmp_path / model),
                 "--no-progress"]) == 0
    from aquarom_fenics.io.run_outputs import read_displacement_series

    series = read_displacement_series(tmp_path / model / "displacement.npz")
    arrays = xdmf_arrays(tmp_path / model / "displacement.h5")
    assert np.abs(arrays["geometry"][:, 2]).max() == pytest.approx(np.abs(series.points[:, 2]).max(), rel=1e-12)
    if model == "fom":
        assert np.abs(arrays["geometry"][:, 2]).max() == pytest.approx(0.065, rel=1e-6)
    assert np.abs(arrays["first"]).max() == 0.0 and np.abs(arrays["last"]).max() > 1e-4
    assert set(np.unique(arrays["regions"])) == {0, 1, 2, 3}


def test_shapes_writes_the_design_mesh_with_its_region_tags(tmp_path):
    import h5py

    scene = start_scene(tmp_path)
    assert main(["shapes", str(scene), "--xi", "z_tail=-0.3", "--out", str(tmp_path / "shapes")]) == 0
    with h5py.File(tmp_path / "shapes" / "design.h5") as data:
        assert np.abs(data["Mesh/mesh/geometry"][:, 2]).max() == pytest.approx(0.065, rel=1e-6)
        assert set(np.unique(data["MeshTags/regions/Values"][:])) == {0, 1, 2, 3}


def test_the_validity_radius_refusal_names_the_build_command(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["simulate", str(scene), "--model", "prom", "--xi", "z_tail=-0.1", "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 2
    assert f"aquarom build {scene} --xi z_tail=-0.1 --out PROM.npz" in capsys.readouterr().err
