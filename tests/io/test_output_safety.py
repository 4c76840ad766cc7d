"""Outputs are never lost: --force, refused inputs, OS errors, Ctrl-C, concurrent cache writers."""
import errno
import json
import re
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.optimization import history
from aquarom_fenics.io import outputs as outputs_module
from aquarom_fenics.io import tables as tables_module
from aquarom_fenics.io import persistence as persistence_module
from aquarom_fenics.cli import main

from conftest import one_line, write_short_scene as write_scene

OPTIMIZE = """
[mesh]
level = 1
[solver]
duration = 0.4
[fluid]
drag = false
[optimizer]
max_iterations = 3
[shapes]
z_tail = {{ bounds = [-0.2, 0.2] }}
y_thin = {{ bounds = [-0.1, 0.1] }}
{extra}
"""


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def simulate(scene, out, *extra) -> int:
    return main(["simulate", scene, "--out", str(out), "--no-progress", *extra])


# ---------------------------------------------------------------------- data loss, case 1
def test_force_refuses_a_folder_the_toolkit_did_not_write(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)
    work = tmp_path / "p"
    work.mkdir()
    (work / "thesis.tex").write_text("x")
    monkeypatch.chdir(work)
    assert simulate(scene, ".", "--force") == 2
    assert "did not write (thesis.tex)" in one_line(capsys)
    assert sorted(os.listdir(work)) == ["thesis.tex"] and (work / "thesis.tex").read_text() == "x"
    assert sorted(os.listdir(tmp_path)) == ["p", "scene.toml"]


def test_force_refuses_to_replace_a_file_that_is_not_a_prom(tmp_path, capsys):
    scene = write_scene(tmp_path)
    (tmp_path / "notes.npz").write_text("my notes")
    assert main(["build", scene, "--out", str(tmp_path / "notes.npz"), "--force"]) == 2
    assert "not written by the toolkit" in one_line(capsys)
    assert (tmp_path / "notes.npz").read_text() == "my notes"


def test_a_file_where_the_output_folder_should_be_is_kept(tmp_path, capsys):
    scene = write_scene(tmp_path)
    (tmp_path / "run").write_text("mine")
    assert simulate(scene, tmp_path / "run", "--force") == 2
    assert "is a file, not a folder" in one_line(capsys)
    assert (tmp_path / "run").read_text() == "mine"


# ---------------------------------------------------------------------- data loss, case 2
@pytest.fixture
def previous_run(tmp_path):
    scene = write_scene(tmp_path)
    out = tmp_path / "prev"
    assert simulate(scene, out) == 0
    return scene, out, snapshot(out)


def test_refused_input_with_force_keeps_the_previous_results(previous_run, tmp_path, capsys):
    scene, out, before = previous_run
    capsys.readouterr()
    assert simulate(scene, out, "--force", "--xi", "z_tail=1e9") == 2
    assert "z_tail" in one_line(capsys)
    assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prev", "scene.toml"]


def test_solver_stop_with_force_keeps_the_previous_results_and_the_partial_run_beside(previous_run, tmp_path, capsys):
    _, out, before = previous_run
    diverging = write_scene(tmp_path, duration=2.0, extra="[actuation]\nstiffness = 1e6", name="diverging.toml")
    capsys.readouterr()
    assert simulate(diverging, out, "--force") == 3
    message = one_line(capsys)
    assert snapshot(out) == before
    partial = [p for p in tmp_path.iterdir() if p.name.startswith("prev.new-")]
    assert len(partial) == 1 and str(partial[0] / "trajectory.csv") in message
    summary = json.loads((partial[0] / "summary.json").read_text())
    stop = re.search(r"at t = ([0-9.]+) s \(step (\d+) of 100\)", summary["stop_reason"])
    assert not summary["completed"] and stop and 0.25 < float(stop.group(1)) <= 0.5   # after the peak activation
    assert (partial[0] / "manifest.json").exists()


def test_finished_forced_run_replaces_the_previous_one_in_place(previous_run, tmp_path, capsys):
    scene, out, before = previous_run
    longer = write_scene(tmp_path, duration=0.3, name="longer.toml")
    assert simulate(longer, out, "--force") == 0
    assert f"outputs in {out}/" in capsys.readouterr().out
    assert snapshot(out) != before and json.loads((out / "summary.json").read_text())["steps"] == 15
    assert sorted(p.name for p in tmp_path.iterdir()) == ["longer.toml", "prev", "scene.toml"]


