"""Findings of the rerun of issue 42 as a new user would: what still failed, each with its test.

A tls:// scheduler without Dask's TLS settings and a client whose start fails are one line (no
traceback, none from Dask's finaliser at garbage collection); an Abaqus label past 32 bits is one
line; a designs file of more designs than a sweep takes is refused before all of it is parsed,
and a dry run looks up a bounded number of designs in the FOM cache; SIGTERM to a Pareto sweep
on two workers leaves no process and no half-written file.
"""
import gc
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aquarom_fenics.cli import main

from conftest import one_line, wait_for, write_short_scene as write_scene


@pytest.fixture
def unraisable(monkeypatch):
    """What finalisers raise (Python prints it as 'Exception ignored in …' with a traceback)."""
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda report: seen.append(report))
    return seen


# ---------------------------------------------------------------------- schedulers
def test_a_tls_scheduler_without_tls_settings_is_one_line(tmp_path, capsys, unraisable):
    pytest.importorskip("distributed")
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--samples", "2", "--scheduler", "tls://127.0.0.1:1",
                 "--connect-timeout", "1", "--out", str(tmp_path / "s")]) == 2
    assert "TLS settings" in one_line(capsys)
    gc.collect()
    assert not unraisable and not (tmp_path / "s").exists()


def test_a_client_whose_start_fails_leaves_no_finaliser_traceback(tmp_path, capsys, unraisable, monkeypatch):
    """Dask raises a TypeError for tls:// without a TLS context; past the settings check (here
    bypassed) it is still one line, and the half-made client is closed once, not again at collection."""
    pytest.importorskip("distributed")
    from aquarom_fenics.parallel import dask_cluster

    monkeypatch.setattr(dask_cluster, "_tls_configured", lambda: True)
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--samples", "2", "--scheduler", "tls://127.0.0.1:1",
                 "--connect-timeout", "1", "--out", str(tmp_path / "s")]) == 2
    assert "not reachable" in one_line(capsys)
    gc.collect()
    assert not unraisable, [str(report.exc_value) for report in unraisable]


# ---------------------------------------------------------------------- large designs files
def designs_file(directory: Path, rows: int) -> str:
    path = directory / "designs.csv"
    path.write_text("z_tail,y_thin\n" + "0.01,0.02\n" * rows)
    return str(path)


def test_a_designs_file_over_the_limit_is_refused_before_it_is_parsed(tmp_path, capsys, monkeypatch):
    from aquarom_fenics.studies import sweep_designs

    monkeypatch.setattr(sweep_designs, "MAX_DESIGNS", 50)
    parsed = []
    number = sweep_designs.parse_number
    monkeypatch.setattr(sweep_designs, "parse_number", lambda *a: parsed.append(1) or number(*a))
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--designs", designs_file(tmp_path, 51), "--dry-run"]) == 2
    assert "more than 50 designs" in one_line(capsys)
    assert not parsed
    assert main(["sweep", scene, "--designs", designs_file(tmp_path, 50), "--dry-run"]) == 0


def test_a_dry_run_looks_up_a_bounded_number_of_designs_in_the_fom_cache(tmp_path, capsys, monkeypatch):
    from aquarom_fenics.cli import sweep as sweep_command
    from aquarom_fenics.studies import sweep

    monkeypatch.setattr(sweep_command, "DRY_RUN_CACHE_LOOKUPS", 7)
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    looked_up = []
    counted = sweep.cached_designs
    monkeypatch.setattr(sweep, "cached_designs", lambda scene, designs, model: looked_up.append(len(designs))
                        or counted(scene, designs, model))
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--designs", designs_file(tmp_path, 20), "--dry-run"]) == 0
    assert looked_up == [7]
    text = capsys.readouterr().out
    assert "0 of the first 7 designs answered already (the other 13 not looked up" in text and "20 to compute" in text


# ---------------------------------------------------------------------- Abaqus labels
RECTANGLE = Path(__file__).resolve().parents[1] / "meshes" / "3d_rectangle_1272el.inp"


