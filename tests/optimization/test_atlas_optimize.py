"""``[optimizer] atlas = true``: the paper method's PROMs are the atlas's (the centre of the cell holding the
iterate, through the PROM cache), so that after a PROM sweep of the same scene the optimiser builds none; a new
PROM when the iterate leaves the cell. Off by default, out of the hash at false."""
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.optimization.cost import CostWeights, cost_value
from aquarom_fenics.optimization.optimize import optimization_space, optimize
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.parallel import InProcess
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, center_id, center_prom, cover
from aquarom_fenics.studies import sweep

S = RADIUS_SCALE
SCENE = f"""
name = "atlas-optimize-test"
[mesh]
level = 1
[solver]
duration = 0.2
[optimizer]
atlas = true
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {0.15 / S!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {0.05 / S!r} }}
"""
"""Cells of half-width 0.15 (z_tail) and 0.05 (y_thin): 2 × 1 cells, centres 0_0 (-0.15, 0.05), 1_0 (0.15, 0.05)."""


def test_after_a_prom_sweep_the_optimiser_takes_every_prom_from_the_atlas(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    rows = sweep.run_sweep(scene, [{"z_tail": -0.2, "y_thin": 0.02}, {"z_tail": 0.2, "y_thin": 0.08}], "prom",
                           tmp_path / "sweep", pool=InProcess())
    assert sorted(row["prom_center"] for row in rows) == ["0_0", "1_0"]
    result = optimize(scene, write_checkpoint=False)
    assert result.prom_builds >= 2 and result.reused == result.prom_builds        # none built: all the atlas's
    grid = cover(scene)
    for record in result.build_records:
        design = np.array([record["design"][name] for name in grid.names])
        assert record["atlas_cell"] == center_id(grid.cells(design[None, :])[0]) and record["from_cache"]
    assert len({record["atlas_cell"] for record in result.build_records}) == 2       # the iterates crossed cells
    z = result.optimum
    prom, built = center_prom(scene, dict(zip(grid.names, grid.center(grid.cells(z[None, :])[0]).tolist())))
    assert not built and not np.allclose(prom.xi_center, z)                          # off-centre, inside the cell
    space = optimization_space(scene, load_fish(scene))
    assert result.evaluation.cost == pytest.approx(cost_value(prom, scene, space, z, CostWeights()), rel=1e-9)


def test_with_the_atlas_a_prom_is_trusted_in_its_cell_only():
    """z_tail = 0.01 is within the radius 0.214 of the centre -0.15, but in the other cell."""
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    fish = load_fish(scene)
    builder = PromBuilder(scene, fish, optimization_space(scene, fish))
    centre = SimpleNamespace(xi_center=np.array([-0.15, 0.05]), validity_radius=np.array([0.15, 0.05]) / S)
    assert builder.trusts(centre, np.array([-0.01, 0.09])) and not builder.trusts(centre, np.array([0.01, 0.05]))
    plain = scene.replace("optimizer", atlas=False)
    assert PromBuilder(plain, fish, builder.space).trusts(centre, np.array([0.01, 0.05]))


def test_a_bad_atlas_value_is_refused_in_one_line_and_the_trust_region_takes_the_atlas():
    with pytest.raises(InputError, match=r"\[optimizer\] atlas must be true or false, got 1"):
        scene_from_dict({"optimizer": {"atlas": 1}}, source="bad.toml")
    scene = scene_from_dict({"optimizer": {"atlas": True, "method": "trust-region"}}, source="good.toml")
    assert scene.optimizer.atlas and scene.optimizer.method == "trust-region"


def test_the_atlas_key_leaves_the_hash_alone_when_off():
    scene = Scene.load("so1")
    assert not scene.optimizer.atlas and "atlas = false" in scene.to_toml()
    assert scene.replace("optimizer", atlas=False).hash == scene.hash
    assert scene.replace("optimizer", atlas=True).hash != scene.hash