def test_interrupted_publication_never_leaves_the_target_empty(previous_run, tmp_path, monkeypatch):
    """Without an atomic exchange the old folder is renamed away before the new one moves in."""
    scene, out, _ = previous_run
    monkeypatch.setattr(outputs_module, "_exchange", lambda first, second: False)
    assert simulate(write_scene(tmp_path, duration=0.3, name="longer.toml"), out, "--force") == 0
    assert json.loads((out / "summary.json").read_text())["steps"] == 15
    assert sorted(p.name for p in tmp_path.iterdir()) == ["longer.toml", "prev", "scene.toml"]


# ---------------------------------------------------------------------- data loss, case 3; cases 7 and 10
@pytest.fixture(scope="module")
def optimized(tmp_path_factory):
    directory = tmp_path_factory.mktemp("optimized")
    scene = write_scene(directory, template=OPTIMIZE, name="o.toml")
    out = directory / "o1"
    assert main(["optimize", scene, "--out", str(out)]) == 0
    return directory, scene, out


def test_refused_resume_leaves_the_history_untouched(optimized, capsys):
    directory, _, out = optimized
    other = write_scene(directory, template=OPTIMIZE, extra="[actuation]\namplitude = 0.25", name="other.toml")
    before = snapshot(out)
    assert main(["optimize", other, "--out", str(out), "--resume"]) == 2
    assert "start without --resume" in one_line(capsys)
    assert snapshot(out) == before


def test_damaged_checkpoint_is_refused_in_one_line(optimized, tmp_path, capsys):
    _, scene, out = optimized
    copy = tmp_path / "copy"
    copy.mkdir()
    for name, content in snapshot(out).items():
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        (copy / name).write_bytes(content)
    for damage in ("{", "[1, 2]", '{"scene_hash": 1}'):
        (copy / "checkpoint.json").write_text(damage)
        before = snapshot(copy)
        assert main(["optimize", scene, "--out", str(copy), "--resume"]) == 2
        assert "checkpoint" in one_line(capsys)
        assert snapshot(copy) == before


def test_resume_without_a_checkpoint_creates_nothing(optimized, tmp_path, capsys):
    _, scene, _ = optimized
    assert main(["optimize", scene, "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "no checkpoint" in one_line(capsys)
    assert not (tmp_path / "none").exists()


def test_interrupted_optimisation_exits_130_and_resumes_with_the_fresh_column_order(optimized, tmp_path, capsys,
                                                                                      monkeypatch):
    _, scene, fresh = optimized
    original = history.Checkpoint.save
    calls = []

    def save_then_interrupt(self, *args):
        original(self, *args)
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(history.Checkpoint, "save", save_then_interrupt)
    out = tmp_path / "o"
    assert main(["optimize", scene, "--out", str(out)]) == 130
    message = one_line(capsys)
    assert "interrupted" in message and "--resume" in message and str(out) in message
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["completed"] and "interrupted" in summary["stop_reason"]
    assert json.loads((out / "checkpoint.json").read_text())["state"]["iteration"] == 2
    monkeypatch.setattr(history.Checkpoint, "save", original)
    assert main(["optimize", scene, "--out", str(out), "--resume"]) == 0
    resumed = (out / "history.csv").read_text().splitlines()
    straight = (fresh / "history.csv").read_text().splitlines()
    assert resumed[0] == straight[0] and len(resumed) == len(straight)


# ---------------------------------------------------------------------- Ctrl-C in a simulation
def test_ctrl_c_writes_the_summary_and_exits_130(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)
    original = tables_module.TrajectoryCSV.write
    rows = []

    def write_then_interrupt(self, *args):
        original(self, *args)
        rows.append(1)
        if len(rows) == 4:       # Ctrl-C while the sample at t = 0.06 s is being recorded
            signal.raise_signal(signal.SIGINT)   # to this (main) thread; its handler runs before this returns

    monkeypatch.setattr(tables_module.TrajectoryCSV, "write", write_then_interrupt)
    # As in an interactive process: a shell starts background jobs with SIGINT ignored, and a
    # simulation rightly leaves an ignored Ctrl-C ignored.
    interactive = signal.signal(signal.SIGINT, signal.default_int_handler)
    out = tmp_path / "run"
    try:
        assert simulate(scene, out) == 130
    finally:
        signal.signal(signal.SIGINT, interactive)
    message = one_line(capsys)
    assert "interrupted at t = 0.06 s" in message and f"partial results in {out}/" in message
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["completed"] and summary["stop_reason"].startswith("interrupted at t = 0.06 s")
    assert summary["steps"] == 3 and np.load(out / "displacement.npz")["time"].size == 4
    assert len((out / "trajectory.csv").read_text().splitlines()) == 5
    assert "files" in json.loads((out / "manifest.json").read_text())


# ---------------------------------------------------------------------- OS errors
def test_output_below_a_file_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)
    (tmp_path / "file").write_text("x")
    monkeypatch.setattr("aquarom_fenics.dynamics.simulate.simulate_fom", lambda *a, **k: pytest.fail("simulated"))
    assert simulate(scene, tmp_path / "file" / "run") == 2
    assert "a parent of this folder is a file" in one_line(capsys)


def test_unwritable_output_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)

    def no_permission(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "run"))

    monkeypatch.setattr(persistence_module.tempfile, "mkstemp", no_permission)
    monkeypatch.setattr("aquarom_fenics.dynamics.simulate.simulate_fom", lambda *a, **k: pytest.fail("simulated"))
    assert simulate(scene, tmp_path / "run") == 2
    assert "not writable (Permission denied)" in one_line(capsys)
    assert not (tmp_path / "run").exists()


