"""``[optimizer] atlas = true`` with the trust region: every PROM is the atlas's (the centre of the leaf holding its
design), the surrogate step stays inside the centre PROM's validity box (centre ± radius, off the iterate), and
the ratio ρ is judged on one PROM where one answers both designs, else on each design's own PROM."""
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.optimization.cost import CostWeights, Evaluation, cost_value
from aquarom_fenics.optimization.optimize import optimization_space, optimize
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, center_id, center_prom, cover

S = RADIUS_SCALE
SCENE = f"""
name = "atlas-trust-region-test"
[mesh]
level = 1
[solver]
duration = 0.2
[optimizer]
method = "trust-region"
atlas = true
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {0.15 / S!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {0.05 / S!r} }}
"""
"""Cells of half-width 0.15 (z_tail) and 0.05 (y_thin): centres 0_0 (-0.15, 0.05) and 1_0 (0.15, 0.05), radii
0.15 / s and 0.05 / s. The start (0, 0) is in 1_0, whose PROM answers z_tail ≥ 0.15 - 0.15 / s ≈ -0.064 only."""


def test_the_trust_region_takes_every_prom_from_the_atlas_and_steps_inside_its_surrogates_box(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    result = optimize(scene, write_checkpoint=False)
    grid = cover(scene)

    def leaf_prom(design):
        prom, _ = center_prom(scene, dict(zip(grid.names, grid.center(grid.cells(design[None, :])[0]).tolist())))
        return prom

    designs = [np.array([record["design"][name] for name in grid.names]) for record in result.build_records]
    for record, design in zip(result.build_records, designs):
        assert record["atlas_cell"] == center_id(grid.cells(design[None, :])[0])
    assert len({record["atlas_cell"] for record in result.build_records}) == 2        # the steps crossed cells
    assert result.reused == result.prom_builds - 2                                   # two PROMs built, once each
    rows = result.history
    accepted = np.array([rows[0]["xi_z_tail"], rows[0]["xi_y_thin"]])
    assert np.allclose(accepted, designs[0])
    for row, design in zip(rows[1:], designs[1:]):                   # each trial step's candidate, built at once
        candidate = np.array([row["xi_z_tail"], row["xi_y_thin"]])
        assert np.allclose(candidate, design, rtol=0, atol=1e-15)
        surrogate = leaf_prom(accepted)
        assert np.all(np.abs(candidate - surrogate.xi_center) <= surrogate.validity_radius * (1 + 1e-12))
        if np.array_equal(leaf_prom(candidate).xi_center, surrogate.xi_center):
            assert row["ratio"] == pytest.approx(1.0, rel=1e-12)                # the model is that PROM
        if row["prom"] == "built":
            accepted = candidate
    first = np.array([rows[1]["xi_z_tail"], rows[1]["xi_y_thin"]])
    assert first[0] == pytest.approx(0.15 - 0.15 / S, rel=1e-9)   # on the edge of the start PROM's box, not 0.15 / s
    z = result.optimum
    prom = leaf_prom(z)
    assert not np.allclose(prom.xi_center, z)                                        # off-centre, inside the cell
    space = optimization_space(scene, load_fish(scene))
    assert result.evaluation.cost == pytest.approx(cost_value(prom, scene, space, z, CostWeights()), rel=1e-9)


SLOPES = np.array([0.02, 0.01])   # L = -(0.01 + SLOPES · z) [m]: the optimum is the upper corner
HALF = 0.05                       # the leaves: z_tail cells of half-width 0.05, centres -0.15, -0.05, 0.05, 0.15
OFFSET = 0.005                    # a leaf PROM centred at z_tail = c lowers d by OFFSET × c (its projection error)
TOY = {"mesh": {"level": 1}, "solver": {"duration": 1.0},
       "optimizer": {"method": "trust-region", "atlas": True, "max_iterations": 40},
       "shapes": {"z_tail": {"bounds": [-0.2, 0.2], "radius": HALF / S}, "y_thin": {"bounds": [-0.1, 0.1],
                                                                                      "radius": 0.1}}}


class LeafBuilder(PromBuilder):
    """'PROM' of the leaf holding z: centre (c, 0), radius (h / s, 0.1), its own basis; exact slopes, an offset
    OFFSET × c of L, and a refusal beyond its radius (as a PROM's Δξ). ``refused``: the designs it refused."""

    def __init__(self, *args):
        super().__init__(*args)
        self.refused = []

    def build(self, z):
        self.builds += 1
        cell = min(int((z[0] + 0.2) // (2 * HALF)), 3)
        centre = np.array([-0.2 + (2 * cell + 1) * HALF, 0.0])
        return SimpleNamespace(xi_center=centre, validity_radius=np.array([HALF / S, 0.1]), basis=np.full(1, cell))

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        if np.any(np.abs(z - prom.xi_center) > prom.validity_radius * (1 + 1e-12)):
            self.refused.append(tuple(z))
            raise InputError(f"{z} beyond the radius of the PROM at {prom.xi_center}")
        distance = 0.01 + SLOPES @ z - OFFSET * prom.xi_center[0]
        return Evaluation(z, -distance, -SLOPES.copy(), distance, SLOPES.copy())

    def cost(self, prom, z, weights):
        return self.evaluate(prom, z, weights).cost

    def meshes(self, z):
        return True


def test_a_candidate_whose_prom_does_not_answer_the_centre_is_judged_on_each_designs_own_prom():
    """From (0, 0) (leaf 0.05): the box of the leaf's PROM, [-0.021, 0.121], holds the steps; a step from the
    leaf's 0.071 to 0.121 (leaf 0.15, whose PROM answers z_tail ≥ 0.079 only) is judged by L_c(z_c) - L_z(z):
    ρ = 1 - OFFSET × 0.1 / predicted = 0.5. A step inside one leaf has ρ = 1 (the model is that PROM)."""
    scene = scene_from_dict(TOY, source="<toy>")
    fish = load_fish(scene)
    space = optimization_space(scene, fish)
    builder = LeafBuilder(scene, fish, space)
    result = optimize(scene, fish=fish, builder=builder, write_checkpoint=False)
    assert result.converged and result.optimum == pytest.approx(space.upper, abs=1e-9), result.stop_reason
    rows = result.history
    centres = [(row["xi_z_tail"], row["xi_y_thin"]) for row in rows if row["prom"] == "built"]
    assert builder.refused and set(builder.refused) <= set(centres)   # a candidate's PROM asked about the centre

    def prom_cost(centre, z):
        return -(0.01 + SLOPES @ z - OFFSET * centre)

    def leaf(z):
        return builder.build(z).xi_center[0]

    judged = set()
    centre = np.array([rows[0]["xi_z_tail"], rows[0]["xi_y_thin"]])
    for row in rows[1:]:
        z = np.array([row["xi_z_tail"], row["xi_y_thin"]])
        c, c_z = leaf(centre), leaf(z)
        predicted = prom_cost(c, centre) - prom_cost(c, z)
        if c == c_z:
            rule, actual = "one PROM", predicted
        elif abs(centre[0] - c_z) <= HALF / S:
            rule, actual = "the candidate's PROM at both", prom_cost(c_z, centre) - prom_cost(c_z, z)
        else:
            rule, actual = "each design's own PROM", prom_cost(c, centre) - prom_cost(c_z, z)
        assert row["ratio"] == pytest.approx(actual / predicted, rel=1e-9), rule
        judged.add(rule)
        if row["prom"] == "built":
            centre = z
    assert judged == {"one PROM", "each design's own PROM"}
    assert min(row["ratio"] for row in rows[1:]) == pytest.approx(0.5, rel=1e-9)
