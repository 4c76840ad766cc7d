"""The compiled forms' cache survives interrupted compiles (fem/jit_cache.py, the adapter's guard).

FFCx claims a module by creating ``<module>.c`` empty; a compile stopped before it writes
``<module>.c.cached`` used to leave that file, and every later process needing the module waited
10 s and failed ("JIT compilation timed out"). Each test starts from an empty cache folder
(``AQUAROM_JIT_CACHE``); the signal tests send their signal once the first compile has claimed its
module (its ``.c`` file exists), not after a timer.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.jit_cache import CACHE_VARIABLE, JitCacheError, claimed, is_complete
from tests.conftest import wait_for
from tests.fem.jit_probe import probe_mesh, stiffness_form

PROBE = Path(__file__).with_name("jit_probe.py")
REPOSITORY = Path(__file__).resolve().parents[2]
AQUAROM = Path(sys.executable).with_name("aquarom")


def probe_environment(cache: Path, home: Path | None = None) -> dict:
    environment = dict(os.environ, **{CACHE_VARIABLE: str(cache)}, PYTHONPATH=str(REPOSITORY))
    if home is not None:
        environment["HOME"] = str(home)
    return environment


def start_probe(cache: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(PROBE)], env=probe_environment(cache), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def run_probe(cache: Path, timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(PROBE)], env=probe_environment(cache), text=True,
                          capture_output=True, timeout=timeout)


def claimed_sources(cache: Path) -> list[Path]:
    """FFCx's claims: the ``.c`` files in the cache."""
    return sorted(cache.glob("*.c"))


def unfinished(cache: Path) -> list[str]:
    """Modules whose ``.c`` exists without a finished compile."""
    return [path.stem for path in claimed_sources(cache) if not is_complete(cache, path.stem)]


