"""The default pool: fresh interpreters on this machine, one BLAS thread each."""
from __future__ import annotations

import atexit
import os
from concurrent.futures import Future
from typing import Callable

from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel.interface import WorkerSetup, local_worker_started, run_task

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

STOP_GRACE = 5.0
"""Seconds a local worker is given to end on SIGTERM before it is killed."""


class LocalProcesses:
    """``workers`` fresh interpreters on this machine (a spawn ``ProcessPoolExecutor``), one BLAS
    thread each; the default backend. ``setup``'s variables reach every task."""

    name = "local"

    def __init__(self, workers: int, setup: WorkerSetup | None = None):
        if workers < 1:
            raise InputError(f"workers = {workers}: must be at least 1")
        self.workers = workers
        self.setup = setup or WorkerSetup()
        self._pool = None

    def _executor(self):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        if self._pool is None:
            for variable in THREAD_VARIABLES:
                os.environ[variable] = "1"     # the spawned workers inherit it
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=local_worker_started, initargs=(self.setup.on_start,))
            _open_pools.add(self)
        return self._pool

    def submit(self, function: Callable, *args) -> Future:
        return self._executor().submit(run_task, self.setup.variables(), function, args)

    def restart(self) -> None:
        """A new set of worker processes after one died (a broken pool takes no more tasks)."""
        self.shutdown(cancel=True)

    def shutdown(self, cancel: bool = False) -> None:
        """Stop the workers: after their running tasks, or at once with ``cancel`` (running tasks
        are ended with SIGTERM; a worker still alive :data:`STOP_GRACE` s later is killed)."""
        pool, self._pool = self._pool, None
        _open_pools.discard(self)
        if pool is None:
            return
        if cancel:
            processes = list((getattr(pool, "_processes", None) or {}).values())
            for process in processes:
                if process.is_alive():
                    process.terminate()
            for process in processes:          # a worker that does not end on SIGTERM is killed
                process.join(timeout=STOP_GRACE)
                if process.is_alive():
                    process.kill()
                    process.join(timeout=STOP_GRACE)
        pool.shutdown(wait=True, cancel_futures=cancel)


_open_pools: set[LocalProcesses] = set()
"""Local pools with worker processes, ended when the interpreter exits (whatever ended the command)."""


@atexit.register
def _end_open_pools() -> None:
    for pool in list(_open_pools):
        pool.shutdown(cancel=True)
