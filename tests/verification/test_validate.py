"""`make validate` (aquarom_fenics.verification.validation): quick stress cases, the case cache and the
report writer."""
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.studies.estimate import power_law_fit
from aquarom_fenics.verification.validation.cases import fom_case, reduced_case
from aquarom_fenics.verification.validation.figures import make_figures
from aquarom_fenics.verification.validation.report import write_report
from aquarom_fenics.verification.validation.report_format import FIGURES
from aquarom_fenics.verification.validation.runner import (CaseTimeLimit, Runner, compute_in_parallel,
                                                           with_time_limit)
from aquarom_fenics.verification.validation.settings import QUICK
from aquarom_fenics.verification.validation.stability import stress_scenes
from aquarom_fenics.verification.validation.suite import STUDIES

CHEAP_STRESS = ("h-0.1", "alpha-0", "soft", "stiffness-5x")
"""The stress cases cheap enough for the test suite (level 1, 0.3 s horizon)."""

TIME_LIMIT = 60.0
"""Seconds per case: a hang ends as a 'time-limit' record, never as a stuck test."""


@pytest.fixture(scope="module")
def runner(tmp_path_factory):
    return Runner(tmp_path_factory.mktemp("validation"), time_limit=TIME_LIMIT)


def stress_scene(case_id):
    scenes = {case: scene for case, _, scene in stress_scenes(QUICK, level=1, duration=0.3)}
    return scenes[case_id]


def assert_clean(record):
    """Converged with finite numbers, or stopped with a SolverError message naming the time."""
    assert record["status"] in ("completed", "stopped"), f"{record['status']}: {record.get('message')}"
    if record["status"] == "stopped":
        assert "t = " in record["message"], record["message"]
        return
    for key in ("distance", "tail_amplitude", "head_x_final"):
        assert math.isfinite(record[key]), key
    assert np.all(np.isfinite(record["trajectory"]["head_x"]))
    assert record["newton"]["max"] >= 1


@pytest.mark.parametrize("case_id", CHEAP_STRESS)
def test_stress_case_fom_is_clean_with_energy_balance(runner, case_id):
    started = time.perf_counter()
    record = runner.compute(fom_case(f"stress {case_id}", stress_scene(case_id), energy=True))
    assert time.perf_counter() - started < TIME_LIMIT + 5
    assert_clean(record)
    energy = record["energy"]
    if record["cut_steps"]:
        assert energy == {"available": False, "message": energy["message"]} and "cut" in energy["message"]
    elif record["status"] == "completed":
        assert energy["available"]
        assert all(math.isfinite(energy[key]) for key in ("work_actuation", "work_thrust", "dissipated_rayleigh",
                                                           "dissipated_numerical", "kinetic_change", "strain_change"))
        assert energy["throughput"] > 0
        assert energy["work_thrust"] == pytest.approx(energy["work_thrust_acceleration"]
                                                      + energy["work_thrust_velocity"])
        # The balance at the scheme's evaluation points closes, with the numerical dissipation as its own term.
        assert abs(energy["relative_imbalance"]) < 5e-3, energy
        assert energy["dissipated_rayleigh"] > 0 and energy["work_actuation"] != 0
        series = energy["series"]
        assert len(series["time"]) == len(series["work"]) == len(series["stored"])
        assert series["dissipated_numerical"][-1] == pytest.approx(energy["dissipated_numerical"])


@pytest.mark.parametrize("case_id", CHEAP_STRESS)
def test_stress_case_rom_is_clean(runner, case_id):
    record = runner.compute(reduced_case(f"stress {case_id} ROM", stress_scene(case_id), parametric=False))
    assert_clean(record)
    assert record["finite_tensors"]


