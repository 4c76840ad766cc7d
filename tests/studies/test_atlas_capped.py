"""A PROM sweep on a scene whose radii ``[reduction] validity_change`` caps: the atlas's cells are bisected
where a centre's capped radius (× the atlas's scale) is below the cell's half-width, in that shape only, and
every design is answered by the leaf's PROM, inside that PROM's capped radius (coarsest block, 0.2 s swim)."""
import json
import tomllib

import numpy as np
import pytest

from conftest import capped_block_scene
from aquarom_fenics.cli.sweep import atlas_line
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.parallel import InProcess
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, center_prom, cover
from aquarom_fenics.reduction.atlas_refine import node_of
from aquarom_fenics.studies import sweep

S = RADIUS_SCALE
SCENE = capped_block_scene("atlas-capped-test", S)
"""Regular cells of half-width 0.05 in both shapes (6 × 1). The block's relative ξ-derivatives are about 0.55-0.6
(z_tail) and 1.24-1.5 (y_thin), so the capped radii are about 0.15 and 0.065: s R ≈ 0.1 holds the cell in z_tail,
s R ≈ 0.045 does not in y_thin, whose cells are bisected once (half-width 0.025)."""
DESIGNS = [{"z_tail": -0.27, "y_thin": 0.01}, {"z_tail": -0.27, "y_thin": 0.09}, {"z_tail": 0.27, "y_thin": 0.09}]


def test_a_capped_sweep_bisects_the_cells_where_the_cap_is_below_them_and_answers_inside_the_radius(tmp_path,
                                                                                                 monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    grid = cover(scene)
    rows = sweep.run_sweep(scene, DESIGNS, "prom", tmp_path / "out", pool=InProcess())
    assert [row["status"] for row in rows] == ["completed"] * 3, [row["reason"] for row in rows]
    assert [row["prom_center"] for row in rows] == ["0_0@0_1", "0_1@0_1", "5_1@0_1"]
    report = json.loads((tmp_path / "out" / "atlas.json").read_text())
    split = report["refinement"]["split_centres"]
    assert [(c["id"], c["split"], c["status"]) for c in split] == [("0_0", ["y_thin"], "built"),
                                                                   ("5_0", ["y_thin"], "built")]
    assert report["totals"]["built"] == 5 and report["totals"]["centres"] == 3
    assert report["refinement"]["at_depth_limit"] == []
    line, totals = atlas_line(tmp_path / "out")
    assert "3 centre(s) used, 5 built" in line and "2 cell(s) bisected for their capped radius" in line
    assert "depth limit" not in line and totals["bisected"] == 2
    for row, design in zip(rows, DESIGNS):
        node = node_of(row["prom_center"], grid)
        center, half = node.center(grid), node.half_width(grid)
        assert half == pytest.approx([0.05, 0.025])
        prom, built = center_prom(scene, dict(zip(grid.names, center.tolist())))
        assert not built and np.allclose(prom.xi_center, center)
        xi = np.array([design[name] for name in grid.names])
        assert np.all(np.abs(xi - center) <= half) and np.all(half <= S * prom.validity_radius)
        assert prom.validity_radius[1] < 0.05 / S                     # capped below the scene's radius
        alone = simulate_reduced(prom, scene, xi)                      # the leaf's PROM answered the row
        assert row["distance_m"] == pytest.approx(alone.distance, rel=1e-9)
    for record in split:                                               # the parents' caps were below the cell
        assert S * record["prom_radius"]["y_thin"] < 0.05 <= S * record["prom_radius"]["z_tail"]


def test_a_cell_at_the_depth_limit_answers_only_inside_its_prom_radius_and_is_reported(tmp_path, monkeypatch):
    """validity_change 0.05: R_y ≈ 0.036 < h = 0.05 / s; with no bisection allowed the cell is at the depth limit,
    the design 0.01 from its centre is answered, the one 0.045 from it (beyond R) is a refused row."""
    from aquarom_fenics.studies import atlas

    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(atlas, "MAX_DEPTH", 0)
    scene = scene_from_dict(tomllib.loads(SCENE.replace("validity_change = 0.09", "validity_change = 0.05")),
                            source="<test>")
    rows = sweep.run_sweep(scene, [{"z_tail": -0.25, "y_thin": 0.04}, {"z_tail": -0.25, "y_thin": 0.005}], "prom",
                           tmp_path / "out", pool=InProcess())
    assert [row["status"] for row in rows] == ["completed", "refused"] and rows[1]["prom_center"] == "0_0"
    assert "outside the PROM's validity radius" in rows[1]["reason"]
    report = json.loads((tmp_path / "out" / "atlas.json").read_text())
    assert report["refinement"] == {"max_depth": 0, "split_centres": [], "at_depth_limit": ["0_0"]}
    assert report["centres"][0]["prom_radius"]["y_thin"] < 0.045 and report["centres"][0]["at_depth_limit"]
    assert "1 cell(s) at the depth limit (0 bisections)" in atlas_line(tmp_path / "out")[0]
