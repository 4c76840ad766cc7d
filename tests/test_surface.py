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
    assert header == "time_s,head_x_m,tail_y_m,com_x_m,tail_x_m,com_y_m,newton_iterations"


def test_the_fom_check_names_the_start_design_not_the_nominal_one():
    import dataclasses

    from aquarom_fenics.studies.study import FomCheck

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
    assert f"aquarom build {scene} --level 1 --degree 1 --xi z_tail=-0.1 --out PROM.npz" in capsys.readouterr().err


def test_verbose_is_accepted_after_the_subcommand(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["mesh", str(scene), "-v"]) == 0
    assert main(["-v", "mesh", str(scene)]) == 0
    assert "cells" in capsys.readouterr().out


def test_weight_is_refused_on_a_scene_without_cooptimisation(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["optimize", str(scene), "--weight", "0.3", "--dry-run"]) == 2
    assert "--weight 0.3" in capsys.readouterr().err


def test_an_xi_outside_the_bounds_is_a_warning(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["shapes", str(scene), "--xi", "z_tail=0.5", "--dry-run"]) == 0
    assert "warning: --xi z_tail=0.5 is outside" in capsys.readouterr().err


def test_set_overrides_a_scene_value_validated_like_the_file(tmp_path, capsys):
    scene = start_scene(tmp_path)
    assert main(["simulate", str(scene), "--set", "solver.duration=0.1", "--set", "shapes.z_tail.start=0.05",
                 "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["scene_values"]["solver"]["duration"] == 0.1 and summary["xi"] == {"z_tail": 0.05}
    capsys.readouterr()
    for setting, named in (("solver.duration=-1", "duration"), ("solver.durration=1", "durration"),
                           ("shapes.z_tail.start=0.5", "outside its bounds"), ("solver", "section.key=value")):
        assert main(["simulate", str(scene), "--set", setting, "--dry-run"]) == 2, setting
        error = capsys.readouterr().err
        assert f"--set {setting}" in error and named in error and "Traceback" not in error


def test_aquarom_cache_moves_the_mesh_cache_and_cache_list_shows_the_folders(tmp_path, monkeypatch, capsys):
    from aquarom_fenics.io.paths import mesh_cache

    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    assert mesh_cache() == tmp_path / "cache" / "meshes"
    assert main(["cache", "list"]) == 0
    out = capsys.readouterr().out
    for folder in ("prom", "fom", "meshes"):
        assert str(tmp_path / "cache" / folder) in out


def test_api_optimize_handles_its_folder_like_the_cli_and_names_the_optimum(tmp_path, monkeypatch):
    from aquarom_fenics import api
    from aquarom_fenics.errors import InputError

    scene = api.Scene.load(start_scene(tmp_path)).replace("optimizer", method="trust-region", max_iterations=1)
    out = tmp_path / "opt"
    result, check = api.optimize(scene, out)
    summary = json.loads((out / "summary.json").read_text())
    manifest = json.loads((out / "manifest.json").read_text())
    assert result.optimum_dict == summary["optimum"] and set(result.optimum_dict) == {"z_tail"}
    assert result.prom_builds == summary["prom_builds"]
    assert summary["fom_check"]["start_distance"] == check.start_distance
    assert manifest["scene"]["hash"] == scene.hash and "summary.json" in manifest["files"]
    with pytest.raises(InputError, match="exists"):
        api.optimize(scene, out)

    def quick(scene, folder, **options):       # the folder handling of a forced run, without the optimiser
        (folder / "summary.json").write_text("{}")
        return result, check

    monkeypatch.setattr(api, "run_optimization", quick)
    api.optimize(scene, out, force=True)
    assert json.loads((out / "summary.json").read_text()) == {}
    assert json.loads((out / "manifest.json").read_text())["files"] == ["summary.json"]


def test_set_log_level_shows_each_warning_once_and_details_on_request(capsys):
    import logging

    from aquarom_fenics import set_log_level

    log = logging.getLogger("aquarom")
    try:
        set_log_level("warning")
        for _ in range(3):
            log.warning("basis: the same warning")
        log.info("a detail")
        err = capsys.readouterr().err
        assert err.count("basis: the same warning") == 1 and "a detail" not in err
        set_log_level("info")
        log.info("a detail")
        assert "a detail" in capsys.readouterr().err
        with pytest.raises(ValueError):
            set_log_level("loud")
    finally:
        set_log_level("warning")
