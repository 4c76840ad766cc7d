"""The measured tables of the README and the manual are those of the snapshot ``docs/data/``: every
figure a table quotes is in its source file, `make docs` has rewritten every table, every snapshot
file says where it came from, and a re-measurement copied in changes the table."""
import json
import re
import shutil
import sys
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY / "docs"))
import measured  # noqa: E402  (docs/measured.py makes the tables)


def page_text(name: str) -> str:
    return (REPOSITORY / name).read_text()


@pytest.mark.parametrize("page", measured.PAGES)
def test_every_figure_of_a_measured_table_is_in_its_source_file(page):
    problems = measured.unsupported_figures(page_text(page))
    assert not problems, (f"{page} quotes figures its snapshot file does not hold (table: figures): {problems}; "
                          "`make docs` rewrites the tables from docs/data/")


@pytest.mark.parametrize("page", measured.PAGES)
def test_every_measured_table_is_the_snapshots(page):
    text = page_text(page)
    assert measured.measured_blocks(text), f"{page} has no measured table"
    assert measured.render_page(text) == text, f"{page}: run `make docs` to rewrite its tables from docs/data/"


def test_every_table_is_on_a_page():
    shown = {name for page in measured.PAGES for name in measured.measured_blocks(page_text(page))}
    assert shown == set(measured.TABLES)


def test_a_figure_changed_by_hand_is_caught():
    text = page_text("README.md")
    body = measured.measured_blocks(text)["accuracy"]
    quoted = re.search(r"\| ([-+]\d+\.\d+) % \|", body).group(1)     # the first relative error of the table
    edited = text.replace(body, body.replace(f"| {quoted} % |", "| -9.87 % |", 1))
    assert edited != text and "9.87" not in body
    assert measured.unsupported_figures(edited) == {"accuracy": ["-9.87"]}


def test_every_snapshot_file_says_where_it_came_from():
    files = measured.snapshot_files()
    assert len(files) >= 10
    for path in files:
        record = json.loads(path.read_text()).get("_snapshot")
        assert record and record.get("date"), f"{path.name}: no _snapshot date"
        if record.get("transcribed"):
            assert record.get("source_page"), f"{path}: transcribed from which page?"
        else:
            assert record.get("copied_from") and record.get("host"), f"{path}: copied from where, on which host?"


def test_a_remeasurement_copied_into_the_snapshot_changes_the_table(tmp_path):
    snapshot = tmp_path / "data"
    shutil.copytree(measured.SNAPSHOT, snapshot)
    results = tmp_path / "results"
    (results / "bench").mkdir(parents=True)
    fom = json.loads((snapshot / "bench" / "fom.json").read_text())
    del fom["_snapshot"]
    fom["runs"] = [run | {"wall_time_simulation": 41.25} for run in fom["runs"] if run["level"] == 3][:1]
    (results / "bench" / "fom.json").write_text(json.dumps(fom))
    assert "41.2 s" not in measured.cost_table(snapshot)
    assert measured.refresh(results, snapshot, host="bench-host") == ["bench/fom.json"]
    record = json.loads((snapshot / "bench" / "fom.json").read_text())["_snapshot"]
    assert record["copied_from"] == "results/bench/fom.json" and record["host"] == "bench-host" and record["date"]
    table = measured.cost_table(snapshot)
    assert "| 41.2 s |" in table and "70.5" not in table
    assert "measured on bench-host" in table and "`bench/prom.json`" in table


def test_a_missing_snapshot_file_names_the_command_that_writes_it(tmp_path):
    with pytest.raises(measured.SnapshotError, match="scripts/validate.py --only stations"):
        measured.stations_table(tmp_path)


def test_the_trust_region_rows_join_the_studies_table_once_measured(tmp_path):
    """The studies table shows each case's trust-region run next to its paper run when its snapshot
    exists (scripts/study.py --methods trust-region writes <case>-trust-region/)."""
    shutil.copytree(measured.SNAPSHOT / "studies", tmp_path / "studies")
    shutil.rmtree(tmp_path / "studies" / "so2-trust-region", ignore_errors=True)
    before = measured.study_table(tmp_path)
    paper = json.loads((tmp_path / "studies" / "so2" / "summary.json").read_text())
    paper.update(method="trust-region", iterations=16, prom_builds=19)
    (tmp_path / "studies" / "so2-trust-region").mkdir()
    (tmp_path / "studies" / "so2-trust-region" / "summary.json").write_text(json.dumps(paper))
    after = measured.study_table(tmp_path)
    rows = [line for line in after.splitlines() if line.startswith("| SO2 |")]
    assert len(rows) == 2 and "| paper |" in rows[0] and "| trust-region |" in rows[1] and "19 (" in rows[1]
    assert len(after.splitlines()) == len(before.splitlines()) + 1
