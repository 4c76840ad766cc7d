"""The CO sweep's table: a point whose FOM check stopped is marked infeasible with the FOM's reason;
a resumed sweep keeps the weights that completed and continues the others."""
import csv
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.errors import InputError

from aquarom_fenics.io.scene import Scene
from aquarom_fenics.studies import study


def test_a_point_whose_fom_check_stops_is_marked_infeasible_with_the_reason(tmp_path, monkeypatch):
    scene = Scene.load("co").replace("cooptimization", weights=(0.3, 0.9))
    names = [shape.name for shape in scene.shapes] + ["amplitude"]

    def optimised(scene, out_dir, weights, fish, render, resume=False):
        amplitude = 0.1 if weights.distance < 0.5 else 0.4
        result = SimpleNamespace(optimum=np.array([0.0] * (len(names) - 1) + [amplitude]),
                                 evaluation=SimpleNamespace(distance=0.02 if amplitude < 0.4 else 0.3),
                                 space=study.design_space(scene), converged=amplitude < 0.4)
        stopped = "FOM at {...} stopped: Newton did not converge at t = 1.42 s"
        check = study.FomCheck(0.045, 0.021 if amplitude < 0.4 else None, 0.045, result.evaluation.distance, 1.0,
                               None if amplitude < 0.4 else stopped)
        return result, check

    monkeypatch.setattr(study, "run_optimization", optimised)
    study.pareto_sweep(scene, tmp_path, fish=object())
    rows = list(csv.DictReader((tmp_path / "pareto.csv").open()))
    assert [row["fom_check"] for row in rows] == ["completed", "infeasible"]
    assert rows[0]["fom_check_reason"] == "" and "did not converge at t = 1.42 s" in rows[1]["fom_check_reason"]
    assert [row["converged"] for row in rows] == ["True", "False"]      # the optimiser's first-order point
    assert [row["mode"] for row in rows] == ["weight", "weight"]       # a budget front's rows say "budget"
    assert (tmp_path / "pareto.png").stat().st_size > 10_000


def _completed_summary(scene, w1, amplitude, distance, names, scene_hash=None):
    return {"scene": scene.name, "scene_hash": scene_hash or scene.hash, "method": "paper",
            "optimum": {**{n: 0.1 for n in names[:-1]}, "amplitude": amplitude},
            "prom_distance_optimal": distance + 0.001,
            "cost_weights": {"distance": w1, "energy": 1.0 - w1, "alpha": scene.cooptimization.energy_weight},
            "fom_check": {"optimal_distance": distance, "error": None}, "converged": True}


def test_a_resumed_sweep_keeps_completed_weights_and_continues_the_others_from_their_checkpoints(tmp_path, monkeypatch):
    scene = Scene.load("co").replace("cooptimization", weights=(0.3, 0.5, 0.9))
    names = [shape.name for shape in scene.shapes] + ["amplitude"]
    (tmp_path / "w1_0.3").mkdir()
    (tmp_path / "w1_0.3" / "summary.json").write_text(json.dumps(_completed_summary(scene, 0.3, 0.2, 0.15, names)))
    (tmp_path / "w1_0.5").mkdir()                  # interrupted: a checkpoint and a summary saying so
    (tmp_path / "w1_0.5" / "checkpoint.json").write_text("{}")
    (tmp_path / "w1_0.5" / "summary.json").write_text(json.dumps(
        {"scene_hash": scene.hash, "completed": False, "stop_reason": "interrupted (Ctrl-C) after 3 history row(s)"}))
    calls = []

    def optimised(scene, out_dir, weights, fish, render, resume=False):
        calls.append((Path(out_dir).name, resume))
        result = SimpleNamespace(optimum=np.array([0.0] * (len(names) - 1) + [0.4]),
                                 evaluation=SimpleNamespace(distance=0.3), space=study.design_space(scene),
                                 converged=True)
        return result, study.FomCheck(0.045, 0.29, 0.045, 0.3, 1.0, None)

    monkeypatch.setattr(study, "run_optimization", optimised)
    points = study.pareto_sweep(scene, tmp_path, fish=object(), resume=True)
    assert calls == [("w1_0.5", True), ("w1_0.9", False)]     # 0.3 is read back, 0.9 never began
    assert [p["distance_m"] for p in points] == [0.15, 0.29, 0.29]
    assert points[0]["amplitude"] == 0.2 and points[0]["prom_distance_m"] == 0.151
    assert points[0]["xi_z_tail"] == 0.1
    assert list(points[0]) == list(points[1])                 # the same columns, in the design space's order

    calls.clear()
    study.pareto_sweep(scene, tmp_path, fish=object())        # without resume every weight runs again
    assert calls == [("w1_0.3", False), ("w1_0.5", False), ("w1_0.9", False)]


@pytest.mark.parametrize("change, message", [({"scene_hash": "0123456789abcdef"}, "scene hash"),
                                             ({"cost_weights": {"distance": 0.4, "energy": 0.6, "alpha": 1.0}},
                                              "cost weights"),
                                             ({"optimum": {"amplitude": 0.2}}, "optimum")])
def test_a_resumed_sweep_refuses_a_summary_of_another_study_in_one_line(tmp_path, monkeypatch, change, message):
    scene = Scene.load("co").replace("cooptimization", weights=(0.3,))
    names = [shape.name for shape in scene.shapes] + ["amplitude"]
    (tmp_path / "w1_0.3").mkdir()
    summary = _completed_summary(scene, 0.3, 0.2, 0.15, names) | change
    (tmp_path / "w1_0.3" / "summary.json").write_text(json.dumps(summary))
    monkeypatch.setattr(study, "run_optimization", lambda *a, **k: pytest.fail("a refused resume must not run"))
    with pytest.raises(InputError, match=message) as refused:
        study.pareto_sweep(scene, tmp_path, fish=object(), resume=True)
    assert "\n" not in str(refused.value)
    assert not (tmp_path / "pareto.csv").exists()


def test_pareto_resume_without_any_checkpoint_is_refused_and_creates_nothing(tmp_path, capsys):
    from aquarom_fenics.cli import main

    assert main(["pareto", "co", "--level", "1", "--out", str(tmp_path / "none"), "--resume"]) == 2
    error = capsys.readouterr().err.strip()
    assert "no w1_*/checkpoint.json" in error and error.count("\n") == 0
    assert not (tmp_path / "none").exists()


def test_pareto_resume_of_a_multi_start_scene_looks_for_its_starts_checkpoints(tmp_path, capsys):
    """A weight of a multi-start scene keeps one checkpoint per start: that is what --resume needs."""
    from aquarom_fenics.cli import main

    assert main(["pareto", "co", "--level", "1", "--set", "optimizer.starts=2", "--out", str(tmp_path / "none"),
                 "--resume"]) == 2
    error = capsys.readouterr().err.strip()
    assert "no w1_*/start_*/checkpoint.json" in error and error.count("\n") == 0
    assert not (tmp_path / "none").exists()