def test_full_disk_during_a_run_is_one_line(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)

    def disk_full(self, *args):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "run" / "trajectory.csv"))

    monkeypatch.setattr(tables_module.TrajectoryCSV, "write", disk_full)
    assert simulate(scene, tmp_path / "run") == 2
    assert "trajectory.csv: No space left on device" in one_line(capsys)


def test_cache_that_is_a_file_is_refused_before_the_build(tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path)
    (tmp_path / "cache").write_text("x")
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr("aquarom_fenics.reduction.reductor.build_prom", lambda *a, **k: pytest.fail("built"))
    assert main(["build", scene, "--out", str(tmp_path / "p.npz")]) == 2
    assert "is a file, not a folder" in one_line(capsys)
    assert not (tmp_path / "p.npz").exists()


def test_unreadable_scene_file_is_one_line(tmp_path, capsys):
    assert main(["mesh", str(tmp_path)]) == 2                  # a folder where the scene should be
    assert "a folder, not a file" in one_line(capsys)
    (tmp_path / "binary.toml").write_bytes(b"\xff\xfe\x00")
    assert main(["mesh", str(tmp_path / "binary.toml")]) == 2
    assert "UTF-8" in one_line(capsys)


# ---------------------------------------------------------------------- smaller items (case 12)
@pytest.mark.parametrize("arguments, named", [
    (["--xi", "z_tail=0.1", "--xi", "z_tail=0.2"], "given twice"),
    (["--prom", "x.npz"], "--model prom only"),
])
def test_ambiguous_arguments_are_refused(tmp_path, capsys, arguments, named):
    scene = write_scene(tmp_path)
    assert simulate(scene, tmp_path / "run", *arguments) == 2
    assert named in one_line(capsys)
    assert not (tmp_path / "run").exists()


def test_design_outside_the_bounds_is_simulated_with_a_warning(tmp_path, caplog):
    scene = write_scene(tmp_path)
    assert simulate(scene, tmp_path / "run", "--xi", "y_thin=0.12") == 0
    assert "outside the scene's bounds [-0.1, 0.1] of y_thin" in caplog.text


@pytest.mark.parametrize("content, named", [(b"", "an empty file"), (b"text, not numbers", "not a .npz archive")])
def test_empty_or_text_prom_file_is_named_as_such(tmp_path, capsys, content, named):
    scene = write_scene(tmp_path)
    (tmp_path / "p.npz").write_bytes(content)
    assert main(["simulate", scene, "--model", "prom", "--prom", str(tmp_path / "p.npz")]) == 2
    message = one_line(capsys)
    assert named in message and "pickle" not in message


