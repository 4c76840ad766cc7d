"""The Pareto front by effort budgets: max d subject to A ≤ A_k, continued from budget to budget,
each optimum FOM-checked (level 1, a 1 s horizon, three budgets)."""
import csv
import dataclasses
import json
import tomllib

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import Scene, resolve_scene_path, scene_from_dict
from aquarom_fenics.studies.budget_front import COLUMNS, budget_front, continuation_start, parse_budgets
from aquarom_fenics.optimization.cost import design_space


def test_budgets_from_a_range_or_a_list_and_bad_ones_refused_in_one_line():
    assert parse_budgets("0.05:0.4:8", (0.05, 0.4)) == pytest.approx(tuple(np.linspace(0.05, 0.4, 8)))
    assert parse_budgets("0.05:0.4:8", (0.05, 0.4))[2] == 0.15          # written to pareto.csv as typed
    assert parse_budgets("0.1,0.2", (0.05, 0.4)) == (0.1, 0.2)
    for text, words in (("0.05:0.5:3", "outside the amplitude bounds [0.05, 0.4]"), ("0.2,0.1", "increase strictly"),
                        ("a:b", "LOW:HIGH:COUNT"), ("0.1:0.2:0", "LOW:HIGH:COUNT")):
        with pytest.raises(InputError) as refused:
            parse_budgets(text, (0.05, 0.4))
        assert words in str(refused.value) and "\n" not in str(refused.value)


def test_a_budget_continues_from_the_previous_optimum_with_the_amplitude_at_the_budget():
    space = design_space(Scene.load("co"))
    upper = space.upper.copy()
    upper[-1] = 0.2
    bounded = dataclasses.replace(space, upper=upper)
    previous = np.array([-0.5, 0.5, 0.4, 0.5, 0.5, 0.1])
    np.testing.assert_array_equal(continuation_start(bounded, previous), [-0.5, 0.5, 0.4, 0.5, 0.5, 0.2])
    assert continuation_start(bounded, None)[-1] == 0.2


FRONT_SHAPES = ("z_tail", "y_ellipse")


def two_shape_co():
    """The CO scene (quadratic tetrahedra, the stroke vectors, the capped validity radius) with two of its
    five shapes and without the stroke vectors' ξ-sensitivities, over 1 s. The front's properties (A at
    the budget, each optimum continues the last and is FOM-checked, d grows with A) do not depend on the
    number of shapes; five shapes and the sensitivities made the optimisers' PROM builds 3× dearer."""
    data = tomllib.loads(resolve_scene_path("co").read_text(encoding="utf-8"))
    data["shapes"] = {name: data["shapes"][name] for name in FRONT_SHAPES}
    data["solver"] = {"duration": 1.0}
    data["reduction"]["stroke_sensitivities"] = False
    return scene_from_dict(data, source="co with two shapes")


@pytest.fixture(scope="module")
def front(tmp_path_factory):
    out = tmp_path_factory.mktemp("budgets")
    return budget_front(two_shape_co(), out, (0.1, 0.2, 0.3)), out


def test_the_budget_front_swims_farther_with_every_larger_budget_each_point_fom_checked(front):
    rows, out = front
    table = list(csv.DictReader((out / "pareto.csv").open()))
    assert list(table[0]) == COLUMNS + [f"xi_{n}" for n in FRONT_SHAPES]
    assert [row["mode"] for row in table] == ["budget"] * 3 and all(row["w1"] == "" for row in table)
    assert [float(row["budget"]) for row in table] == [0.1, 0.2, 0.3]
    assert all(row["fom_check"] == "completed" and row["converged"] == "True" for row in table)
    fom = [float(row["distance_m"]) for row in table]
    assert np.all(np.diff(fom) > 0), fom
    assert all(float(row["amplitude"]) == pytest.approx(float(row["budget"]), abs=1e-3) for row in table)
    assert (out / "pareto.png").stat().st_size > 10_000


@pytest.mark.parametrize("budgets, words", [("0.3,0.2", "must increase strictly"),
                                            ("0.01:0.4:8", "outside the amplitude bounds")])
def test_pareto_refuses_bad_budgets_in_one_line_and_writes_nothing(tmp_path, capsys, budgets, words):
    from aquarom_fenics.cli import main

    assert main(["pareto", "co", "--budgets", budgets, "--out", str(tmp_path / "front")]) == InputError.exit_code
    error = capsys.readouterr().err.strip()
    assert words in error and "\n" not in error and "Traceback" not in error
    assert not (tmp_path / "front").exists()


