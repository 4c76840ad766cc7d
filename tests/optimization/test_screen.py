"""The multi-start screen (``[optimizer] screen``): the starts are the screened designs of least cost, each cost
the optimiser's L from the PROM of the atlas centre whose cell holds the design; the key is checked when read
and leaves the scene's hash alone at 0."""
import json
import tomllib

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.optimization import screen as screen_module
from aquarom_fenics.optimization.cost import CostWeights, cost_value
from aquarom_fenics.optimization.optimize import optimization_space, start_points
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.reduction.atlas_cover import RADIUS_SCALE, center_prom, cover

S = RADIUS_SCALE
SCENE = f"""
name = "screen-test"
[mesh]
level = 1
[solver]
duration = 0.2
[optimizer]
starts = 2
screen = 6
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {0.15 / S!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {0.05 / S!r} }}
"""
"""Cells of half-width 0.15 (z_tail) and 0.05 (y_thin): 2 × 1 cells, whatever s."""


def test_the_starts_are_the_screened_designs_of_least_cost(tmp_path, monkeypatch, no_single_reduced_runs):
    """Six designs (the start and five Latin-hypercube ones) in the atlas's two cells: each cost equals the
    optimiser's L from its cell's centre PROM (checked one by one below, after the screen, whose designs are
    integrated in one batch per centre), the two least start; a second screen takes both PROMs from the cache."""
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(SCENE), source="<test>")
    fish = load_fish(scene)
    space = optimization_space(scene, fish)
    weights, meshes = CostWeights(), PromBuilder(scene, fish, space).meshes
    screened = screen_module.screen(scene, space, weights, meshes)
    np.testing.assert_array_equal(screened.designs, np.array(start_points(space, 6, 0, meshes)))
    report = screened.report(space)
    assert report["designs"] == 6 and report["finite_costs"] == 6
    assert report["centres"] == 2 and report["built"] == 2 and report["from_the_cache"] == 0

    monkeypatch.undo()                                       # the single runs of cost_value from here on
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    grid = cover(scene)
    one_by_one = []
    for z in screened.designs:
        cell = grid.cells(z[None, :2])[0]
        prom, built = center_prom(scene, dict(zip(grid.names, grid.center(cell).tolist())))
        assert not built
        one_by_one.append(cost_value(prom, scene, space, z, weights))
    np.testing.assert_allclose(screened.costs, one_by_one, rtol=1e-9, atol=1e-15)
    assert len(set(np.round(one_by_one, 12))) == 6                         # a strict order to check
    assert list(screened.chosen) == list(np.argsort(one_by_one)[:2])
    assert [row["cost"] for row in report["chosen"]] == sorted(one_by_one)[:2]
    np.testing.assert_array_equal(np.array(screened.starts), screened.designs[np.argsort(one_by_one)[:2]])

    again = screen_module.screen(scene, space, weights, meshes)
    assert again.report(space)["from_the_cache"] == 2 and again.report(space)["built"] == 0
    np.testing.assert_array_equal(again.costs, screened.costs)


