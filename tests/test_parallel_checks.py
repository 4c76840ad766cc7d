"""The pool layer's own checks, without a real cluster: a local worker that ignores SIGTERM is
killed when its pool is cancelled, and a Dask cluster without a usable worker is one line."""
import os
import signal
import time

import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel import ClusterSettings, LocalProcesses, STOP_GRACE, usable_workers

from conftest import wait_for


def ignore_sigterm_and_wait() -> int:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    time.sleep(120)
    return os.getpid()


def test_a_local_worker_that_ignores_sigterm_is_killed_on_cancel(monkeypatch):
    """With a 1 s grace instead of STOP_GRACE: the worker ignores SIGTERM however long the grace is."""
    from aquarom_fenics.parallel import local

    monkeypatch.setattr(local, "STOP_GRACE", 1.0)
    pool = LocalProcesses(1)
    pool.submit(ignore_sigterm_and_wait)
    wait_for(lambda: getattr(pool._pool, "_processes", None), 120, "the worker did not start")
    processes = list(pool._pool._processes.values())
    time.sleep(2)                                   # inside the task, SIGTERM ignored
    started = time.monotonic()
    pool.shutdown(cancel=True)
    assert time.monotonic() - started < 3 * STOP_GRACE + 30
    assert processes and not any(process.is_alive() for process in processes)


class FakeFuture:
    def __init__(self, error):
        self.error = error
        self.cancelled = False

    def result(self, timeout):
        raise self.error

    def cancel(self):
        self.cancelled = True


class FakeClient:
    """What usable_workers asks of a ``distributed.Client``."""

    def __init__(self, workers: bool, probe_error: Exception | None = None):
        self.workers = workers
        self.probe_error = probe_error
        self.futures = []

    def wait_for_workers(self, count, timeout):
        if not self.workers:
            raise TimeoutError(f"only 0 of {count} workers after {timeout} s")

    def submit(self, function, pure):
        self.futures.append(FakeFuture(self.probe_error))
        return self.futures[-1]


SETTINGS = ClusterSettings(scheduler="tcp://head-node:8786", connect_timeout=1.0)


def test_a_cluster_without_workers_is_one_line():
    with pytest.raises(InputError) as refused:
        usable_workers(FakeClient(workers=False), SETTINGS, probe=os.getpid)
    message = str(refused.value)
    assert "\n" not in message and "no worker within 1 s" in message and "tcp://head-node:8786" in message


def test_workers_that_cannot_import_the_probe_are_the_import_line():
    client = FakeClient(workers=True, probe_error=ModuleNotFoundError("No module named 'aquarom_fenics'"))
    with pytest.raises(InputError) as refused:
        usable_workers(client, SETTINGS, probe=os.getpid)
    message = str(refused.value)
    assert "cannot import the toolkit" in message and "No module named 'aquarom_fenics'" in message
    assert client.futures[0].cancelled


def test_a_probe_that_fails_otherwise_is_one_line():
    client = FakeClient(workers=True, probe_error=TimeoutError("probe not done\nsecond line"))
    with pytest.raises(InputError) as refused:
        usable_workers(client, SETTINGS, probe=os.getpid)
    message = str(refused.value)
    assert "\n" not in message and "no worker could run a task" in message and "probe not done" in message


SIGTERM_IN_A_FINALISER = """
import os, signal, time, weakref
from aquarom_fenics.parallel.interface import local_worker_started, run_task

class Resource:
    pass

def task():
    resource = Resource()
    weakref.finalize(resource, lambda: os.kill(os.getpid(), signal.SIGTERM))
    del resource              # its finaliser runs, and SIGTERM arrives inside it
    time.sleep(30)            # reached only if the stop was lost in the finaliser
    return "completed"

local_worker_started()
print(run_task({}, task, ()))
"""


def test_sigterm_inside_a_finaliser_of_a_task_still_ends_the_worker_without_a_traceback():
    """Python cannot raise from a finaliser: the stop is delivered again after it, not printed as an
    'Exception ignored' traceback and lost (a pareto sweep's worker printed one on SIGTERM)."""
    import subprocess
    import sys

    process = subprocess.run([sys.executable, "-c", SIGTERM_IN_A_FINALISER], capture_output=True, text=True,
                             timeout=60)
    assert process.returncode == 143, (process.returncode, process.stdout, process.stderr)
    assert process.stdout == "" and process.stderr == "", process.stderr