def probe_modules(scratch: Path) -> list[str]:
    """The modules the probe compiles, as the adapter names them (the names do not depend on the
    cache folder); its element is compiled in the cache folder ``scratch`` on the way."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_VARIABLE, str(scratch))
        space = fx.vector_space(probe_mesh(MPI.COMM_SELF), 2)
        jit = fx.jit_parameters()
        return [fx.ffcx_module_name(space.ufl_element(), "elements", jit),
                fx.ffcx_module_name(stiffness_form(space), "forms", jit)]


def stop_once_claimed(process: subprocess.Popen, cache: Path, number: int) -> str:
    """Send signal ``number`` as soon as the first compile has claimed its module; that module."""
    wait_for(lambda: claimed_sources(cache) or process.poll() is not None, 60, "no compile started")
    assert process.poll() is None, "the run ended before its first compile was claimed"
    process.send_signal(number)
    process.communicate(timeout=60)
    return claimed_sources(cache)[0].stem if claimed_sources(cache) else ""


@pytest.mark.parametrize("number", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["ctrl-c", "sigterm", "sigkill"])
def test_a_run_stopped_in_its_first_compile_leaves_a_cache_the_next_run_uses(tmp_path, number):
    cache = tmp_path / "jit"
    process = start_probe(cache)
    module = stop_once_claimed(process, cache, number)
    assert process.returncode != 0, "the probe finished before the signal reached it"
    if number == signal.SIGKILL:            # nothing runs after SIGKILL: its claim is left as it was
        assert unfinished(cache) == [module]
    else:                                   # an exception ends the compile: its own files are removed
        assert unfinished(cache) == []
    started = time.monotonic()
    again = run_probe(cache)
    assert again.returncode == 0 and "compiled" in again.stdout, again.stderr
    assert "timed out" not in again.stderr
    assert time.monotonic() - started < 60
    assert unfinished(cache) == []


def test_a_run_starts_from_a_left_over_empty_source_and_a_dead_process_claim(tmp_path):
    cache = tmp_path / "jit"
    cache.mkdir()
    finished = subprocess.Popen(["true"])
    finished.wait()
    for module in probe_modules(tmp_path / "scratch"):
        (cache / f"{module}.c").write_text("")                                  # FFCx's claim, left empty
        (cache / f"{module}.claim").write_text(f"{finished.pid} {os.uname().nodename}\n")   # a dead process's
    result = run_probe(cache)
    assert result.returncode == 0 and "compiled" in result.stdout, result.stderr
    assert "removed an unfinished compile" in result.stderr
    assert all(is_complete(cache, module) for module in probe_modules(tmp_path / "scratch"))


def test_a_run_waits_for_another_process_compiling_its_module_and_says_for_whom(tmp_path):
    cache = tmp_path / "jit"
    element = probe_modules(tmp_path / "scratch")[0]
    with claimed(cache, element, "the probe's element"):         # this process compiles it, for now
        process = start_probe(cache)
        said: list[str] = []
        reader = threading.Thread(target=lambda: said.extend(process.stderr), daemon=True)
        reader.start()
        wait_for(lambda: any("waiting for" in line for line in said) or process.poll() is not None, 60,
                 "the run did not say it waits")
        assert process.poll() is None, "the run did not wait for the claim"
        assert not (cache / f"{element}.c").exists(), "the run compiled a module another process holds"
    out = process.communicate(timeout=120)[0]
    reader.join(timeout=10)
    assert process.returncode == 0 and "compiled" in out, "".join(said)
    waiting = next(line for line in said if "waiting for" in line)
    assert f"waiting for process {os.getpid()} on {os.uname().nodename} to finish compiling" in waiting
    assert element in waiting and str(cache) in waiting


def test_two_processes_compiling_one_form_at_once_both_succeed(tmp_path):
    cache = tmp_path / "jit"
    processes = [start_probe(cache) for _ in range(2)]
    outputs = [process.communicate(timeout=120) for process in processes]
    for process, (out, err) in zip(processes, outputs):
        assert process.returncode == 0 and "compiled" in out, err
        assert "timed out" not in err
    assert unfinished(cache) == [] and not list(cache.glob("*.failed"))
    assert all(is_complete(cache, module) for module in probe_modules(tmp_path / "scratch"))


def test_the_wait_for_another_process_is_bounded_and_names_it(tmp_path):
    with claimed(tmp_path, "libffcx_forms_x", "a form"):
        with pytest.raises(JitCacheError) as stopped:
            with claimed(tmp_path, "libffcx_forms_x", "the mass form", wait=0.2):
                pass
    message = str(stopped.value)
    assert f"process {os.getpid()} on {os.uname().nodename}" in message and "the mass form" in message
    assert str(tmp_path) in message and CACHE_VARIABLE in message


def test_the_module_names_are_ffcx_own(tmp_path, monkeypatch):
    """The guard claims the module FFCx compiles: after a compile, each claim has its finished module."""
    modules = probe_modules(tmp_path / "jit")
    monkeypatch.setenv(CACHE_VARIABLE, str(tmp_path / "jit"))
    space = fx.vector_space(probe_mesh(MPI.COMM_SELF), 2)
    fx.compile_form(stiffness_form(space))
    cache = tmp_path / "jit"
    assert all(is_complete(cache, module) for module in modules)
    assert sorted(path.stem for path in cache.glob("*.claim")) == sorted(path.name[:-len(".c.cached")]
                                                                       for path in cache.glob("*.c.cached"))


def test_a_cache_that_cannot_be_made_is_one_line_and_exit_2(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    folder = blocker / "jit"
    result = subprocess.run([str(AQUAROM), "simulate", "nominal", "--level", "1", "--set", "solver.duration=0.1",
                             "--no-progress", "--out", str(tmp_path / "run")], env=probe_environment(folder),
                            text=True, capture_output=True, timeout=300)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert str(folder) in lines[0] and CACHE_VARIABLE in lines[0]
    assert "writing in" not in lines[0]


SOURCES = ("aquarom_fenics", "forms", "scripts", "tests")
COMPILING_CALLS = ("fem.form(", "fem.Expression(", "FunctionSpace(", "import ffcx", "from ffcx", "dolfinx.jit",
                   "from dolfinx import jit")


def test_only_the_adapter_compiles():
    """Every FFCx compile goes through fem/dolfinx_adapter.py (which guards it)."""
    allowed = {REPOSITORY / "aquarom_fenics" / "fem" / "dolfinx_adapter.py",
               REPOSITORY / "aquarom_fenics" / "fem" / "jit_cache.py", Path(__file__).resolve()}
    offenders = [f"{path.relative_to(REPOSITORY)}: {call}"
                 for folder in SOURCES for path in sorted((REPOSITORY / folder).rglob("*.py")) if path not in allowed
                 for call in COMPILING_CALLS if call in path.read_text()]
    assert offenders == []


SHORT_RUN = ["simulate", "nominal", "--level", "1", "--set", "solver.duration=0.1", "--no-progress"]


def test_a_command_stopped_in_its_compiles_by_ctrl_c_sigterm_then_sigkill_runs_next_time(tmp_path):
    """The command line on an empty cache, as a new user's first runs: each run is stopped once its
    first compile has claimed its module, the next run gets past that module, the last one finishes.
    Nothing is written under HOME (the cache folder is the variable's)."""
    cache, home = tmp_path / "jit", tmp_path / "home"
    home.mkdir()
    environment = probe_environment(cache, home)
    for attempt, number in enumerate((signal.SIGINT, signal.SIGTERM, signal.SIGKILL)):
        before = set(claimed_sources(cache))
        process = subprocess.Popen([str(AQUAROM), *SHORT_RUN, "--out", str(tmp_path / f"stopped-{attempt}")],
                                   env=environment, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        wait_for(lambda: set(claimed_sources(cache)) - before or process.poll() is not None, 120,
                 f"run {attempt} claimed no module")
        assert process.poll() is None, process.communicate()
        process.send_signal(number)
        err = process.communicate(timeout=60)[1]
        assert process.returncode != 0
        assert "timed out" not in err and "Traceback" not in err, err
        expected = 1 if number == signal.SIGKILL else 0
        assert len(unfinished(cache)) == expected, (number, unfinished(cache))
    result = subprocess.run([str(AQUAROM), *SHORT_RUN, "--out", str(tmp_path / "finished")], env=environment,
                            text=True, capture_output=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert unfinished(cache) == [] and not list(cache.glob("*.failed"))
    assert not (home / ".cache" / "fenics").exists()


@pytest.mark.mpi
def test_mpirun_on_an_empty_cache(tmp_path):
    cache, home = tmp_path / "jit", tmp_path / "home"
    home.mkdir()
    result = subprocess.run(["mpirun", "-n", "2", str(AQUAROM), *SHORT_RUN, "--out", str(tmp_path / "run")],
                            env=probe_environment(cache, home), text=True, capture_output=True, timeout=900)
    assert result.returncode == 0, result.stderr
    assert "timed out" not in result.stderr
    assert claimed_sources(cache) and unfinished(cache) == []
    assert not (home / ".cache" / "fenics").exists()
