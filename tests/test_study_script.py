"""`make study`'s table: one row per case from its summary.json, the rows of separate invocations gathered."""
import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location("study_script", REPOSITORY / "scripts" / "study.py")
study = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(study)

SCENE = SimpleNamespace(mesh=SimpleNamespace(degree=2, level=2))
FISH = SimpleNamespace(mesh=SimpleNamespace(cells=np.zeros((4176, 4))))


def summary(optimal_distance):
    return {"optimum": {"z_tail": -0.5, "y_thin": 0.15}, "prom_size": 17, "prom_builds": 4,
            "prom_builds_reused_from_cache": 1, "timings": {"total": 60.04, "fom_check": 95.5},
            "time_per_build": 3.25, "bounds_active": ["z_tail ≥ -0.5"], "converged": True, "iterations": 12,
            "fom_check": {"start_distance": 0.045, "optimal_distance": optimal_distance,
                          "ratio": None if optimal_distance is None else optimal_distance / 0.045}}


def test_a_row_gives_mesh_times_optimum_and_ratio_and_the_case_time_only_when_given():
    cells = [cell.strip() for cell in study._row("so1", SCENE, FISH, summary(0.09), 171.26).split("|")[1:-1]]
    assert cells[:10] == ["so1", "P2 level 2", "2", "4176", "17", "4 (1)", "60.0", "95.5", "171.3", "3.25"]
    assert cells[10:] == ["z_tail -0.500, y_thin +0.150", "z_tail ≥ -0.5", "optimal (12)", "1", "4.500", "9.000", "2.00"]
    assert study._row("co w1=0.5", SCENE, FISH, summary(None), None).split("|")[9].strip() == ""


def test_the_summary_gathers_every_case_folder_with_co_last_and_names_stopped_fom_runs(tmp_path):
    for case, row in (("so3", "| so3 | a |"), ("co", "| co w1=0.2 | stopped |\n| co w1=0.5 | b |"), ("so1", "| so1 | c |")):
        (tmp_path / case).mkdir()
        (tmp_path / case / study.ROWS).write_text(row + "\n")
    lines = study.summary_lines(tmp_path)
    rows = [line for line in lines if line.startswith("| ") and not line.startswith("| case")]
    assert [row.split("|")[1].strip() for row in rows] == ["so1", "so3", "co w1=0.2", "co w1=0.5"]
    assert any("did not converge" in line for line in lines)


def test_each_method_has_its_own_case_folder_and_rows(tmp_path, monkeypatch):
    """`--methods paper trust-region` runs every case once per optimiser, into <case>/ and
    <case>-trust-region/, the trust region's rows after the paper method's and CO's sweeps last."""
    assert study.case_folder("so1", "paper") == "so1"
    assert study.case_folder("so1", "trust-region") == "so1-trust-region"
    ran = []
    monkeypatch.setattr(study, "run_case", lambda args, pool, case, method: ran.append((case, method)))
    (tmp_path / "summary.md").write_text("")
    study.run_cases(SimpleNamespace(cases=["so1", "co"], methods=["paper", "trust-region"], out=tmp_path), None)
    assert ran == [("so1", "paper"), ("so1", "trust-region"), ("co", "paper"), ("co", "trust-region")]
    for folder in ("co-trust-region", "so1-trust-region", "co", "so1"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / study.ROWS).write_text(f"| {folder} | x |\n")
    rows = [line.split("|")[1].strip() for line in study.summary_lines(tmp_path)
            if line.startswith("| ") and not line.startswith("| case")]
    assert rows == ["so1", "so1-trust-region", "co", "co-trust-region"]