def test_alpha_zero_has_no_numerical_dissipation(runner):
    """Newmark with γ = ½, β = ¼ conserves energy: its numerical dissipation is zero up to O(Δu³); the
    default generalized-α at the same h = 0.02 s removes more. (At h = 0.05 s, 6 steps of the 0.3 s run,
    the O(h²) error of the thrust's trapezoidal work outweighs the scheme's dissipation: -0.28 % of the
    actuation's work through the stations.)"""
    record = runner.compute(fom_case("alpha 0", stress_scene("alpha-0"), energy=True))
    assert record["status"] == "completed"
    assert abs(record["energy"]["numerical_dissipation_relative"]) < 5e-3
    damped = runner.compute(fom_case("reference", stress_scene("reference"), energy=True))
    assert damped["energy"]["numerical_dissipation_relative"] > abs(record["energy"]["numerical_dissipation_relative"])


def test_time_limit_stops_a_hang():
    with pytest.raises(CaseTimeLimit):
        with_time_limit(0.2, lambda: time.sleep(5))


def test_time_limit_reached_inside_a_finaliser_still_stops_the_case():
    """An alarm that comes while a ``__del__`` runs raises there, where Python only reports it: the limit is
    raised again by the next alarm, not lost (the case would otherwise run to its end)."""
    class SlowFinaliser:
        def __del__(self):
            time.sleep(0.3)                  # the 0.1 s alarm comes in here

    def case():
        SlowFinaliser()
        time.sleep(2.0)
        return "ran to the end"

    started = time.perf_counter()
    with pytest.raises(CaseTimeLimit):
        with_time_limit(0.1, case)
    assert time.perf_counter() - started < 1.0


def test_case_over_its_time_limit_is_reported_not_cached(tmp_path):
    runner = Runner(tmp_path, time_limit=1e-3, stream=open("/dev/null", "w"))
    case = fom_case("too slow", stress_scene("alpha-0"))
    [record] = runner.run("t", [case])
    assert record["status"] == "time-limit" and "time limit" in record["message"]
    assert not (tmp_path / "cases" / case.file_name).exists()


def test_cases_are_cached_by_key(tmp_path):
    output = tmp_path / "progress.txt"
    with open(output, "w") as stream:
        scene = stress_scene("reference").replace("solver", duration=0.2)
        case = reduced_case("ROM", scene, parametric=False)
        first = Runner(tmp_path, time_limit=TIME_LIMIT, stream=stream).run("t", [case])
        again = Runner(tmp_path, time_limit=TIME_LIMIT, stream=stream)
        second = again.run("t", [case])
    assert again.counts["cached"] == 1 and again.counts["computed"] == 0
    assert second[0]["distance"] == first[0]["distance"]
    assert (tmp_path / "cases" / f"reduced-{case.key}.json").exists()
    other = reduced_case("ROM", scene.replace("actuation", stiffness=3e4), parametric=False)
    assert other.key != case.key
    text = output.read_text()
    assert "[t 1/1] ROM: computing" in text and "[t 1/1] ROM: cached" in text


def test_missing_cases_computed_in_parallel_workers(tmp_path):
    scene = stress_scene("reference").replace("solver", duration=0.2)
    cases = [reduced_case("ROM", scene, parametric=False),
             reduced_case("ROM k=30 kPa", scene.replace("actuation", stiffness=3e4), parametric=False)]
    runner = Runner(tmp_path, time_limit=TIME_LIMIT, stream=open("/dev/null", "w"))
    assert compute_in_parallel(runner, cases + cases[:1], jobs=2) == 2
    assert runner.computed_elsewhere == {case.key for case in cases}
    records = runner.run("t", cases)
    assert [r["status"] for r in records] == ["completed", "completed"]
    assert all(r["concurrent_jobs"] == 2 for r in records)
    assert runner.counts == {"cached": 0, "computed": 2, "not cached (time limit or crash)": 0}


