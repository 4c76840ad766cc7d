"""The capped atlas's builds told before a sweep (``studies/atlas_plan.py``, ``sweep --dry-run``): the ways down
go through the PROMs the cache holds (read, never built), stop at the first cell not in it, and the builds lie
between the stop cells and the bound of one per halving left for each design; a sweep's own cells, once in the
cache, answer every design without a build, and the dry run writes nothing."""
import tomllib
from types import SimpleNamespace

import numpy as np

from conftest import capped_block_scene
from aquarom_fenics.cli import main
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.parallel import InProcess
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, cover
from aquarom_fenics.reduction.atlas_refine import MAX_DEPTH, Refiner
from aquarom_fenics.studies import sweep
from aquarom_fenics.studies.atlas_plan import division_plan

S = RADIUS_SCALE
SCENE = capped_block_scene("atlas-plan-test", S)
"""Regular cells of half-width 0.05 (6 × 1); test_atlas_capped.py's scene."""
DESIGNS = [{"z_tail": -0.27, "y_thin": 0.01}, {"z_tail": -0.27, "y_thin": 0.04}, {"z_tail": -0.27, "y_thin": 0.09},
           {"z_tail": 0.27, "y_thin": 0.09}]


def fake_cache(held):
    """stored(ξ_c): a PROM with R = (r, 0.0125 / s) (two halvings of y_thin at once, then leaves) at the centres
    in ``held`` (rounded), else None; records the look-ups."""
    looked = []

    def stored(xi):
        looked.append(tuple(np.round(xi, 9)))
        if tuple(np.round(xi, 9)) not in held:
            return None
        return SimpleNamespace(validity_radius=np.array([0.05 / S, 0.0125 / S]), xi_center=xi)
    return stored, looked


def centres_met(scene):
    """The centres of every node the real descent meets for DESIGNS with the fake PROM (all of it cached)."""
    every = lambda center: (SimpleNamespace(validity_radius=np.array([0.05 / S, 0.0125 / S])), True)  # noqa: E731
    refiner = Refiner(scene, cover(scene), prom_at=every)
    leaves = {refiner.leaf(np.array([d["z_tail"], d["y_thin"]])).node for d in DESIGNS}
    grid = cover(scene)
    return leaves, {tuple(np.round(node.center(grid), 9)) for node in refiner.radii}, grid


def test_the_plan_stops_each_way_at_the_first_cell_not_in_the_cache_and_bounds_the_builds():
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    leaves, every_centre, grid = centres_met(scene)
    assert len(leaves) == 4 and all(node.levels == (0, 2) for node in leaves)
    empty = division_plan(scene, DESIGNS, stored=fake_cache(set())[0])
    assert (empty.to_build, empty.read, empty.answered_from_cache) == (2, 0, 0)     # the two regular cells
    assert empty.at_most == (1 + 3 * 2 * MAX_DEPTH) + (1 + 1 * 2 * MAX_DEPTH)
    bases = {tuple(np.round(grid.center(np.array(cell)), 9)) for cell in [(0, 0), (5, 0)]}
    stored, looked = fake_cache(bases)
    half = division_plan(scene, DESIGNS, stored=stored)
    assert (half.read, half.to_build, half.answered_from_cache) == (2, 4, 0)        # one jump to four parts
    assert half.at_most == 4 * (1 + (MAX_DEPTH + MAX_DEPTH - 2))
    assert len(looked) == 2 + 4                                                      # each centre looked up once
    full = division_plan(scene, DESIGNS, stored=fake_cache(every_centre)[0])
    assert (full.answered_from_cache, full.leaves_in_cache, full.to_build, full.at_most) == (4, 4, 0, 0)
    assert full.read == len(every_centre) == 6


def test_a_dry_run_on_a_capped_scene_tells_the_builds_from_the_prom_cache_and_writes_nothing(tmp_path, capsys,
                                                                                             monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "capped.toml"
    path.write_text(SCENE)
    designs = tmp_path / "designs.csv"
    designs.write_text("z_tail,y_thin\n-0.27,0.01\n-0.27,0.09\n0.27,0.09\n")
    assert main(["sweep", str(path), "--model", "prom", "--designs", str(designs), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "(0 PROM(s) read, none built): 0 of 3 designs reach a cached leaf" in text
    assert f"stop at 2 cell(s) not in the cache: 2 to {(1 + 2 * 2 * MAX_DEPTH) + (1 + 2 * MAX_DEPTH)} PROM builds" \
        in text
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    rows = sweep.run_sweep(scene, [{"z_tail": -0.27, "y_thin": 0.01}, {"z_tail": -0.27, "y_thin": 0.09},
                                   {"z_tail": 0.27, "y_thin": 0.09}], "prom", tmp_path / "out", pool=InProcess())
    assert [row["status"] for row in rows] == ["completed"] * 3
    entries = sorted((tmp_path / "cache" / "prom").iterdir())
    assert main(["sweep", str(path), "--model", "prom", "--designs", str(designs), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "(5 PROM(s) read, none built): 3 of 3 designs reach a cached leaf (3 leaves)" in text  # test_atlas_capped's
    assert "stop at 0 cell(s) not in the cache: 0 to 0 PROM builds" in text
    assert sorted((tmp_path / "cache" / "prom").iterdir()) == entries
