"""A PROM sweep with the atlas's own check (``[reduction] atlas_check``) on the coarsest block, a 0.2 s swim and
two shapes without capped radii: each cell's PROM is compared with the PROMs at two of its corners, built through
the PROM cache; atlas.json records the corners, the gaps and the builds, the gaps are those of the PROMs in the
cache; a cell whose check fails at the depth limit is named; the dry run says it cannot know the gaps."""
import json
import tomllib

import numpy as np
import pytest

from conftest import capped_block_scene
from aquarom_fenics.cli import main
from aquarom_fenics.cli.sweep import atlas_line
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.parallel import InProcess
from aquarom_fenics.reduction.atlas_cover import center_prom
from aquarom_fenics.studies import sweep

SCENE = capped_block_scene("atlas-check-test").replace("validity_change = 0.09", "atlas_check = TOLERANCE")
DESIGN = {"z_tail": 0.12, "y_thin": 0.03}
"""In the cell 4_0 (z_tail 0.1 to 0.2, y_thin 0 to 0.1), where the 0.2 s swim's PROMs differ by 10-15 % at the
corners (near the box's z_tail = -0.3 the distance is closer to 0 and the relative gaps larger)."""


def scene_at(tolerance):
    return scene_from_dict(tomllib.loads(SCENE.replace("TOLERANCE", repr(tolerance))), source="<test>")


def test_a_cell_within_its_check_is_answered_by_its_prom_and_the_check_is_recorded(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_at(0.5)
    rows = sweep.run_sweep(scene, [DESIGN], "prom", tmp_path / "out", pool=InProcess())
    assert rows[0]["status"] == "completed" and rows[0]["prom_center"] == "4_0"
    report = json.loads((tmp_path / "out" / "atlas.json").read_text())
    check = report["centres"][0]["check"]
    assert check["passed"] and check["corner_builds"] == 2 and len(check["corners"]) == 2
    assert report["totals"]["built"] == 1 and report["totals"]["check_corner_builds"] == 2
    assert report["refinement"]["check_failed_at_depth_limit"] == [] and not report["refinement"]["split_centres"]
    center, _ = center_prom(scene, report["centres"][0]["center"])
    for corner, gap in zip(check["corners"], check["gaps"]):
        own, built = center_prom(scene, corner)
        assert not built                                              # the check's corner PROM, in the cache
        xi = np.array([corner["z_tail"], corner["y_thin"]])
        assert np.abs(xi - [0.15, 0.05]) == pytest.approx([0.05, 0.05])    # a corner of the cell
        there, alone = simulate_reduced(center, scene, xi).distance, simulate_reduced(own, scene, xi).distance
        assert gap == pytest.approx(abs(there - alone) / abs(alone), rel=1e-6, abs=1e-12)
    assert "atlas check: 2 corner PROM(s) built" in atlas_line(tmp_path / "out")[0]


def test_a_cell_failing_its_check_at_the_depth_limit_is_named(tmp_path, monkeypatch):
    from aquarom_fenics.studies import atlas

    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(atlas, "MAX_DEPTH", 1)
    rows = sweep.run_sweep(scene_at(1e-9), [DESIGN], "prom", tmp_path / "out", pool=InProcess())
    assert rows[0]["status"] == "completed" and rows[0]["prom_center"] == "8_0@1_1"
    report = json.loads((tmp_path / "out" / "atlas.json").read_text())
    assert report["refinement"]["check_failed_at_depth_limit"] == ["8_0@1_1"]
    assert [record["id"] for record in report["refinement"]["split_centres"]] == ["4_0"]
    assert report["refinement"]["split_centres"][0]["split"] == ["z_tail", "y_thin"]
    assert report["totals"]["built"] == 2 and report["totals"]["checked"] == 2
    assert 2 <= report["totals"]["check_corner_builds"] <= 4          # fewer where the half's corner is shared
    line = atlas_line(tmp_path / "out")[0]
    assert "1 cell(s) failed their check at the depth limit" in line and "or their check" in line


def test_the_dry_run_says_it_cannot_know_the_gaps(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.replace("TOLERANCE", "0.03"))
    designs = tmp_path / "designs.csv"
    designs.write_text("z_tail,y_thin\n-0.27,0.02\n0.27,0.09\n")
    assert main(["sweep", str(path), "--model", "prom", "--designs", str(designs), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "atlas_check = 0.03" in text and "cannot tell which cells will be halved" in text
    assert "(0 PROM(s) read, none built): 0 of 2 designs reach a cached leaf" in text
    assert "stop at 2 cell(s) not in the cache: 2 to 78 PROM builds" in text            # 3 (1 + 1 × 12) each
    assert not (tmp_path / "cache" / "prom").exists() or not any((tmp_path / "cache" / "prom").iterdir())
