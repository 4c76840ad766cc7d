"""A Dask worker whose Python cannot import the toolkit is refused in one line with the fix (exit
2), before any design runs and without an output folder: a real scheduler and a worker started
with Debian's Python, which has Dask but not this package."""
import subprocess
from pathlib import Path

import pytest

from aquarom_fenics.cli import main

SYSTEM_PYTHON = Path("/usr/bin/python3")


def system_python_lacks_the_toolkit() -> bool:
    if not SYSTEM_PYTHON.exists():
        return False
    probe = subprocess.run([str(SYSTEM_PYTHON), "-c", "import distributed, aquarom_fenics"], capture_output=True,
                           text=True, cwd="/")
    return "No module named 'aquarom_fenics'" in probe.stderr


@pytest.mark.skipif(not system_python_lacks_the_toolkit(), reason="needs a Python with Dask but without the toolkit")
def test_a_worker_that_cannot_import_the_toolkit_is_refused_in_one_line(tmp_path, capsys):
    address = tmp_path / "scheduler.json"
    started = []
    try:
        for module, arguments in (("dask_scheduler", ["--port", "0"]), ("dask_worker", ["--nthreads", "1"])):
            started.append(subprocess.Popen([str(SYSTEM_PYTHON), "-m", f"distributed.cli.{module}", "--scheduler-file",
                                             str(address), "--no-dashboard", *arguments], cwd="/",
                                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(scheduler_file=str(address), timeout=60) as client:
            client.wait_for_workers(1, timeout=60)
        out = tmp_path / "sweep"
        code = main(["sweep", "so1", "--level", "1", "--grid", "z_tail=0:0.1:2", "--model", "prom",
                     "--scheduler-file", str(address), "--out", str(out)])
    finally:
        for process in reversed(started):
            process.terminate()
            process.wait(timeout=30)
    error = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(error) == 1, error
    assert error[0].startswith("aquarom sweep: error: the workers of the scheduler of ")
    assert "cannot import the toolkit" in error[0] and "No module named 'aquarom_fenics'" in error[0]
    assert ".venv/bin/python -m distributed.cli.dask_worker" in error[0]
    assert not out.exists()
