"""`aquarom sweep` with [gait] variables: their columns, and rows equal to single runs at the design's gait
(the PROM to 1e-12, the FOM exactly) on the coarsest block's wave."""
import csv

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.scene_gait import apply_gait
from aquarom_fenics.studies import sweep

MUSCLES = "".join(f'[[muscles]]\nregion = "{side}_{k}"\nscale = {1.0 if side == "left" else -1.0}\n'
                  f'phase = {120.0 * (k - 1)}\n' for k in (1, 2, 3) for side in ("left", "right"))
SCENE = ('name = "gait-sweep"\n[mesh]\nlevel = 1\n[regions]\nmuscle_pairs = 3\n[solver]\nduration = {duration}\n'
         '[output]\nplots = false\nrender = false\n[shapes]\nz_tail = {{ bounds = [-0.2, 0.2] }}\n'
         '[gait]\nfrequency = {{ bounds = [0.5, 2.0] }}\nphase_lag = {{ bounds = [30.0, 180.0] }}\n') + MUSCLES


def write_scene(folder, duration=0.3):
    path = folder / "gait.toml"
    path.write_text(SCENE.format(duration=duration))
    return path


def read_csv(path):
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


def test_the_designs_span_the_gait_variables_named_as_in_the_scene(tmp_path):
    scene = Scene.load(write_scene(tmp_path))
    designs = sweep.grid_designs(["frequency=1:1.5:2", "phase_lag=60:120:2"], scene)
    assert designs[0] == {"z_tail": 0.0, "frequency": 1.0, "phase_lag": 60.0}
    assert {(d["frequency"], d["phase_lag"]) for d in designs} == {(1.0, 60.0), (1.0, 120.0), (1.5, 60.0), (1.5, 120.0)}
    assert sweep.columns(scene)[:4] == ["design", "z_tail", "frequency", "phase_lag"]
    for design in sweep.latin_hypercube(scene, 5, seed=1):
        assert 0.5 <= design["frequency"] <= 2.0 and 30.0 <= design["phase_lag"] <= 180.0
    table = tmp_path / "designs.csv"
    table.write_text("phase_lag,z_tail\n90,0.1\n")
    assert sweep.csv_designs(table, scene) == [{"z_tail": 0.1, "frequency": 1.0, "phase_lag": 90.0}]


def test_a_prom_sweep_row_of_a_gait_equals_a_single_reduced_run_at_that_gait(tmp_path, request):
    """The centre's designs are integrated together, each with its own gait's activations, and their rows are
    the single runs' answers to 1e-12."""
    path = write_scene(tmp_path)
    scene = Scene.load(path)
    prom = sweep.reduced_model(scene, {"z_tail": 0.02, "frequency": 1.0, "phase_lag": 60.0}, "prom")
    singles = [simulate_reduced(prom, apply_gait(scene, {"frequency": f, "phase_lag": 60.0}), np.array([0.02]))
               for f in (1.0, 1.4)]
    at_start = simulate_reduced(prom, scene, np.array([0.02]))
    request.getfixturevalue("no_single_reduced_runs")     # from here on, only the batched path may run
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "z_tail=0.02:0.02:1", "--grid", "frequency=1:1.4:2",
                 "--grid", "phase_lag=60:60:1", "--model", "prom", "--workers", "1", "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [row["status"] for row in rows] == ["completed"] * 2, [row["reason"] for row in rows]
    for row, single in zip(rows, singles):
        assert float(row["frequency"]) in (1.0, 1.4)
        assert abs(float(row["distance_m"]) - single.distance) <= 1e-12 * abs(single.distance)
        assert abs(float(row["tail_amplitude_m"]) - single.tail_amplitude) <= 1e-12 * single.tail_amplitude
    assert singles[0].distance != pytest.approx(singles[1].distance, rel=1e-3)     # the frequency moves the answer
    assert singles[0].distance != pytest.approx(at_start.distance, rel=1e-3)       # and so does the lag (60° vs 120°)


def test_a_fom_sweep_row_of_a_gait_is_the_fom_run_at_that_gait(tmp_path):
    path = write_scene(tmp_path, duration=0.1)
    scene = Scene.load(path)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "phase_lag=60:60:1", "--model", "fom", "--workers", "1",
                 "--out", str(out)]) == 0
    [row] = read_csv(out / "sweep.csv")
    assert row["status"] == "completed", row["reason"]
    run = simulate_fom(apply_gait(scene, {"phase_lag": 60.0}), {"z_tail": 0.0})
    assert float(row["distance_m"]) == run.distance and float(row["tail_amplitude_m"]) == run.tail_amplitude
    assert run.distance != pytest.approx(simulate_fom(scene, {"z_tail": 0.0}).distance, rel=1e-6)


def test_a_gait_the_scene_refuses_is_a_refused_row(tmp_path):
    """An amplitude beyond the fibre stiffness or a period of too few steps is refused by apply_gait: a row."""
    path = write_scene(tmp_path)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "frequency=20:20:1", "--model", "prom", "--workers", "1",
                 "--out", str(out)]) == 0
    [row] = read_csv(out / "sweep.csv")
    assert row["status"] == "refused" and "time step" in row["reason"]


def test_a_scene_of_gait_variables_alone_sweeps_with_one_prom(tmp_path):
    path = tmp_path / "gait_only.toml"
    path.write_text(SCENE.format(duration=0.2).replace("[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n", ""))
    scene = Scene.load(path)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "phase_lag=60:120:2", "--model", "prom", "--workers", "1",
                 "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [row["status"] for row in rows] == ["completed"] * 2, [row["reason"] for row in rows]
    assert {row["prom_center"] for row in rows} == {"0"}
    prom = sweep.reduced_model(scene, {"frequency": 1.0, "phase_lag": 120.0}, "prom")
    single = simulate_reduced(prom, apply_gait(scene, {"phase_lag": 60.0}), np.zeros(0))
    assert abs(float(rows[0]["distance_m"]) - single.distance) <= 1e-12 * abs(single.distance)


def test_a_rom_sweep_row_of_a_gait_is_the_rom_run_at_that_gait(tmp_path):
    path = write_scene(tmp_path, duration=0.2)
    scene = Scene.load(path)
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "frequency=1.3:1.3:1", "--grid", "phase_lag=90:90:1", "--model", "rom",
                 "--workers", "1", "--out", str(out)]) == 0
    [row] = read_csv(out / "sweep.csv")
    assert row["status"] == "completed", row["reason"]
    rom = sweep.reduced_model(scene, {"z_tail": 0.0, "frequency": 1.3, "phase_lag": 90.0}, "rom")
    single = simulate_reduced(rom, apply_gait(scene, {"frequency": 1.3, "phase_lag": 90.0}), np.zeros(0))
    assert abs(float(row["distance_m"]) - single.distance) <= 1e-12 * abs(single.distance)
    assert single.distance != pytest.approx(simulate_reduced(rom, scene, np.zeros(0)).distance, rel=1e-3)
