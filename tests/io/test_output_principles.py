"""Each output-safety principle on every command that writes: one writer per output (a lock),
--force decides at the moment it replaces, SIGTERM handled like Ctrl-C, damaged read-back files
refused in one line, bounded plans, caches cleared entry by entry."""
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.io import outputs as outputs_module
from aquarom_fenics.io import tables as tables_module
from aquarom_fenics.io.output_lock import LOCK_SUFFIX, lock_file_of

from conftest import SHORT_SCENE as SHORT, wait_for

OPTIMIZE = """
[mesh]
level = 1
[solver]
duration = 0.4
[fluid]
drag = false
[optimizer]
max_iterations = {iterations}
[shapes]
z_tail = {{ bounds = [-0.2, 0.2] }}
y_thin = {{ bounds = [-0.1, 0.1] }}
"""

HOLDER = """
import sys, time
from aquarom_fenics.io.output_lock import lock_output
lock_output(sys.argv[1])
print("locked", flush=True)
time.sleep(600)
"""


def write_scene(directory: Path, text: str, name: str) -> str:
    path = directory / name
    path.write_text(text)
    return str(path)


def one_line(capsys) -> str:
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "Traceback" not in error, error
    return error


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def aquarom() -> str:
    return str(Path(sys.executable).with_name("aquarom"))


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    directory = tmp_path_factory.mktemp("scenes")
    return {"short": write_scene(directory, SHORT.format(duration=0.2, extra=""), "short.toml"),
            "long": write_scene(directory, SHORT.format(duration=40.0, extra=""), "long.toml"),
            "optimize": write_scene(directory, OPTIMIZE.format(iterations=3), "optimize.toml"),
            "co": write_scene(directory, "[mesh]\nlevel = 1\n[solver]\nduration = 0.4\n[cooptimization]\n"
                                         "enabled = true\nweights = [0.5]\n[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n",
                              "co.toml")}


@pytest.fixture(scope="module")
def run_dir(scenes, tmp_path_factory):
    """A finished simulation run (what animate reads)."""
    out = tmp_path_factory.mktemp("runs") / "run"
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.fixture
def holder():
    """``hold(path)``: another process holding the output lock of ``path``; returns its PID."""
    processes = []

    def hold(path: Path) -> int:
        Path(path).resolve().parent.mkdir(parents=True, exist_ok=True)
        process = subprocess.Popen([sys.executable, "-c", HOLDER, str(path)], stdout=subprocess.PIPE, text=True)
        processes.append(process)
        assert process.stdout.readline().strip() == "locked"
        return process.pid

    yield hold
    for process in processes:
        process.kill()
        process.wait()


def writing_commands(scenes, run_dir, out: Path) -> dict[str, list[str]]:
    """Every command that writes an output, aimed at ``out``."""
    return {
        "simulate": ["simulate", scenes["short"], "--out", str(out), "--no-progress"],
        "simulate prom": ["simulate", scenes["short"], "--model", "prom", "--out", str(out), "--no-progress"],
        "build": ["build", scenes["short"], "--out", str(out.with_suffix(".npz"))],
        "compare": ["compare", scenes["short"], "--out", str(out), "--no-progress"],
        "optimize": ["optimize", scenes["optimize"], "--out", str(out)],
        "pareto": ["pareto", scenes["co"], "--out", str(out)],
        "shapes": ["shapes", scenes["short"], "--out", str(out)],
        "basis": ["basis", scenes["short"], "--out", str(out)],
        "animate": ["animate", str(run_dir), "--out", str(out.with_suffix(".mp4"))],
    }


COMMAND_NAMES = ["simulate", "simulate prom", "build", "compare", "optimize", "pareto", "shapes", "basis", "animate"]