@pytest.mark.parametrize("where", ["node", "element", "elset"])
def test_an_abaqus_label_of_ten_to_the_twenty_is_one_line(tmp_path, capsys, where):
    label = str(10 ** 20)
    text = RECTANGLE.read_text()
    if where == "node":       # an extra node (meshio reads it; unused nodes are dropped)
        text = text.replace("*Node\n", f"*Node\n{label},           0.,           0.,           0.\n", 1)
    elif where == "element":  # the first tetrahedron's label
        head, _, tail = text.partition("*Element, type=C3D4\n")
        text = head + "*Element, type=C3D4\n" + label + tail[tail.index(","):]
    else:
        text = text.replace("*End Instance", f"*Elset, elset=head, generate\n 1, {label}, 1\n*End Instance", 1)
    (tmp_path / "big.inp").write_text(text)
    scene = tmp_path / "big.toml"
    scene.write_text('[mesh]\nfile = "big.inp"\nscale = 0.001\n[solver]\nduration = 0.2\n')
    assert main(["mesh", str(scene)]) == 2
    message = one_line(capsys)
    assert f"label {label} is over 2147483647" in message and "line " in message


# ---------------------------------------------------------------------- SIGTERM: no process, no half-written file
CO_LONG = """
[mesh]
level = 1
[solver]
duration = 2.0
[fluid]
drag = false
[optimizer]
max_iterations = 200
[shapes]
z_tail = { bounds = [-0.2, 0.2] }
y_thin = { bounds = [-0.1, 0.1] }
[actuation]
amplitude = 0.2
[cooptimization]
enabled = true
amplitude_bounds = [0.05, 0.4]
weights = [0.5, 0.9]
"""
"""A co-optimisation whose two weights run long enough that a signal always lands inside their tasks."""

def write_atomically_while_stopped(folder: str) -> None:
    """A task caught by its pool's cancel inside an atomic write (between the temporary file and
    its rename): ``started`` tells the test it is there."""
    from aquarom_fenics.io import persistence

    def slow_replace(source, target):
        Path(folder, "started").write_text("")
        time.sleep(120)
        os.rename(source, target)

    persistence.os.replace = slow_replace      # in this worker process only
    persistence.write_text_atomic(Path(folder) / "result.csv", "a,b\n1,2\n")


def exit_codes(processes) -> list:
    """The processes' exit codes once each is stored (at most 30 s). The pool's own thread also
    reaps its workers: a join that loses that race returns before the exit code is stored, so
    ``exitcode`` can still read None just after it."""
    wait_for(lambda: all(process.exitcode is not None for process in processes), 30, "an exit code was not stored")
    return [process.exitcode for process in processes]


def test_sigterm_to_a_local_worker_runs_its_task_cleanups(tmp_path):
    from aquarom_fenics.parallel import STOP_GRACE, LocalProcesses

    pool = LocalProcesses(1)
    pool.submit(write_atomically_while_stopped, str(tmp_path))
    wait_for((tmp_path / "started").exists, 120, "the task did not start")
    processes = list(pool._pool._processes.values())
    started = time.monotonic()
    pool.shutdown(cancel=True)
    assert time.monotonic() - started < STOP_GRACE           # ended by SIGTERM, not killed after the grace
    assert exit_codes(processes) == [143]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["started"]    # no temporary left, no result


def test_sigterm_to_a_pareto_sweep_on_two_workers_leaves_no_process_and_no_partial_file(tmp_path):
    """As a batch system stops a job: SIGTERM to the command alone, which ends its workers."""
    psutil = pytest.importorskip("psutil")
    scene = tmp_path / "co.toml"
    scene.write_text(CO_LONG)
    command = [str(Path(sys.executable).with_name("aquarom")), "pareto", str(scene), "--workers", "2",
               "--out", str(tmp_path / "p")]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, env=os.environ | {"AQUAROM_CACHE": str(tmp_path / "cache")})
    parent = psutil.Process(process.pid)
    everything = []
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and process.poll() is None and not list((tmp_path / "p").glob("w1_*/history.csv")):
            time.sleep(0.5)                             # until the weights' tasks are writing
        everything = parent.children(recursive=True)
        assert len([child for child in everything if "python" in child.name()]) >= 2, "the two workers did not start"
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=120)
        assert process.returncode == 143, err
        assert "Traceback" not in err and "leaked semaphore" not in err, err
        assert len([line for line in err.splitlines() if line.strip()]) == 1, err
        gone, alive = psutil.wait_procs(everything, timeout=15)
        assert not alive, [p.cmdline() for p in alive]
        files = [path for path in (tmp_path / "p").rglob("*") if path.is_file()]
        assert files and not [path for path in files if path.name.startswith(".")], files   # no temporary left
        for path in files:
            if path.suffix in (".csv", ".json"):
                assert path.read_text().endswith("\n"), path
    finally:                                            # whatever failed, this test leaves nothing running
        for leftover in [parent, *everything]:
            try:
                leftover.kill()
            except psutil.Error:
                pass