def test_cases_computed_on_dask_equal_those_of_local_workers(tmp_path, dask_cluster):
    """`make validate --scheduler`: the missing cases on a LocalCluster's workers, the same records."""
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.parallel import ClusterSettings, DaskCluster

    scene = stress_scene("reference").replace("solver", duration=0.2)
    cases = [reduced_case("ROM", scene, parametric=False),
             reduced_case("ROM k=30 kPa", scene.replace("actuation", stiffness=3e4), parametric=False)]
    records = {}
    for backend in ("local", "dask"):
        runner = Runner(tmp_path / backend, time_limit=TIME_LIMIT, stream=open("/dev/null", "w"))
        pool = DaskCluster(ClusterSettings(scheduler=dask_cluster.scheduler_address), SWIMMER_WORKERS) if backend == "dask" else None
        try:
            assert compute_in_parallel(runner, cases, jobs=2, pool=pool) == 2
        finally:
            if pool is not None:
                pool.shutdown()
        assert runner.computed_elsewhere == {case.key for case in cases}
        records[backend] = runner.run("t", cases)
    for local, dask in zip(records["local"], records["dask"], strict=True):
        assert local["status"] == dask["status"] == "completed" and local["distance"] is not None
        assert (local["distance"], local["tail_amplitude"]) == (dask["distance"], dask["tail_amplitude"])


def test_power_law_fit():
    cells = np.array([1e3, 4e3, 8e3, 16e3])
    fit = power_law_fit(cells, 2e-3 * cells ** 1.1)
    assert fit["exponent"] == pytest.approx(1.1) and fit["prefactor"] == pytest.approx(2e-3)
    assert power_law_fit([1e3], [1.0]) is None


# ---------------------------------------------------------------------------------------------
# Report writer on a synthetic results folder


def _trajectory(scale, n=21):
    time_values = np.linspace(0.0, 0.4, n)
    return time_values, scale * time_values ** 2