class Stop(Exception):
    """Stands for Ctrl-C in the middle of a budget."""


def fake_optimizer(starts: list, stop_at: float | None = None):
    """optimize() for the budget front without PROMs: the optimum is the start (A at the budget), its
    distance 0.1 A; raises Stop at the budget ``stop_at``."""
    from types import SimpleNamespace

    def fake(scene, fish, weights, builder, write_checkpoint, start):
        budget = builder.space.upper[-1]
        if budget == stop_at:
            raise Stop(budget)
        starts.append(np.array(start))
        optimum = np.array(start, dtype=float)
        optimum[0] = -0.1 * len(starts)          # each optimum differs, so a continuation can be told apart
        return SimpleNamespace(space=builder.space, optimum=optimum, evaluation=SimpleNamespace(distance=0.1 * budget),
                               converged=True, optimality=SimpleNamespace(measure=0.0), stop_reason="fake")
    return fake


def test_a_stopped_front_keeps_its_budgets_and_resume_continues_from_the_last_optimum(tmp_path, monkeypatch):
    from aquarom_fenics.studies import budget_front as module
    from aquarom_fenics.studies.budget_front import CHECKPOINT, budget_space

    scene = two_shape_co()
    monkeypatch.setattr(module, "fom_distance", lambda scene, fish, shapes, amplitude: 0.1 * amplitude + 1e-3)
    first = []
    monkeypatch.setattr(module, "optimize", fake_optimizer(first, stop_at=0.3))
    with pytest.raises(Stop):
        budget_front(scene, tmp_path, (0.1, 0.2, 0.3))
    table = list(csv.DictReader((tmp_path / "pareto.csv").open()))
    assert [float(row["budget"]) for row in table] == [0.1, 0.2]
    kept = (tmp_path / CHECKPOINT).read_text()

    for other, words in (((0.1, 0.25, 0.3), "do not begin the budgets asked for (0.1, 0.25, 0.3)"),
                         ((0.1,), "do not begin")):
        with pytest.raises(InputError) as refused:
            budget_front(scene, tmp_path, other, resume=True)
        assert words in str(refused.value) and "\n" not in str(refused.value)
    with pytest.raises(InputError, match="written for scene hash"):
        budget_front(scene.replace("solver", duration=0.5), tmp_path, (0.1, 0.2, 0.3), resume=True)
    assert (tmp_path / CHECKPOINT).read_text() == kept

    resumed = []
    monkeypatch.setattr(module, "optimize", fake_optimizer(resumed))
    rows = budget_front(scene, tmp_path, (0.1, 0.2, 0.3), resume=True)
    assert [row["budget"] for row in rows] == [0.1, 0.2, 0.3] and len(resumed) == 1
    space = module.optimization_space(scene, module.load_fish(scene))
    last = module.row_optimum(space, json.loads(kept)["rows"][-1])
    assert last[0] == -0.2
    np.testing.assert_array_equal(resumed[0], module.continuation_start(budget_space(space, 0.3), last))
    table = list(csv.DictReader((tmp_path / "pareto.csv").open()))
    assert [float(row["budget"]) for row in table] == [0.1, 0.2, 0.3]
    assert [float(row["distance_m"]) for row in table] == pytest.approx([0.011, 0.021, 0.031])


def test_the_real_front_resumed_with_its_own_budgets_runs_no_optimisation(front, monkeypatch):
    from aquarom_fenics.studies import budget_front as module

    rows, out = front
    monkeypatch.setattr(module, "optimize", lambda *args, **kwargs: pytest.fail("a finished budget ran again"))
    again = budget_front(two_shape_co(), out, (0.1, 0.2, 0.3), resume=True)
    assert [row["distance_m"] for row in again] == [row["distance_m"] for row in rows]


def test_pareto_budgets_resume_without_a_checkpoint_is_one_line(tmp_path, capsys):
    from aquarom_fenics.cli import main

    (tmp_path / "front").mkdir()
    assert main(["pareto", "co", "--budgets", "0.1,0.2", "--resume", "--out", str(tmp_path / "front")]) \
        == InputError.exit_code
    error = capsys.readouterr().err.strip()
    assert "budget_front.json" in error and "\n" not in error and "Traceback" not in error