# ---------------------------------------------------------------------- a picture stopped by Ctrl-C
LEFT_OPEN = """
import sys
from pathlib import Path
import pyvista
from aquarom_fenics.viz import render
from aquarom_fenics.viz.display import ensure_display
ensure_display()
plotter = render._plotter((1, 1), (200, 200))
plotter.add_mesh(pyvista.Sphere())
plotter.screenshot(str(Path(sys.argv[1]) / "left_open.png"))     # drawn, never closed (Ctrl-C before _save)
sys.exit(130)
"""


def test_a_plotter_left_open_does_not_change_the_exit_code(tmp_path):
    """Ctrl-C during optimize's pictures exited with 1 and 'XIO: fatal IO error' (the window
    outlived the process's own Xvfb), not 130."""
    import shutil

    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed")
    environment = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    result = subprocess.run([sys.executable, "-c", LEFT_OPEN, str(tmp_path)], capture_output=True, text=True,
                            env=environment, timeout=120)
    assert result.returncode == 130 and "XIO" not in result.stderr, result.stderr
    assert (tmp_path / "left_open.png").is_file()


INTERRUPTED_IMPORT = """
import builtins, signal, sys
real_import = builtins.__import__
fired = []

def importing(name, *args, **kwargs):       # Ctrl-C arrives while VTK loads one of its modules
    if name.startswith("vtkmodules.vtkIOLegacy") and not fired:
        fired.append(name)
        signal.raise_signal(signal.SIGINT)
    return real_import(name, *args, **kwargs)

builtins.__import__ = importing
from aquarom_fenics.viz import render
try:
    render.import_pyvista()
except KeyboardInterrupt as stop:
    print(stop, file=sys.stderr)
    sys.exit(130)
print("imported", file=sys.stderr)
"""


def test_ctrl_c_while_the_renderer_loads_is_an_interrupt():
    """Ctrl-C during `import pyvista` (optimize's first picture) was VTK's ImportError, a traceback
    and exit 1."""
    result = subprocess.run([sys.executable, "-c", INTERRUPTED_IMPORT], capture_output=True, text=True, timeout=300)
    assert result.returncode == 130 and "Traceback" not in result.stderr, result.stderr
    assert "while the renderer was loading (Ctrl-C)" in result.stderr


def slow_start(folder: str) -> None:
    Path(folder, "started").write_text("")
    time.sleep(3)
    Path(folder, "finished").write_text("")


def test_sigterm_during_a_local_workers_start_up_waits_for_its_end(tmp_path):
    """SIGTERM sent in the first second of a pareto --workers 2 (to the process group) cut the
    workers' MPI start-up, and MPI's daemons printed 'ORTE_ERROR_LOG: Broken pipe' beside the
    command's line; the start-up (WorkerSetup.on_start) now runs with SIGTERM held back."""
    import functools

    from aquarom_fenics.parallel import LocalProcesses, WorkerSetup

    pool = LocalProcesses(1, WorkerSetup(on_start=functools.partial(slow_start, str(tmp_path))))
    pool.submit(os.getpid)
    wait_for((tmp_path / "started").exists, 120, "the worker's start-up did not run")
    processes = list(pool._pool._processes.values())
    for process in processes:
        os.kill(process.pid, signal.SIGTERM)
    for process in processes:
        process.join(timeout=30)
    assert (tmp_path / "finished").exists()
    assert exit_codes(processes) == [143]
    pool.shutdown(cancel=True)


def test_an_unreachable_scheduler_leaves_no_finaliser_traceback(tmp_path, capsys, unraisable):
    pytest.importorskip("distributed")
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--samples", "2", "--scheduler", "tcp://127.0.0.1:1",
                 "--connect-timeout", "1", "--out", str(tmp_path / "s")]) == 2
    assert "not reachable within 1 s" in one_line(capsys)
    gc.collect()
    assert not unraisable, [str(report.exc_value) for report in unraisable]