@pytest.mark.parametrize("starts", [1, 2])
def test_a_multistart_starts_from_the_screens_choice(starts, tmp_path, monkeypatch):
    """The study driver with a screen: its starts are the screen's (an analytic cost stands in for the PROMs and
    the optimiser's runs are recorded, not run), and summary.json's multistart names the screen; one start
    with a screen is a multi-start of one."""
    from aquarom_fenics.studies import study

    text = SCENE.replace("screen = 6", "screen = 9").replace("starts = 2", f"starts = {starts}")
    scene = scene_from_dict(tomllib.loads(text), source="<test>")
    assert study.checkpoint_pattern(scene) == "start_*/checkpoint.json"
    fish = load_fish(scene)
    space = optimization_space(scene, fish)

    def analytic(prom, scene, space, designs, weights):
        return (designs[:, 0] - 0.1) ** 2 + designs[:, 1]

    monkeypatch.setattr(screen_module, "center_prom", lambda scene, center: (None, True))
    monkeypatch.setattr(screen_module, "batch_costs", analytic)
    started = []
    monkeypatch.setattr(study, "start_run", lambda scene, out, resume, weights, max_time, item, fish=None:
                        started.append(item) or _fake_run(space, item[1]))
    monkeypatch.setattr(study, "_write_figures", lambda *args: None)
    study.run_optimization(scene, tmp_path, fish=fish, render=False)
    designs = np.array(start_points(space, 9, 0, PromBuilder(scene, fish, space).meshes))
    best = np.argsort(analytic(None, scene, space, designs, None))[:starts]
    assert [k for k, _ in started] == list(range(starts))
    np.testing.assert_array_equal(np.array([z for _, z in started]), designs[best])
    summary = json.loads((tmp_path / "summary.json").read_text())
    chosen = summary["multistart"]["screen"]["chosen"]
    assert [row["screened"] for row in chosen] == [int(k) + 1 for k in best]
    assert summary["multistart"]["screen"]["designs"] == 9
    assert [row["start"] for row in summary["multistart"]["local_optima"]] == [row["design"] for row in chosen]


def _fake_run(space, z):
    from aquarom_fenics.optimization.cost import Evaluation, FirstOrder
    from aquarom_fenics.optimization.optimize import OptimizationResult
    from aquarom_fenics.studies.study import FomCheck

    evaluation = Evaluation(z, -0.01, np.zeros(2), 0.01, np.zeros(2))
    history = [{"iteration": 0, "prom": "built", "distance": 0.01}]
    result = OptimizationResult(z, evaluation, history, 1, "first-order optimality", space,
                                timings={"prom_builds": 0.0, "prom_solves": 0.0, "total": 0.0},
                                optimality=FirstOrder(0.0, []))
    return result, FomCheck(0.01, 0.01, None, 0.01, 0.0)


@pytest.mark.parametrize("table, message", [
    ({"screen": -1}, r"\[optimizer\] screen = -1 must be 0 \(off\) or a number of designs in \[starts, 100000\]"),
    ({"screen": 100_001}, r"\[optimizer\] screen = 100001 must be 0 \(off\)"),
    ({"screen": 2.5}, r"\[optimizer\] screen must be an integer, got 2.5"),
    ({"screen": "yes"}, r"\[optimizer\] screen must be an integer, got 'yes'"),
    ({"screen": 2, "starts": 3}, r"\[optimizer\] screen = 2 is below starts = 3: 0 \(off\) or at least starts"),
])
def test_a_bad_screen_is_refused_in_one_line(table, message, tmp_path, capsys):
    with pytest.raises(InputError, match=message):
        scene_from_dict({"optimizer": table}, source="bad.toml")
    with pytest.raises(InputError, match=message):
        Scene.load("so1").replace("optimizer", **table)
    path = tmp_path / "bad.toml"
    path.write_text("[optimizer]\n" + "".join(f"{key} = {json.dumps(value)}\n" for key, value in table.items()))
    assert main(["optimize", str(path), "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "screen" in lines[0] and "Traceback" not in lines[0], lines


def test_the_screen_leaves_the_hash_alone_at_0_and_changes_it_otherwise():
    scene = Scene.load("so1")
    assert scene.optimizer.screen == 0 and not scene.optimizer.multistart
    written = scene_from_dict(tomllib.loads(scene.to_toml()), source=scene.source, base_dir=scene.base_dir)
    assert "screen = 0" in scene.to_toml() and written.hash == scene.hash
    assert scene.replace("optimizer", screen=0).hash == scene.hash
    screened = scene.replace("optimizer", screen=200)
    assert screened.hash != scene.hash and screened.optimizer.multistart
    assert scene.replace("optimizer", screen=200, starts=3).hash != screened.hash
