"""The CO sweep's table: a point whose FOM check stopped is marked infeasible with the FOM's reason."""
import csv
from types import SimpleNamespace

import numpy as np

from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization import study


def test_a_point_whose_fom_check_stops_is_marked_infeasible_with_the_reason(tmp_path, monkeypatch):
    scene = Scene.load("co").replace("cooptimization", weights=(0.3, 0.9))
    names = [shape.name for shape in scene.shapes] + ["amplitude"]

    def optimised(scene, out_dir, weights, fish, render):
        amplitude = 0.1 if weights.distance < 0.5 else 0.4
        result = SimpleNamespace(optimum=np.array([0.0] * (len(names) - 1) + [amplitude]),
                                 evaluation=SimpleNamespace(distance=0.02 if amplitude < 0.4 else 0.3),
                                 space=SimpleNamespace(names=names))
        stopped = "FOM at {...} stopped: Newton did not converge at t = 1.42 s"
        check = study.FomCheck(0.045, 0.021 if amplitude < 0.4 else None, 0.045, result.evaluation.distance, 1.0,
                               None if amplitude < 0.4 else stopped)
        return result, check

    monkeypatch.setattr(study, "run_optimization", optimised)
    study.pareto_sweep(scene, tmp_path, fish=object())
    rows = list(csv.DictReader((tmp_path / "pareto.csv").open()))
    assert [row["fom_check"] for row in rows] == ["completed", "infeasible"]
    assert rows[0]["fom_check_reason"] == "" and "did not converge at t = 1.42 s" in rows[1]["fom_check_reason"]
    assert (tmp_path / "pareto.png").stat().st_size > 10_000
