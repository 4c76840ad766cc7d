"""The shipped fish's mesh convergence in `make validate`: its cases and its report section."""
import json
from dataclasses import asdict

import pytest

from aquarom_fenics.geometry.fish_recipe import shipped_fish_path
from aquarom_fenics.verification.convergence import MeshCase
from aquarom_fenics.verification.validation.convergence_studies import study_fish_mesh_convergence
from aquarom_fenics.verification.validation.report import write_report
from aquarom_fenics.verification.validation.runner import CasesCollected, Runner
from aquarom_fenics.verification.validation.settings import FULL, QUICK
from aquarom_fenics.verification.validation.suite import STUDIES


def test_make_validate_runs_the_fish_on_its_four_shipped_levels_at_degree_2(tmp_path):
    assert "fish_mesh_convergence" in STUDIES
    runner = Runner(tmp_path, collect=True)
    with pytest.raises(CasesCollected):
        study_fish_mesh_convergence(runner, FULL)
    scenes = [case.scene for case in runner.collected]
    assert [scene.mesh_file for scene in scenes] == [shipped_fish_path(level).resolve() for level in (1, 2, 3, 4)]
    assert all(case.kind == "mesh" for case in runner.collected)
    assert all(scene.mesh.degree == 2 and scene.solver.duration == 2.0 for scene in scenes)
    assert len({case.key for case in runner.collected}) == 4
    assert len(QUICK.fish_levels) >= 3        # Richardson needs three levels


def fish_study(distances, tmp_path):
    """The study as `make validate` computes it, from cached records with these distances."""
    records = [MeshCase(2, level, cells, 5 * cells, distance, 0.045, 3.0, 0.02, 1e-3, 10.0 * level)
               for level, (cells, distance) in enumerate(zip((1868, 3488, 6516, 11844), distances), start=1)]

    class Recorded(Runner):
        def run(self, study, cases):
            return [{"status": "completed", "label": case.label} | asdict(record) for case, record in zip(cases, records)]

    return json.loads(json.dumps(study_fish_mesh_convergence(Recorded(tmp_path), FULL)))


def report_text(tmp_path, study) -> str:
    out = tmp_path / "validation"
    out.mkdir()
    (out / "fish_mesh_convergence.json").write_text(json.dumps(study))
    return write_report(out, tmp_path / "REPORT.md").read_text()


def test_report_passes_a_fish_series_converging_within_1_percent(tmp_path):
    reference = 0.074
    text = report_text(tmp_path, fish_study([reference * (1 + 0.3 * (1868 / cells) ** (2 / 3) * 0.05)
                                             for cells in (1868, 3488, 6516, 11844)], tmp_path))
    assert "## Mesh convergence of the shipped fish" in text
    assert "| fish: estimated error of the reference distance |" in text
    section = text.split("## Mesh convergence of the shipped fish")[1]
    assert "| 4 | 11844 |" in section
    checks = [line for line in text.splitlines() if line.startswith("| fish:")]
    assert len(checks) == 2 and all(line.endswith("| pass |") for line in checks), checks


def test_report_fails_a_fish_series_whose_finest_level_is_far_from_its_reference(tmp_path):
    # errors 40 %, 21 %, 11 %, 6 % (∝ 1/cells): the finest level is 6 % off the extrapolated distance
    distances = [0.074 * (1 + 0.4 * (1868 / cells)) for cells in (1868, 3488, 6516, 11844)]
    text = report_text(tmp_path, fish_study(distances, tmp_path))
    checks = [line for line in text.splitlines() if line.startswith("| fish:")]
    assert any(line.endswith("| **FAIL** |") for line in checks), checks


def test_a_series_without_an_order_takes_the_finest_level_and_the_spread_of_the_three_finest(tmp_path):
    """The shipped fish measured (recipe 2, 2 s): differences 0.045, 0.0021, 0.0021 cm show no order."""
    study = fish_study([0.073488, 0.073036, 0.073015, 0.072994], tmp_path)
    assert study["reference"]["distance"]["value"] is None
    reference = study["distance_reference"]
    assert reference["value"] == 0.072994
    assert reference["estimated_error"] == pytest.approx(0.073036 - 0.072994, rel=1e-12)
    assert study["rows"][0]["distance_error"] == pytest.approx(0.073488 / 0.072994 - 1, rel=1e-12)
    checks = [line for line in report_text(tmp_path, study).splitlines() if line.startswith("| fish:")]
    assert len(checks) == 2 and all(line.endswith("| pass |") for line in checks), checks
    assert "spread of the three finest levels" in checks[0]