def synthetic_results(folder: Path):
    """Minimal study files like validate.py writes, with one FOM that stopped and one case above 10%."""
    folder.mkdir(parents=True, exist_ok=True)
    levels, stiffnesses = [1, 2], [1.2e4, 6e4]
    cells = {"1": 1232, "2": 4176}
    model_labels = {"rom": "ROM", "rom-paper": "ROM, source's basis", "prom3": "PROM, p = 3"}
    rows = []
    for level in levels:
        for k in stiffnesses:
            stopped = level == 2 and k == 6e4
            fom = {"status": "stopped" if stopped else "completed",
                   "message": "Newton did not converge at t = 0.3 s (step 15 of 20)" if stopped else None,
                   "distance": None if stopped else 0.01 * k / 6e4, "tail_amplitude": None if stopped else 0.02 * k / 6e4,
                   "wall_time": 1.0 * level, "setup_time": 0.1 * level, "solve_time": 0.9 * level,
                   "stopped_at": 0.28 if stopped else 0.4, "newton": {"mean": 4.5, "max": 6, "total": 90}}
            models = {}
            for index, model in enumerate(model_labels):
                error = None if stopped else (0.15 if model == "rom-paper" else 0.01 * (index + 1))
                models[model] = {"status": "completed", "distance": 0.01, "tail_amplitude": 0.02,
                                 "build_time": 0.2 * level * (index + 1), "build_basis": 0.05 * level,
                                 "build_tensors": 0.1 * level * (index + 1), "build_rest": 0.05,
                                 "solve_time": 0.1, "solve_time_sensitivities": 0.15 if model.startswith("prom") else None,
                                 "size": 5 + index, "distance_error_relative": error,
                                 "distance_error_absolute": None if error is None else error * 0.01,
                                 "tail_amplitude_error_relative": None if error is None else error / 2,
                                 "tail_amplitude_error_absolute": None if error is None else error * 0.01}
            rows.append({"level": level, "stiffness": k, "cells": cells[str(level)], "fom": fom, "models": models})
    a = {"study": "a", "levels": levels, "stiffnesses": stiffnesses, "cells": cells, "reference_level": 1,
         "reference_stiffness": 6e4, "duration": 0.4, "models": model_labels, "rows": rows}
    series = {"FOM": {"build": [[1232, 0.1], [4176, 0.2]], "solve": [[1232, 0.9], [4176, 1.8]]}}
    fits = [{"model": "FOM", "quantity": "build", "exponent": 0.57, "prefactor": 1e-3, "points": 2}]
    for model in model_labels:
        series[model] = {"build": [[1232, 0.2], [4176, 0.4]], "build: basis": [[1232, 0.05], [4176, 0.1]],
                         "build: tensors": [[1232, 0.1], [4176, 0.2]], "build: rest": [[1232, 0.05], [4176, 0.05]],
                         "solve": [[1232, 0.1], [4176, 0.1]]}
        fits += [{"model": model, "quantity": "build", "exponent": 0.57, "prefactor": 1e-3, "points": 2},
                 {"model": model, "quantity": "solve", "exponent": 0.0, "prefactor": 0.1, "points": 2}]
    b = {"study": "b", "stiffness": 6e4, "models": {"FOM": "FOM"} | model_labels, "series": series, "fits": fits,
         "settings": {"duration": 0.4}}
    points = []
    for index, (point_id, family) in enumerate((("fom-h0.02", "FOM"), ("basis-source", "basis"),
                                                ("basis-default", "basis"), ("rom-h0.01", "time step"),
                                                ("taylor1", "Taylor order"))):
        points.append({"id": point_id, "label": point_id, "short": point_id, "family": family,
                       "default": point_id == "basis-default", "time_step": 0.02, "status": "completed",
                       "wall_time": 0.1 * (index + 1), "build_time": 0.05, "solve_time": 0.05, "size": 5,
                       "distance": 0.01, "distance_error_relative": 0.1 / (index + 1)})
    c = {"study": "c", "level": 1, "stiffness": 6e4, "reference_time_step": 0.005,
         "taylor_design": {"y_thin": 0.0375}, "reference": {"distance": 0.01, "wall_time": 2.0}, "points": points}
    time_values, values = _trajectory(1e-4, 21)
    d = {"study": "d", "level": 1, "time_steps": [0.02, 0.01, 0.005], "grid_step": 0.02, "quantities": [
        {"name": "FOM head x, α_N = 0.02", "newmark_alpha": 0.02, "status": "completed", "differences": [4e-5, 2e-5],
         "ratios": [2.0], "ratio": 2.0, "pairs": ["0.02–0.01", "0.01–0.005"]},
        {"name": "FOM head x, α_N = 0", "newmark_alpha": 0.0, "status": "completed",
         "differences": [4e-5, 1e-5, 2.5e-6], "ratios": [4.0, 3.9], "window_ratios": [4.0], "finest_ratio": 3.9,
         "ratio": 4.0, "pairs": ["0.02–0.01", "0.01–0.005", "0.005–0.0025"], "time": time_values.tolist(),
         "difference_series": [values.tolist(), (values / 4).tolist(), (values / 15.6).tolist()]},
        {"name": "ROM head x, α_N = 0", "newmark_alpha": 0.0, "status": "completed",
         "differences": [4e-5 / 4 ** k for k in range(6)], "ratios": [4.0] * 5, "window_ratios": [4.0, 4.0],
         "finest_ratio": 4.0, "ratio": 4.0, "pairs": [f"{0.02 / 2 ** k:g}–{0.01 / 2 ** k:g}" for k in range(6)],
         "time": time_values.tolist(), "difference_series": [(values / 4 ** k).tolist() for k in range(6)]},
        {"name": "d head x / d ξ[y_thin] (PROM p=3)", "status": "completed", "differences": [4e-4, 1.1e-4],
         "ratios": [3.6], "ratio": 3.6, "pairs": ["0.02–0.01", "0.01–0.005"], "time": time_values.tolist(),
         "difference_series": [values.tolist(), (values / 3.6).tolist()]}]}
    e = {"study": "e", "levels": [1], "runs": [
        {"level": 1, "ranks": 1, "status": "completed", "cells": 1232, "wall_time": 2.0, "distance": 0.01},
        {"level": 1, "ranks": 2, "status": "completed", "cells": 1232, "wall_time": 1.2, "distance": 0.01}],
         "comparisons": [{"level": 1, "cells": 1232, "speedup": 1.67, "distance_relative_difference": 1e-14,
                          "head_x_max_difference": 1e-17, "compared_until": 0.4}]}
    energy_series = {"time": time_values.tolist(), "work": values.tolist(),
                     "dissipated_rayleigh": (0.3 * values).tolist(), "dissipated_numerical": (0.01 * values).tolist(),
                     "stored": (0.69 * values).tolist()}
    energy = {"available": True, "work_actuation": 1e-3, "work_thrust": -1e-4, "work_thrust_acceleration": -2e-4,
              "work_thrust_velocity": 1e-4, "work_drag": -1e-6, "throughput": 2e-3, "dissipated_rayleigh": 3e-4,
              "dissipated_numerical": 1e-5, "kinetic_change": 1e-4, "strain_change": 5e-4, "newton_residual": 1e-12,
              "imbalance": 1e-12, "relative_imbalance": 5e-10, "numerical_dissipation_relative": 5e-3,
              "series": energy_series}
    stress = {"study": "stress", "level": 1, "duration": 0.4, "energy_note": "synthetic", "rows": [
        {"id": "h-0.1", "description": "time step h = 0.1 s", "model": "FOM", "status": "completed", "clean": True,
         "distance": 0.01, "newton": {"mean": 10.0, "max": 17}, "wall_time": 0.5, "energy": energy},
        {"id": "stiffness-5x", "description": "actuation stiffness 5×", "model": "FOM", "status": "stopped",
         "message": "Newton did not converge at t = 1.2 s", "clean": True, "newton": {"mean": 9.0, "max": 30},
         "wall_time": 3.0, "energy": {"available": False, "message": "not available: the run cut 2 steps"}}]}
    run = {"date": "2026-01-01 00:00:00", "versions": {"dolfinx": "0.5.2"}, "machine": {"cores": 2, "cpu": "test CPU"},
           "quick": True, "studies": list(STUDIES), "cases": {"cached": 3, "computed": 4}, "wall_time": 42.0}
    from aquarom_fenics.verification.convergence import MeshCase, mesh_convergence

    quadratic = [MeshCase(2, level, cells, 5 * cells, 0.045 - 3.0 / cells, 0.03, 5.8, 0.027, 1e-3, 10.0 * level)
                 for level, cells in ((1, 1232), (2, 4176), (3, 7944))]
    mesh = mesh_convergence(quadratic + [MeshCase(1, 3, 7944, 6015, 0.034, 0.026, 6.4, 0.0226, 1e-3, 9.0)]) | {"failed": []}
    for name, data in (("a", a), ("b", b), ("c", c), ("d", d), ("e", e), ("stress", stress),
                       ("mesh_convergence", mesh), ("run", run)):
        (folder / f"{name}.json").write_text(json.dumps(data))


