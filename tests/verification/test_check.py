"""`aquarom check`: the built-in Taylor tests pass on a shipped scene and catch wrong PROMs (SPEC §8–§10)."""
import json
from itertools import islice

import numpy as np
import pytest

from aquarom_fenics.verification.check import run_checks
from aquarom_fenics.cli import main
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.io.scene import Scene
from conftest import coarse_scene

ONE_SHAPE_SCENE = '[mesh]\nlevel = 1\n[shapes]\nz_tail = { bounds = [-0.5, 0.5] }\n'


def table_rows(output):
    """The rows of the printed table: they start with the check number."""
    return [line for line in output.splitlines() if line[:2] in ("1 ", "2 ", "3 ", "4 ", "5 ")]


@pytest.mark.parametrize("scene", ["so1", "so2", "so3", "so7", "so8", "so9", "co"])
def test_shipped_scenes_pass_every_check(scene, capsys):
    assert main(["check", scene, "--level", "1"]) == 0
    rows = table_rows(capsys.readouterr().out)
    assert {row[0] for row in rows} == set("12345")
    assert all("PASS" in row and "FAIL" not in row for row in rows), rows
    taylor = next(row for row in rows if row.startswith("3 "))
    assert "ratios" in taylor and "ratio 4 ± 25 %" in taylor


@pytest.mark.parametrize("scene", ["so1", "so3"])
def test_the_trapezoid_spine_rule_passes_every_check(scene, capsys):
    """The trapezoid rule's front-station virtual masses and, for SO3's xz_concave_tail, the moving rest
    stations: tensors, ξ-derivatives, Taylor order, sensitivities and cost gradient against the FOM."""
    assert main(["check", scene, "--level", "1", "--set", "fluid.spine_rule=trapezoid"]) == 0
    rows = table_rows(capsys.readouterr().out)
    assert {row[0] for row in rows} == set("12345")
    assert all("PASS" in row and "FAIL" not in row for row in rows), rows


def test_prom_from_another_mesh_fails_the_tensor_check(tmp_path, capsys):
    scene_file = tmp_path / "tail.toml"
    scene_file.write_text(ONE_SHAPE_SCENE)
    scene = Scene.load(scene_file)
    prom_file = tmp_path / "level2.npz"
    build_prom(scene.replace("mesh", level=2)).save(prom_file)
    with np.load(prom_file) as data:
        arrays = {key: data[key] for key in data.files}
    header = json.loads(arrays["header"].tobytes().decode()) | {"prom_hash": scene.prom_hash}
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(prom_file, **arrays)
    assert main(["check", str(scene_file), "--prom", str(prom_file)]) == 1
    output = capsys.readouterr().out
    tensor_row = next(row for row in table_rows(output) if row.startswith("1 "))
    assert "FAIL" in tensor_row and "nodes" in tensor_row and "another mesh" in tensor_row
    assert all("SKIP" in row for row in table_rows(output) if row[0] in "23")
    assert "1 check(s) failed" in output


@pytest.fixture(scope="module")
def one_shape_prom():
    """Without the response vectors: with them, the random probe state of check 3 puts more of the
    error in the ξ² remainder near the tail, and a 1.5× ∂K1/∂ξ gives ratios 3.40, 3.04 (inside 4 ± 25 %;
    without them 2.74, 2.44); check 2 flags it either way."""
    scene = coarse_scene(shapes={"z_tail": {"bounds": [-0.5, 0.5]}}, reduction={"response_vectors": False})
    return scene, build_prom(scene)


def test_perturbed_tensor_fails_check_1(one_shape_prom):
    scene, prom = one_shape_prom
    original = prom.elastic.linear.constant
    prom.elastic.linear.constant = original * (1 + 1e-6)
    try:
        tensors = next(run_checks(scene, prom))
    finally:
        prom.elastic.linear.constant = original
    assert tensors.check.startswith("1 ") and tensors.passed is False


def test_wrong_xi_derivative_fails_checks_2_and_3(one_shape_prom):
    scene, prom = one_shape_prom
    original = prom.elastic.linear.first
    prom.elastic.linear.first = original * 1.5
    try:
        tensors, derivative, taylor = islice(run_checks(scene, prom), 3)
    finally:
        prom.elastic.linear.first = original
    assert tensors.passed and derivative.check == "2 ∂f_int/∂ξ z_tail" and not derivative.passed
    assert taylor.check.startswith("3 ") and not taylor.passed


def test_scene_without_shapes_skips_the_xi_checks(capsys):
    assert main(["check", "nominal", "--level", "1"]) == 0
    rows = table_rows(capsys.readouterr().out)
    assert "PASS" in rows[0] and all("SKIP" in row for row in rows[1:]) and len(rows) == 5


def test_missing_prom_file_is_bad_input(tmp_path, capsys):
    assert main(["check", "so1", "--level", "1", "--prom", str(tmp_path / "missing.npz")]) == 2
    assert "not found" in capsys.readouterr().err


def test_check_starts_with_the_taylor_test_of_each_shape_field(tmp_path, capsys):
    scene_file = tmp_path / "two.toml"
    scene_file.write_text(ONE_SHAPE_SCENE + "y_fin = { bounds = [-0.5, 0.5] }\n")
    assert main(["check", str(scene_file)]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("0 ")]
    assert [row.split()[2] for row in rows] == ["z_tail", "y_fin"]
    assert all("PASS" in row and " 2.00 " in row for row in rows), rows