# ---------------------------------------------------------------------- 1. one writer per output
@pytest.mark.parametrize("name", COMMAND_NAMES)
def test_a_second_writer_of_an_output_is_refused_naming_the_first(name, scenes, run_dir, holder, tmp_path, capsys,
                                                                  monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = writing_commands(scenes, run_dir, tmp_path / "out")[name]
    target = Path(argv[argv.index("--out") + 1])
    pid = holder(target)
    before = snapshot(tmp_path)
    assert main(argv) == 2
    message = one_line(capsys)
    assert f"being written by another aquarom run (PID {pid})" in message and str(target) in message
    assert snapshot(tmp_path) == before and not target.exists()


def test_two_real_simulations_on_one_output(scenes, tmp_path):
    out = tmp_path / "same"
    first = subprocess.Popen([aquarom(), "simulate", scenes["long"], "--out", str(out), "--no-progress"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: (out / "trajectory.csv").is_file())
        second = subprocess.run([aquarom(), "simulate", scenes["short"], "--out", str(out), "--no-progress",
                                 "--force"], capture_output=True, text=True, timeout=120)
        assert second.returncode == 2 and f"(PID {first.pid})" in second.stderr, second.stderr
        assert second.stderr.count("\n") == 1
        assert first.poll() is None, "the first run was disturbed"
    finally:
        first.send_signal(signal.SIGTERM)
        first.wait(timeout=60)
    assert first.returncode == 143
    assert not lock_file_of(out).exists(), "the lock file outlived its run"


def test_animate_refuses_a_run_that_is_being_written(run_dir, holder, tmp_path, capsys):
    pid = holder(run_dir)
    assert main(["animate", str(run_dir), "--out", str(tmp_path / "a.mp4")]) == 2
    assert f"PID {pid}" in one_line(capsys) and not (tmp_path / "a.mp4").exists()


def test_a_stale_lock_file_of_a_killed_run_does_not_block(scenes, tmp_path):
    out = tmp_path / "run"
    stale = tmp_path / f".run{LOCK_SUFFIX}"
    stale.write_text("999999\n")
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0
    assert not stale.exists() and (out / "summary.json").exists()


# ---------------------------------------------------------------------- 2. --force decides when it replaces
def test_a_file_added_during_a_forced_run_is_kept_with_the_earlier_run(scenes, tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0
    earlier = snapshot(out)
    original = tables_module.TrajectoryCSV.write

    def write_and_add_a_user_file(self, *args):
        original(self, *args)
        (out / "notes.txt").write_text("mine")

    monkeypatch.setattr(tables_module.TrajectoryCSV, "write", write_and_add_a_user_file)
    capsys.readouterr()
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress", "--force"]) == 2
    message = one_line(capsys)
    assert "notes.txt" in message and "the earlier results are kept" in message
    assert snapshot(out) == earlier | {"notes.txt": b"mine"}
    beside = [p for p in tmp_path.iterdir() if p.name.startswith("run.new-")]
    assert len(beside) == 1 and str(beside[0]) in message and (beside[0] / "summary.json").exists()


def test_a_file_added_at_the_swap_is_not_deleted(scenes, tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0
    exchange = outputs_module._exchange

    def add_then_exchange(first, second):       # after the check, before the swap
        (second / "late.txt").write_text("mine")
        return exchange(first, second)

    monkeypatch.setattr(outputs_module, "_exchange", add_then_exchange)
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress", "--force"]) == 0
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("run.kept-")]      # not taken for a killed run
    assert len(kept) == 1 and (kept[0] / "late.txt").read_text() == "mine"
    assert sorted(os.listdir(kept[0])) == ["late.txt"]          # the earlier run's own files are gone
    assert "late.txt" not in os.listdir(out) and (out / "manifest.json").exists()


def test_the_manifest_lists_the_animation_so_force_replaces_the_folder(scenes, run_dir, tmp_path, capsys):
    assert main(["animate", str(run_dir), "--stride", "5"]) == 0
    listed = json.loads((run_dir / "manifest.json").read_text())["files"]
    assert "animation.mp4" in listed and "animation.gif" in listed
    assert main(["animate", str(run_dir), "--stride", "5"]) == 2                 # twice: refused
    assert "--force" in one_line(capsys)
    assert main(["animate", str(run_dir), "--stride", "5", "--force"]) == 0
    copy = tmp_path / "copy"
    copy.mkdir()
    for name, content in snapshot(run_dir).items():
        (copy / name).write_bytes(content)
    assert main(["simulate", scenes["short"], "--out", str(copy), "--no-progress", "--force"]) == 0
    assert "animation.mp4" not in os.listdir(copy)


def test_animate_writes_only_the_files_it_is_named_and_replaces_only_its_own(run_dir, tmp_path, capsys):
    folder = tmp_path / "u"
    folder.mkdir()
    (folder / "clip.mp4").write_text("my film")
    (folder / "clip.gif").write_text("my gif")
    assert main(["animate", str(run_dir), "--out", str(folder / "clip.mp4")]) == 2
    assert "exists; pass --force" in one_line(capsys)
    assert main(["animate", str(run_dir), "--out", str(folder / "clip.mp4"), "--force"]) == 2
    assert "not written by the toolkit" in one_line(capsys)
    assert main(["animate", str(run_dir), "--out", str(folder / "new.mp4"), "--stride", "5"]) == 0
    assert sorted(os.listdir(folder)) == ["clip.gif", "clip.mp4", "new.mp4"]
    assert (folder / "clip.mp4").read_text() == "my film" and (folder / "clip.gif").read_text() == "my gif"
    assert main(["animate", str(run_dir), "--out", str(folder)]) == 2            # a folder as --out
    assert ".mp4" in one_line(capsys)


def test_cache_clear_removes_only_the_caches_entries(scenes, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    assert main(["build", scenes["short"], "--out", str(tmp_path / "p.npz")]) == 0
    prom = tmp_path / "cache" / "prom"
    assert any(p.suffix == ".sha256" for p in prom.iterdir())
    (prom / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["cache", "clear", "--kind", "prom"]) == 0
    said = capsys.readouterr().out
    assert "removed 1 entry" in said and "left 1 file(s) the cache did not write: notes.txt" in said
    assert os.listdir(prom) == ["notes.txt"]


def test_a_refused_run_removes_the_parent_folders_it_created(scenes, tmp_path, capsys):
    assert main(["simulate", scenes["short"], "--out", str(tmp_path / "a" / "b" / "run"), "--xi", "z_tail=x"]) == 2
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------- 3. SIGTERM like Ctrl-C
def temporary_folders() -> set[str]:
    return {name for name in os.listdir(tempfile.gettempdir()) if name.startswith("aquarom-")}


def test_sigterm_mid_simulation_keeps_the_partial_run_with_its_summary_and_manifest(scenes, tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0     # replaced below
    run = subprocess.Popen([aquarom(), "simulate", scenes["long"], "--out", str(out), "--no-progress", "--force"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial = next(tmp_path.glob("run.new-*"), None)
    wait_for(lambda: any(len(p.read_text().splitlines()) > 20 for p in tmp_path.glob("run.new-*/trajectory.csv")))
    run.send_signal(signal.SIGTERM)
    _, error = run.communicate(timeout=60)
    assert run.returncode == 143, error
    assert error.count("\n") == 1 and "terminated at t = " in error and f"partial results in {out}/" in error
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["completed"] and summary["stop_reason"].startswith("terminated at t = ")
    listed = json.loads((out / "manifest.json").read_text())["files"]
    assert "trajectory.csv" in listed and "summary.json" in listed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"], partial
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress", "--force"]) == 0   # the toolkit's own


def test_sigterm_mid_optimisation_then_resume(scenes, tmp_path):
    scene = write_scene(tmp_path, OPTIMIZE.format(iterations=6), "o.toml")
    out = tmp_path / "o"
    before = temporary_folders()
    run = subprocess.Popen([aquarom(), "optimize", scene, "--out", str(out)], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (out / "checkpoint.json").is_file(), timeout=300)
    run.send_signal(signal.SIGTERM)
    _, error = run.communicate(timeout=120)
    assert run.returncode == 143, error
    assert "terminated (SIGTERM)" in error and "--resume" in error and error.count("\n") == 1
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["completed"] and "terminated" in summary["stop_reason"]
    assert "history.csv" in json.loads((out / "manifest.json").read_text())["files"]
    assert temporary_folders() <= before, "a temporary folder outlived the run"
    assert main(["optimize", scene, "--out", str(out), "--resume"]) == 0
    assert "terminated" not in json.loads((out / "summary.json").read_text())["stop_reason"]
    iterations = [int(line.split(",")[0]) for line in (out / "history.csv").read_text().splitlines()[1:]]
    assert iterations == list(range(len(iterations))) and len(iterations) >= 7      # none lost, none twice


# ---------------------------------------------------------------------- 4. damaged read-back files
@pytest.mark.parametrize("damage", [
    '{"scene_hash": "x", "method": "paper", "state": {}, "history": [], "builds": 0, "build_time": 0, '
    '"solve_time": 0}',
    '{"scene_hash": "x", "method": "paper", "state": {"z": [0, 0]}, "history": "rows", "builds": 0, '
    '"build_time": 0, "solve_time": 0}',
    "[" * 5000, "\xff", "",
])
def test_a_damaged_checkpoint_is_refused_before_the_history_is_touched(scenes, tmp_path, capsys, damage):
    out = tmp_path / "o"
    out.mkdir()
    (out / "history.csv").write_text("iteration,cost\n0,1.0\n")
    (out / "checkpoint.json").write_text(damage, encoding="latin-1")
    before = snapshot(out)
    assert main(["optimize", scenes["optimize"], "--out", str(out), "--resume"]) == 2
    assert "checkpoint" in one_line(capsys)
    assert snapshot(out) == before


@pytest.mark.parametrize("name, damage, named", [
    ("summary.json", "{", "not valid JSON"),
    ("summary.json", '{"completed": true, "stop_reason": 3}', "stop_reason must be a string"),
    ("summary.json", '{"completed": true, "stop_reason": "", "xi": {"a": "b"}}', "xi.a must be a number"),
    ("trajectory.csv", "time,head_x\n0,0\n", "the header lacks"),
    ("trajectory.csv", "time_s,head_x_m,tail_y_m,com_x_m,newton_iterations\n", "no rows"),
    ("trajectory.csv", "time_s,head_x_m,tail_y_m,com_x_m,newton_iterations\n0,0,0,x,0\n", "column com_x_m"),
    ("trajectory.csv", "time_s,head_x_m,tail_y_m,com_x_m,newton_iterations\n0,0\n", "line 2 has 2 cells"),
    ("displacement.npz", "text", "not a displacement series"),
])
def test_animate_refuses_a_damaged_run_in_one_line(run_dir, tmp_path, capsys, name, damage, named):
    copy = tmp_path / "copy"
    copy.mkdir()
    for file, content in snapshot(run_dir).items():
        (copy / file).write_bytes(content)
    (copy / name).write_text(damage)
    before = snapshot(copy)
    assert main(["animate", str(copy), "--out", str(tmp_path / "a.mp4")]) == 2
    assert named in one_line(capsys)
    assert snapshot(copy) == before and not (tmp_path / "a.mp4").exists()


def test_a_damaged_manifest_makes_force_refuse_the_folder(scenes, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress"]) == 0
    (out / "manifest.json").write_text('{"files": "everything"}')
    before = snapshot(out)
    assert main(["simulate", scenes["short"], "--out", str(out), "--no-progress", "--force"]) == 2
    assert "did not write" in one_line(capsys)
    assert snapshot(out) == before


# ---------------------------------------------------------------------- 5. bounded plans
TIME_STEP_1E_9 = ("level = 1\n[solver]\ntime_step = 1e-9", "steps")
FLAT_BLOCK = ("level = 1\nheight = 1e-4", "far outside the level's range")


@pytest.mark.parametrize("command, plan, named", [
    *((command, *TIME_STEP_1E_9) for command in ("simulate", "compare", "optimize")),
    *((command, *FLAT_BLOCK) for command in ("simulate", "compare", "optimize", "mesh", "shapes", "build")),
])
def test_unbounded_plans_are_refused_before_any_work(command, plan, named, tmp_path, capsys, monkeypatch):
    scene = write_scene(tmp_path, f"[mesh]\n{plan}\n[shapes]\nz_tail = {{ bounds = [-0.2, 0.2] }}\n", "s.toml")
    monkeypatch.setattr("aquarom_fenics.geometry.block._generate_block", lambda *a: pytest.fail("meshed"))
    started = time.perf_counter()
    assert main([command, scene, "--out", str(tmp_path / "out")] if command != "mesh" else [command, scene]) == 2
    message = one_line(capsys)
    assert named in message and "--allow-large" in message
    assert time.perf_counter() - started < 10 and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------- 6. what the messages say
def test_a_folder_named_like_a_shipped_scene_does_not_hide_it(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "so1").mkdir()
    assert main(["mesh", "so1", "--dry-run"]) == 0
    assert "scene so1" in capsys.readouterr().out


@pytest.mark.parametrize("content", [b"\xef\xbb\xbf[mesh]\nlevel = 1\n", b"a = " + b"[" * 3000 + b"]" * 3000,
                                     b"a = " + b"{b = " * 3000 + b"1" + b"}" * 3000])
def test_byte_order_marks_and_absurd_nesting(tmp_path, capsys, content):
    (tmp_path / "s.toml").write_bytes(content)
    code = main(["mesh", str(tmp_path / "s.toml"), "--dry-run"])
    if content.startswith(b"\xef"):
        assert code == 0
    else:
        assert code == 2 and "nested deeper than" in one_line(capsys)


def test_a_symlink_loop_is_named_as_such(tmp_path, capsys):
    (tmp_path / "a.toml").symlink_to(tmp_path / "b.toml")
    (tmp_path / "b.toml").symlink_to(tmp_path / "a.toml")
    assert main(["mesh", str(tmp_path / "a.toml")]) == 2
    assert "symbolic link that leads to no file" in one_line(capsys)


def test_simulate_lists_the_files_it_wrote(tmp_path, capsys):
    scene = write_scene(tmp_path, SHORT.format(duration=0.2, extra="[output]\nplots = false"), "s.toml")
    assert main(["simulate", scene, "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "trajectory.csv" in said and "trajectory.png" not in said


def test_a_parameter_left_at_zero_outside_its_bounds_is_warned_about(tmp_path, capsys):
    """``shapes --xi`` draws the other parameters at 0; a run (simulate, compare) takes their start values."""
    scene = write_scene(tmp_path, "[mesh]\nlevel = 1\n[shapes]\nz_tail = { bounds = [0.05, 0.2], start = 0.1 }\n"
                        "y_thin = { bounds = [-0.1, 0.1] }\n", "s.toml")
    assert main(["shapes", scene, "--xi", "y_thin=0.05", "--dry-run"]) == 0
    assert "z_tail is not given with --xi: the design takes z_tail = 0, outside" in capsys.readouterr().err
    assert main(["simulate", scene, "--dry-run"]) == 0
    assert "not given with --xi" not in capsys.readouterr().err


# ---------------------------------------------------------------------- under mpirun
@pytest.mark.mpi
def test_under_mpirun_the_lock_refuses_and_sigterm_to_the_ranks_ends_all_alike(scenes, holder, tmp_path):
    import shutil

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    held = tmp_path / "held"
    pid = holder(held)
    refused = subprocess.run(["mpirun", "-n", "2", aquarom(), "simulate", scenes["short"], "--out", str(held),
                              "--no-progress"], capture_output=True, text=True, timeout=120, env=os.environ)
    assert refused.returncode == 2 and refused.stderr.count(f"(PID {pid})") == 1, refused.stderr
    out = tmp_path / "run"
    run = subprocess.Popen(["mpirun", "-n", "2", aquarom(), "simulate", scenes["long"], "--out", str(out),
                            "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=os.environ)
    wait_for(lambda: (out / "trajectory.csv").is_file() and len((out / "trajectory.csv").read_text().splitlines()) > 20)
    ranks = subprocess.run(["pgrep", "-P", str(run.pid)], capture_output=True, text=True).stdout.split()
    assert len(ranks) == 2
    for rank in ranks:                         # as a batch system does: every rank gets SIGTERM
        os.kill(int(rank), signal.SIGTERM)
    _, error = run.communicate(timeout=120)
    assert run.returncode == 143, error
    assert error.count("aquarom simulate: terminated at t = ") == 1 and "Traceback" not in error
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"].startswith("terminated at t = ")
    steps = len((out / "trajectory.csv").read_text().splitlines()) - 2
    assert summary["steps"] == steps and (out / "manifest.json").exists() and not lock_file_of(out).exists()


# ---------------------------------------------------------------------- SIGTERM on every command that writes
STOP_HOOKS = {                # where each command writes its first file: SIGTERM arrives right after it
    "simulate prom": "aquarom_fenics.io.persistence.write_bytes_atomic",
    "build": "aquarom_fenics.io.persistence.write_bytes_atomic",
    "compare": "aquarom_fenics.io.persistence.write_bytes_atomic",
    "optimize": "aquarom_fenics.io.persistence.write_bytes_atomic",
    "pareto": "aquarom_fenics.io.persistence.write_bytes_atomic",
    "shapes": "aquarom_fenics.viz.render._save",
    "basis": "aquarom_fenics.viz.animate._save",
    "animate": "aquarom_fenics.viz.animate._write_movies",
}


@pytest.mark.parametrize("name", sorted(STOP_HOOKS))
def test_sigterm_during_any_command_exits_143_and_leaves_a_listed_folder(name, scenes, run_dir, tmp_path, capsys,
                                                                         monkeypatch):
    import importlib

    argv = writing_commands(scenes, run_dir, tmp_path / "out")[name]
    module_name, function = STOP_HOOKS[name].rsplit(".", 1)
    module = importlib.import_module(module_name)
    original = getattr(module, function)
    sent = []

    def write_then_terminate(*args, **kwargs):
        value = original(*args, **kwargs)
        if not sent:
            sent.append(1)
            signal.raise_signal(signal.SIGTERM)       # handled before this returns, as a real one would be
        return value

    monkeypatch.setattr(module, function, write_then_terminate)
    handler = signal.getsignal(signal.SIGTERM)
    assert main(argv) == 143
    message = one_line(capsys)
    assert "terminated" in message and "(SIGTERM)" in message
    target = Path(argv[argv.index("--out") + 1])
    if target.is_dir():                                 # a folder output: its files are listed
        assert set(json.loads((target / "manifest.json").read_text())["files"]) == {
            str(p.relative_to(target)) for p in target.rglob("*") if p.is_file() and p.name != "manifest.json"}
        assert f"partial results in {target}/" in message
    assert sorted(p.name for p in tmp_path.iterdir() if ".new-" in p.name or LOCK_SUFFIX in p.name) == []
    assert signal.getsignal(signal.SIGTERM) is handler           # the caller's handler is back


# ---------------------------------------------------------------------- files added during --force, every folder command
FOLDER_COMMANDS = ["simulate prom", "compare", "optimize", "pareto", "shapes", "basis"]


@pytest.mark.parametrize("name", FOLDER_COMMANDS)
def test_files_added_during_a_forced_run_of_any_command_are_kept(name, scenes, run_dir, tmp_path, capsys,
                                                                 monkeypatch):
    import importlib

    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("an earlier run's file")
    (out / "manifest.json").write_text(json.dumps({"files": ["old.txt"]}))
    earlier = snapshot(out)
    module_name, function = STOP_HOOKS[name].rsplit(".", 1)
    module = importlib.import_module(module_name)
    original = getattr(module, function)

    def write_then_add_a_user_file(*args, **kwargs):
        value = original(*args, **kwargs)
        (out / "notes.txt").write_text("mine")
        return value

    monkeypatch.setattr(module, function, write_then_add_a_user_file)
    assert main(writing_commands(scenes, run_dir, out)[name] + ["--force"]) == 2
    message = one_line(capsys)
    assert "now holds files the toolkit did not write (notes.txt)" in message
    assert snapshot(out) == earlier | {"notes.txt": b"mine"}
    beside = [p for p in tmp_path.iterdir() if p.name.startswith("out.new-")]
    assert len(beside) == 1 and f"this run's results are in {beside[0]}/" in message


def test_a_folder_whose_parent_takes_no_files_is_locked_itself(tmp_path):
    """``--out .`` below a read-only parent: the flock goes on the folder, its holder read from /proc/locks."""
    from aquarom_fenics.errors import InputError
    from aquarom_fenics.io import output_lock

    script = ("import sys, time\nfrom pathlib import Path\nfrom aquarom_fenics.io import output_lock\n"
              "output_lock._lock_folder_itself(Path(sys.argv[1]))\nprint('locked', flush=True)\ntime.sleep(600)")
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "locked"
        with pytest.raises(InputError, match=f"another aquarom run \\(PID {child.pid}\\)"):
            output_lock._lock_folder_itself(tmp_path)
    finally:
        child.kill()
        child.wait()
    output_lock._lock_folder_itself(tmp_path)
    output_lock.release_output_locks()
    assert os.listdir(tmp_path) == []


def test_a_file_output_refused_after_its_claim_leaves_no_parent_folders(scenes, tmp_path, capsys, monkeypatch):
    from aquarom_fenics.errors import InputError

    def refuse(*args, **kwargs):
        raise InputError("refused by the build")

    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr("aquarom_fenics.reduction.reductor.build_prom", refuse)
    assert main(["build", scenes["short"], "--out", str(tmp_path / "a" / "b" / "p.npz")]) == 2
    assert "refused by the build" in one_line(capsys)
    assert not (tmp_path / "a").exists()


def test_a_folder_output_refused_after_its_claim_leaves_no_parent_folders(scenes, tmp_path, capsys, monkeypatch):
    from aquarom_fenics.errors import InputError

    def refuse(*args, **kwargs):
        raise InputError("refused by the model")

    monkeypatch.setattr("aquarom_fenics.dynamics.simulate.simulate_fom", refuse)
    assert main(["simulate", scenes["short"], "--out", str(tmp_path / "a" / "b" / "run"), "--no-progress"]) == 2
    assert "refused by the model" in one_line(capsys)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_sigterm_between_iterations_then_resume_with_either_method(method, tmp_path, capsys, monkeypatch):
    from aquarom_fenics.optimization import history

    scene = write_scene(tmp_path, OPTIMIZE.format(iterations=4), "o.toml")
    original = history.Checkpoint.save
    saves = []

    def save_then_terminate(self, *args):
        original(self, *args)
        saves.append(1)
        if len(saves) == 2:
            signal.raise_signal(signal.SIGTERM)

    monkeypatch.setattr(history.Checkpoint, "save", save_then_terminate)
    out = tmp_path / "o"
    assert main(["optimize", scene, "--method", method, "--out", str(out)]) == 143
    assert "terminated (SIGTERM)" in one_line(capsys)
    monkeypatch.setattr(history.Checkpoint, "save", original)
    assert main(["optimize", scene, "--method", method, "--out", str(out), "--resume"]) == 0
    iterations = [int(line.split(",")[0]) for line in (out / "history.csv").read_text().splitlines()[1:]]
    assert iterations == list(range(len(iterations))) and len(iterations) >= 3


def test_a_killed_runs_partial_folder_is_mentioned_not_removed(scenes, tmp_path, capsys):
    leftover = tmp_path / "run.new-999999"
    leftover.mkdir()
    (leftover / "trajectory.csv").write_text("time\n0\n")
    assert main(["simulate", scenes["short"], "--out", str(tmp_path / "run"), "--no-progress"]) == 0
    assert ("run.new-999999/ holds the partial results of a run that was killed (PID 999999)"
            in capsys.readouterr().err)
    assert (leftover / "trajectory.csv").read_text() == "time\n0\n"