def test_report_writer_on_synthetic_results(tmp_path):
    out = tmp_path / "validation"
    synthetic_results(out)
    (tmp_path / "studies").mkdir()
    (tmp_path / "studies" / "summary.md").write_text("# Studies\n\n| study | ratio |\n|---|---|\n| so1 | 1.2 |\n\n"
                                                     "![cost](so1/cost.png)\n")
    figures = make_figures(out)
    assert {path.name for path in figures} == set(FIGURES.values())
    report = write_report(out, tmp_path / "REPORT.md")
    text = report.read_text()
    for section in ("## Checks", "## a. ", "## b. ", "## c. ", "## d. ", "## e. ", "## Stress tests",
                    "### Energy balance", "## Mesh convergence of the FOM", "## Optimisation studies", "## Reproduce"):
        assert section in text, section
    for name in FIGURES.values():
        assert f"](validation/{name})" in text, name
        assert (out / name).stat().st_size > 10_000, name
    assert "2 cores" in text and "dolfinx 0.5.2" in text
    assert "Newton did not converge at t = 0.3 s" in text          # the stopped FOM is listed, not dropped
    assert "| ROM, source's basis | 1 | 1232 | 12 |" in text          # the case above 10%, with cells and k
    assert "](studies/so1/cost.png)" in text and "| so1 | 1.2 |" in text
    assert "**FAIL**" not in text.split("## a.")[0]                 # synthetic numbers meet every check
    assert "| time-step ratios, FOM head x, α_N = 0.02 | 2.00 | → 2 (first order: γ = ½ + α_N) | — |" in text
    assert "| time-step ratios, FOM head x, α_N = 0 | 4.00 (finest pair 0.005–0.0025 s: 3.90) | 3.5–4.5 | pass |" in text
    assert "| 1 | 3 | 7944 | 6015 | 3.4 | -24." in text                      # degree-1 row against the reference
    assert "within 3 % of the reference distance: degree 2, level 2" in text
    assert "| h-0.1 | 1 | -0.1 | -0.001 | 2 | 0.3 | 0.01 | 0.1 | 0.5 | +0.500% | +5.0e-08% |" in text
    assert "| stiffness-5x | — | — | — | — | — | — | — | — | not available | not available |" in text


