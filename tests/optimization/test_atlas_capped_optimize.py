"""``[optimizer] atlas = true`` on a scene whose radii ``[reduction] validity_change`` caps: accepted, the
paper method's PROMs are those of the refined atlas's leaves (bisected where the cap is below the cell), a PROM
is trusted only in its leaf, and at the depth limit a design beyond the leaf's capped radius gets a PROM built at
it instead (coarsest block, 0.2 s swim)."""
import tomllib

import numpy as np
import pytest

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.optimization.cost import CostWeights, cost_value
from aquarom_fenics.optimization.optimize import optimization_space, optimize
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, center_prom, cover
from aquarom_fenics.reduction.atlas_refine import Refiner, node_of

S = RADIUS_SCALE
SCENE = f"""
name = "atlas-capped-optimize-test"
[mesh]
level = 1
[solver]
duration = 0.2
[optimizer]
atlas = true
[reduction]
validity_change = 0.09
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {0.05 / S!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {0.05 / S!r} }}
"""
"""Regular cells of half-width 0.05 (6 × 1); the capped radius in y_thin (about 0.065, relative ξ-derivative
about 1.4) is below the cell / s, so each cell met is bisected in y_thin (tests/studies/test_atlas_capped.py)."""


@pytest.fixture()
def capped(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")          # no longer refused
    fish = load_fish(scene)
    return scene, fish, PromBuilder(scene, fish, optimization_space(scene, fish))


def test_the_optimisers_prom_is_the_leafs_and_is_trusted_in_its_leaf_only(capped):
    scene, _, builder = capped
    grid = cover(scene)
    z = np.array([-0.27, 0.09])
    prom = builder.build(z)
    record = builder.records[-1]
    assert record["atlas_cell"] == "0_1@0_1" and record["atlas_builds"] == 2 and not record["from_cache"]
    assert record["atlas_refined"]["split_on_the_way"] == ["0_0"] and not record["atlas_refined"]["at_depth_limit"]
    node = node_of("0_1@0_1", grid)
    assert np.allclose(prom.xi_center, node.center(grid)) and np.all(node.half_width(grid) <= S * prom.validity_radius)
    assert builder.trusts(prom, np.array([-0.251, 0.051]))                 # the same leaf
    assert not builder.trusts(prom, np.array([-0.27, 0.049]))              # the other half, within prom's radius
    assert np.all(np.abs(np.array([-0.27, 0.049]) - prom.xi_center) <= prom.validity_radius)
    assert not builder.trusts(prom, np.array([-0.19, 0.09]))               # the next base cell
    again = builder.build(np.array([-0.26, 0.06]))
    assert again is prom and builder.records[-1]["from_cache"] and builder.builds == 2 and builder.reused == 1


def test_at_the_depth_limit_a_design_beyond_the_leafs_radius_gets_its_own_prom(capped):
    scene, fish, _ = capped
    tight = scene.replace("reduction", validity_change=0.05)                # R_y ≈ 0.036 < h = 0.05
    builder = PromBuilder(tight, fish, optimization_space(tight, fish))
    builder._atlas = Refiner(tight, cover(tight), fish, max_depth=0)         # no bisection allowed
    inside = builder.build(np.array([-0.25, 0.04]))                        # 0.01 from the centre: within R
    assert builder.records[-1]["atlas_refined"]["at_depth_limit"] and np.allclose(inside.xi_center, [-0.25, 0.05])
    assert builder.trusts(inside, np.array([-0.25, 0.03])) and not builder.trusts(inside, np.array([-0.25, 0.005]))
    z = np.array([-0.25, 0.005])                                           # 0.045 from the centre: beyond R
    assert np.abs(z - inside.xi_center)[1] > inside.validity_radius[1]
    own = builder.build(z)
    assert np.allclose(own.xi_center, z) and "atlas_cell" not in builder.records[-1]
    assert builder.trusts(own, z) and builder.trusts(own, z + [0.0, 0.9 * own.validity_radius[1]])


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_an_optimisation_on_the_capped_atlas_takes_only_leaf_proms(capped, method):
    scene, fish, _ = capped
    scene = scene.replace("optimizer", method=method)
    result = optimize(scene, write_checkpoint=False)
    grid = cover(scene)
    assert result.build_records
    for record in result.build_records:
        node = node_of(record["atlas_cell"], grid)
        assert node.levels == (0, 1)                                      # every PROM a bisected cell's
        design = np.array([record["design"][name] for name in grid.names])
        assert np.all(np.abs(design - node.center(grid)) <= node.half_width(grid) * (1 + 1e-12))
    z = result.optimum
    last = node_of(next(record["atlas_cell"] for record in reversed(result.build_records)
                        if np.array_equal([record["design"][name] for name in grid.names], z)), grid)
    prom, built = center_prom(scene, dict(zip(grid.names, last.center(grid).tolist())))
    assert not built and np.all(np.abs(z - prom.xi_center) <= prom.validity_radius)
    space = optimization_space(scene, fish)
    assert result.evaluation.cost == pytest.approx(cost_value(prom, scene, space, z, CostWeights()), rel=1e-9)