def test_scene_name_cannot_leave_the_results_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene = tmp_path / "escape.toml"
    scene.write_text('name = "../../../escaped"\n[mesh]\nlevel = 1\n')
    assert main(["mesh", str(scene)]) == 2
    assert "plain folder name" in one_line(capsys)


def test_json_outputs_hold_no_infinity(tmp_path):
    persistence_module.write_json_atomic(tmp_path / "x.json", {"a": float("inf"), "b": [np.float64("-inf"), 1.0],
                                                               "c": np.array([np.nan, 2.0])})
    text = (tmp_path / "x.json").read_text()
    assert "Infinity" not in text and "NaN" not in text
    assert json.loads(text) == {"a": None, "b": [None, 1.0], "c": [None, 2.0]}


# ---------------------------------------------------------------------- concurrent cache writers
WRITER = """
import sys
from pathlib import Path

import numpy as np

from aquarom_fenics.io.persistence import read_intact, store
from aquarom_fenics.reduction.prom import ReducedModel

model, entry, count = ReducedModel.load(Path(sys.argv[1])), Path(sys.argv[2]), int(sys.argv[3])
damaged = 0
for i in range(count):
    model.timings = {"writer": sys.argv[4], "save": i}     # each save differs in bytes, like real rebuilds
    store(entry, model.save)
    damaged += read_intact(entry, lambda path: ReducedModel.load(path)) is None
print(damaged)
"""


def test_two_processes_saving_the_same_prom_entry(tmp_path):
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom
    from conftest import coarse_scene

    scene = coarse_scene(solver={"duration": 0.2})
    build_prom(scene, parametric=False).save(tmp_path / "model.npz")
    entry = tmp_path / "cache" / "prom" / "entry.npz"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    writers = [subprocess.Popen([sys.executable, str(script), str(tmp_path / "model.npz"), str(entry), "150", name],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for name in ("a", "b")]
    results = [writer.communicate(timeout=300) for writer in writers]
    for writer, (out, err) in zip(writers, results):
        assert writer.returncode == 0, err
        assert out.strip() == "0", "a reader saw data and checksum of different writers"
    assert ReducedModel.load(entry).timings["save"] == 149
    assert sorted(p.name for p in entry.parent.iterdir()) == ["entry.npz", "entry.npz.lock", "entry.npz.sha256"]


# ---------------------------------------------------------------------- MPI: a failure on one rank ends all
RANK_ZERO_DISK_FULL = """
import errno
import sys

from mpi4py import MPI

from aquarom_fenics import cli
from aquarom_fenics.io import tables

if MPI.COMM_WORLD.rank == 0:
    def disk_full(self, *args):
        raise OSError(errno.ENOSPC, "No space left on device", "trajectory.csv")

    tables.TrajectoryCSV.write = disk_full
cli.AGREEMENT_SECONDS = 1.0     # rank 1 never fails: rank 0's wait for it ends in the abort however long it is
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.mpi
@pytest.mark.parametrize("failure", ["output below a file", "disk full on rank 0 only"])
def test_a_failure_on_one_rank_ends_every_rank(tmp_path, failure):
    import shutil

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene = write_scene(tmp_path)
    (tmp_path / "file").write_text("x")
    if failure == "output below a file":
        command = [str(Path(sys.executable).with_name("aquarom")), "simulate", scene, "--out",
                   str(tmp_path / "file" / "run")]
        expected = "a parent of this folder is a file"
    else:
        (tmp_path / "failing.py").write_text(RANK_ZERO_DISK_FULL)
        command = [sys.executable, str(tmp_path / "failing.py"), "simulate", scene, "--out", str(tmp_path / "run")]
        expected = "trajectory.csv: No space left on device"
    completed = subprocess.run(["mpirun", "-n", "2", *command, "--no-progress"], capture_output=True, text=True,
                               timeout=120, env=os.environ)
    assert completed.returncode == 2, completed.stderr
    assert completed.stderr.count("aquarom simulate:") == 1 and expected in completed.stderr
    assert "Traceback" not in completed.stderr
