"""The serial pool: each task runs at submission, in this process."""
from __future__ import annotations

from concurrent.futures import Future
from typing import Callable

from aquarom_fenics.parallel.interface import worker_threads


class InProcess:
    """Runs each task at submission, in this process: the serial backend (one worker, no cluster).

    A task runs with one BLAS and OpenMP thread (:func:`worker_threads`), as on the other backends."""

    name = "serial"
    workers = 1

    def submit(self, function: Callable, *args) -> Future:
        future: Future = Future()
        try:
            with worker_threads():
                result = function(*args)
            future.set_result(result)
        except Exception as error:  # noqa: BLE001 — handed to the caller like a worker's error
            future.set_exception(error)
        return future

    def shutdown(self, cancel: bool = False) -> None:
        pass
