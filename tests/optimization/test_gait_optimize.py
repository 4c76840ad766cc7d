"""Optimisation with [gait] variables: the design vector [ξ, (A), g], the cost's gradient against central
differences of the PROM's cost, and the optimize command on the coarsest block's wave."""
import json

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.optimization.cost import CostWeights, cost_value, design_space, evaluate, scene_at
from aquarom_fenics.reduction.reductor import build_prom

PAIRS = [{"region": f"{side}_{k}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (k - 1)}
         for k in (1, 2, 3) for side in ("left", "right")]


def gait_scene(gait, method="trust-region", **sections):
    data = {"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "muscles": PAIRS, "gait": gait,
            "shapes": {"z_tail": {"bounds": [-0.2, 0.2]}},
            "solver": {"duration": 1.0, "tolerance": 1e-11}, "optimizer": {"method": method, "max_iterations": 4}}
    return scene_from_dict(data | sections, source="<test>")


def test_the_design_vector_is_shapes_amplitude_then_gait():
    scene = gait_scene({"frequency": {"bounds": [0.5, 2.0]}, "phase_lag": {"bounds": [60, 180], "start": 90}},
                       cooptimization={"enabled": True})
    space = design_space(scene)
    assert space.names == ("z_tail", "amplitude", "frequency", "phase_lag")
    assert (space.n_shapes, space.amplitude_index, space.n_gait) == (1, 1, 2)
    np.testing.assert_array_equal(space.start, [0.0, 0.2, 1.0, 90.0])
    driven = scene_at(scene, space, np.array([0.0, 0.2, 1.5, 45.0]))
    assert driven.actuation.frequency == 1.5 and [m.phase for m in driven.muscles][::2] == [0.0, 45.0, 90.0]


def test_the_cost_gradient_in_the_gait_matches_central_differences_of_the_prom_cost():
    scene = gait_scene({"frequency": {"bounds": [0.5, 2.0]}, "phase_lag": {"bounds": [60, 180]},
                        "amplitude_3": {"bounds": [0.1, 0.3]}})
    space = design_space(scene)
    prom = build_prom(scene)
    z = np.array([0.05, 1.1, 100.0, 0.25])
    evaluation = evaluate(prom, scene, space, z, CostWeights())
    assert cost_value(prom, scene, space, z, CostWeights()) == evaluation.cost
    for k, step in ((1, 1e-5), (2, 1e-3), (3, 1e-5)):
        shift = step * np.eye(4)[k]
        central = (cost_value(prom, scene, space, z + shift, CostWeights())
                   - cost_value(prom, scene, space, z - shift, CostWeights())) / (2 * step)
        assert abs(evaluation.gradient[k] - central) < 1e-5 * abs(central), (k, evaluation.gradient[k], central)


def test_the_paper_method_with_gait_variables_is_refused_in_one_line(tmp_path, capfd):
    path = tmp_path / "gait.toml"
    path.write_text('[mesh]\nlevel = 1\n[optimizer]\nmethod = "paper"\n[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n'
                    '[gait]\nfrequency = { bounds = [0.5, 2.0] }\n')
    assert main(["optimize", str(path), "--dry-run"]) == 2
    err = capfd.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "trust-region" in err and "[gait]" in err


def test_optimize_moves_the_gait_and_its_fom_check_improves(tmp_path, capsys):
    """The block's wave, 1 s: the frequency and the lag leave their start, the FOM swims farther at the optimum."""
    path = tmp_path / "gait.toml"
    path.write_text('[mesh]\nlevel = 1\n[regions]\nmuscle_pairs = 3\n[solver]\nduration = 1.0\n'
                    '[optimizer]\nmethod = "trust-region"\nmax_iterations = 3\n[output]\nrender = false\nplots = false\n'
                    '[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n'
                    '[gait]\nfrequency = { bounds = [0.5, 1.5] }\nphase_lag = { bounds = [60, 180] }\n'
                    + "".join(f'[[muscles]]\nregion = "{m["region"]}"\nscale = {m["scale"]}\nphase = {m["phase"]}\n'
                              for m in PAIRS))
    out = tmp_path / "run"
    assert main(["optimize", str(path), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    optimum = summary["optimum"]
    assert set(optimum) == {"z_tail", "frequency", "phase_lag"}
    assert optimum["frequency"] != pytest.approx(1.0, abs=1e-3) or optimum["phase_lag"] != pytest.approx(120.0, abs=0.1)
    assert summary["fom_check"]["ratio"] > 1.0


def test_a_scene_of_gait_variables_alone_is_planned_and_budgets_are_refused(tmp_path, capfd):
    path = tmp_path / "gait_only.toml"
    path.write_text('[mesh]\nlevel = 1\n[optimizer]\nmethod = "trust-region"\n[gait]\nfrequency = { bounds = [0.5, 2.0] }\n')
    assert main(["optimize", str(path), "--dry-run"]) == 0
    capfd.readouterr()
    path.write_text('[mesh]\nlevel = 1\n[optimizer]\nmethod = "trust-region"\n[cooptimization]\nenabled = true\n'
                    '[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n[gait]\nfrequency = { bounds = [0.5, 2.0] }\n')
    assert main(["pareto", str(path), "--budgets", "0.1,0.2", "--dry-run"]) == 2
    err = capfd.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--budgets" in err and "[gait]" in err


def test_the_power_effort_gradient_matches_central_differences_of_the_prom_cost():
    """[cooptimization] effort = "power": L = -w_1 d + w_2 α P̄ over [ξ, A, g], its gradient against the cost's
    central differences; the effort "amplitude" keeps α A²."""
    scene = gait_scene({"phase_lag": {"bounds": [60, 180]}}, cooptimization={"enabled": True, "effort": "power"},
                       solver={"duration": 0.6, "tolerance": 1e-11})
    space = design_space(scene)
    prom = build_prom(scene)
    weights = CostWeights(0.6, 0.4, 1.0)
    z = np.array([0.03, 0.22, 100.0])
    evaluation = evaluate(prom, scene, space, z, weights)
    assert cost_value(prom, scene, space, z, weights) == evaluation.cost
    assert evaluation.cost != pytest.approx(-0.6 * evaluation.distance + 0.4 * 0.22 ** 2, rel=1e-6)
    for k, step in ((0, 1e-5), (1, 1e-6), (2, 1e-4)):
        shift = step * np.eye(3)[k]
        central = (cost_value(prom, scene, space, z + shift, weights)
                   - cost_value(prom, scene, space, z - shift, weights)) / (2 * step)
        assert abs(evaluation.gradient[k] - central) < 1e-4 * abs(central), (k, evaluation.gradient[k], central)
    amplitude = scene_from_dict({"mesh": {"level": 1}, "cooptimization": {"enabled": True}}, source="<test>")
    assert amplitude.hash == scene_from_dict({"mesh": {"level": 1}, "cooptimization": {"enabled": True,
                                              "effort": "amplitude"}}, source="<test>").hash
