"""`aquarom pareto` with [gait] variables: the weights' front runs the trust region over [shapes, A, gait]
(a tiny one on the coarsest block's wave), and pareto.csv names the amplitude and the gait's columns."""
import csv
import json

import pytest

from aquarom_fenics.cli import main

MUSCLES = "".join(f'[[muscles]]\nregion = "{side}_{k}"\nscale = {1.0 if side == "left" else -1.0}\n'
                  f'phase = {120.0 * (k - 1)}\n' for k in (1, 2, 3) for side in ("left", "right"))
SCENE = ('name = "gait-front"\n[mesh]\nlevel = 1\n[regions]\nmuscle_pairs = 3\n[solver]\nduration = 0.3\n'
         '[output]\nplots = false\nrender = false\n[optimizer]\nmethod = "trust-region"\nmax_iterations = 1\n'
         '[cooptimization]\nenabled = true\namplitude_bounds = [0.05, 0.3]\nweights = [0.2, 0.98]\n'
         'energy_weight = 0.01\n[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n'
         '[gait]\nphase_lag = { bounds = [30.0, 180.0] }\n') + MUSCLES


def test_the_weights_front_runs_with_gait_variables_and_names_their_columns(tmp_path, capsys):
    path = tmp_path / "front.toml"
    path.write_text(SCENE)
    out = tmp_path / "out"
    assert main(["pareto", str(path), "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "pareto.csv").open()))
    assert [float(row["w1"]) for row in rows] == [0.2, 0.98]
    assert {"amplitude", "xi_z_tail", "gait_phase_lag"} <= set(rows[0]) and "xi_amplitude" not in rows[0]
    for row in rows:
        summary = json.loads((out / f"w1_{float(row['w1']):g}" / "summary.json").read_text())
        assert float(row["amplitude"]) == summary["optimum"]["amplitude"]
        assert float(row["gait_phase_lag"]) == summary["optimum"]["phase_lag"]
        assert 30.0 <= float(row["gait_phase_lag"]) <= 180.0 and row["fom_check"] == "completed"
        history = list(csv.DictReader((out / f"w1_{float(row['w1']):g}" / "history.csv").open()))
        assert "gait_phase_lag" in history[0] and "xi_phase_lag" not in history[0]
    assert float(rows[0]["amplitude"]) < float(rows[1]["amplitude"])     # the effort's weight lowers A


@pytest.mark.parametrize("change, extra, message", [
    ((), ["--budgets", "0.1,0.2"], "--budgets"),
    (('method = "trust-region"', 'method = "paper"'), [], 'method = "paper" with [gait]'),
    (("180.0] }\n", "180.0] }\namplitude_1 = { bounds = [0.1, 0.3] }\n"), [], "amplitude_1 with [cooptimization]"),
])
def test_what_cannot_take_gait_variables_is_refused_in_one_line(tmp_path, capfd, change, extra, message):
    path = tmp_path / "front.toml"
    path.write_text(SCENE.replace(*change) if change else SCENE)
    assert main(["pareto", str(path), *extra, "--out", str(tmp_path / "out")]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