def test_report_without_results_says_what_is_missing(tmp_path):
    text = write_report(tmp_path / "validation", tmp_path / "REPORT.md").read_text()
    assert text.count("*Not run yet*") == len(STUDIES)


def test_energy_balance_of_a_run_with_cut_steps_is_not_available():
    from types import SimpleNamespace

    from aquarom_fenics.verification.validation.compute import energy_record

    record = energy_record(SimpleNamespace(cut_steps=2))
    assert record == {"available": False, "message": record["message"]}
    assert "not available" in record["message"] and "2 steps" in record["message"]


def test_successive_differences_over_the_last_stroke_leave_out_the_start_transient():
    """q_h(t) = h² sin t + (start-up ringing that does not converge, t < 1 s): over the whole run the
    ratios stall near 1, over t ≥ 1 s they are those of the h² error, 4."""
    from aquarom_fenics.verification.validation.convergence_studies import convergence

    time = np.linspace(0.0, 2.0, 101)
    steps = [0.02, 0.01, 0.005, 0.0025]
    ringing = [1e-4 * np.cos(40 * time + k) * (time < 1.0) for k in range(len(steps))]
    values = [h ** 2 * np.sin(time) + ring for h, ring in zip(steps, ringing)]
    entry = convergence("q", values, time, steps, len(steps), {}, last_stroke_start=1.0)
    assert min(entry["window_ratios"]) < 2.0
    assert entry["last_stroke_window_ratios"] == pytest.approx([4.0, 4.0], rel=1e-6)
    assert "last_stroke_window_ratios" not in convergence("q", values, time, steps, len(steps), {})


def test_an_mpi_case_computed_again_replaces_its_earlier_attempt(runner):
    """Study e's case writes `aquarom simulate --out` into its own folder; computing the case again
    (after a crash, the time limit, or a removed record) must not stop at that folder."""
    import shutil

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    from aquarom_fenics.verification.validation.cases import mpi_case
    from aquarom_fenics.verification.validation.settings import base_scene

    scene = base_scene(QUICK, level=1).replace("solver", duration=0.1)
    case = mpi_case("mpirun -n 1 FOM L1, 0.1 s", scene, ranks=1)
    records = [runner.compute(case) for _ in range(2)]
    for record in records:
        assert record["status"] == "completed", record.get("message")
    assert records[0]["distance"] == records[1]["distance"]
