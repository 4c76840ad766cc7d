"""What every pool offers, and what a task may ask about the worker it runs on.

A pool is ``concurrent.futures``-shaped: ``submit(function, *args) -> Future``, ``shutdown(cancel)``,
a ``name`` and a number of ``workers``. The caller says how a worker is made ready for its tasks
(:class:`WorkerSetup`): environment variables handed to every task, and a function run once when
a long-lived worker starts. The pools know nothing else of what their tasks compute.
"""
from __future__ import annotations

import os
import socket
import sys
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Callable, Protocol


class Pool(Protocol):
    """Workers that run plain functions: a ``concurrent.futures`` executor with a name and a size."""

    name: str

    @property
    def workers(self) -> int: ...

    def submit(self, function: Callable, *args) -> Future: ...

    def shutdown(self, cancel: bool = False) -> None: ...


@dataclass(frozen=True)
class WorkerSetup:
    """How the caller readies a worker: ``environment()`` gives variables set in the worker before
    each task (read in the submitting process at submission), ``on_start()`` runs once on a
    long-lived worker's main thread when it starts (a Dask worker), ``name`` identifies it there.
    ``probe()`` is the first task sent to a cluster before it is used: it fails on a worker that
    cannot run the caller's tasks (one that cannot import them), so that such a cluster is refused
    after the connect timeout instead of taking tasks it never finishes."""

    environment: Callable[[], dict[str, str]] | None = None
    on_start: Callable[[], None] | None = None
    name: str = "worker-setup"
    probe: Callable[[], object] | None = None

    def variables(self) -> dict[str, str]:
        return dict(self.environment()) if self.environment is not None else {}


def run_task(variables: dict[str, str], function: Callable, args: tuple):
    """``function(*args)`` in a worker after setting the submitter's ``variables`` (what every
    backend but the in-process one runs). A local worker's task stopped by SIGTERM
    (:class:`WorkerStopped`) ends the worker process once the task's cleanups have run."""
    global _IN_TASK
    os.environ.update(variables)
    _IN_TASK = True
    try:
        return function(*args)
    except WorkerStopped:
        os._exit(STOPPED_EXIT_CODE)
    finally:
        _IN_TASK = False


_IN_LOCAL_WORKER = False
"""Set in a worker process of a local pool when it starts (:func:`local_worker_started`)."""
_IN_TASK = False
"""True while :func:`run_task` runs a task in this process."""
STOPPED_EXIT_CODE = 143
"""Exit code of a local worker ended by SIGTERM (128 + 15, as a death by the signal)."""


class WorkerStopped(BaseException):
    """Raised in a local worker's running task by SIGTERM (its pool being cancelled): the task's
    ``finally`` blocks run (an atomic write removes its temporary file), then the worker ends;
    a BaseException, so that no ``except Exception`` of the task keeps it running."""


def _stop_worker(number, frame) -> None:
    """A local worker's SIGTERM handler (and SIGALRM's, for a stop re-raised after a finaliser): unwind the
    running task, or end at once when idle."""
    if _IN_TASK:
        raise WorkerStopped("stopped by SIGTERM")
    os._exit(STOPPED_EXIT_CODE)


def _unraisable_in_worker(unraisable) -> None:
    """A local worker's ``sys.unraisablehook``: a :class:`WorkerStopped` raised where Python cannot
    propagate it (a finaliser or ``__del__`` running when SIGTERM came) is not printed but raised
    again 10 ms later (SIGALRM, once the finaliser has returned), so that it unwinds the task;
    anything else is reported as usual."""
    if isinstance(unraisable.exc_value, WorkerStopped):
        import signal

        signal.signal(signal.SIGALRM, _stop_worker)
        signal.setitimer(signal.ITIMER_REAL, 0.01)
        return
    sys.__unraisablehook__(unraisable)


def local_worker_started(on_start: Callable[[], None] | None = None) -> None:
    """What a local worker process does first (the pool's initializer): it knows it is a worker
    (Python 3.9+ pool workers are not daemonic, so :func:`in_worker` cannot tell from that), and
    it ignores Ctrl-C, which the terminal sends to the whole process group: the submitting process
    alone handles it and ends its workers (no worker traceback, none left running). SIGTERM, from
    the submitting process or sent to the group, ends the worker after its task's cleanups
    (:class:`WorkerStopped`), leaving no half-written file.

    ``on_start`` (:attr:`WorkerSetup.on_start`) runs here with SIGTERM only recorded: a start-up is
    not cut in the middle (MPI's start-up handshake cut by SIGTERM makes MPI's daemon print errors);
    a SIGTERM that arrived meanwhile ends the worker when it is done. (A handler, not a blocked
    signal mask: the mask is per thread, and a library's thread would take the signal.)"""
    import signal

    global _IN_LOCAL_WORKER
    _IN_LOCAL_WORKER = True
    sys.unraisablehook = _unraisable_in_worker
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})   # a mask inherited from the spawning thread
    held: list[int] = []
    signal.signal(signal.SIGTERM, lambda number, frame: held.append(number))
    try:
        if on_start is not None:
            on_start()
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)       # again: whatever on_start's imports installed
        signal.signal(signal.SIGTERM, _stop_worker)
    if held:
        os._exit(STOPPED_EXIT_CODE)


def in_worker() -> bool:
    """True inside a task of a worker (a local worker process, or a Dask worker), where starting
    more worker processes is not allowed or would compete for the worker's core: one pool level only."""
    import multiprocessing

    if _IN_LOCAL_WORKER or multiprocessing.current_process().daemon:
        return True
    return dask_worker() is not None


def dask_worker():
    """The Dask worker running this task, else None (without importing Dask where it is not loaded)."""
    if "distributed" not in sys.modules:
        return None
    from distributed import get_worker

    try:
        return get_worker()
    except ValueError:
        return None


def worker_name() -> str:
    """Who ran a task: the Dask worker's address, else host:pid."""
    worker = dask_worker()
    return worker.address if worker is not None else f"{socket.gethostname()}:{os.getpid()}"


def worker_threads():
    """A context with one BLAS and OpenMP thread in this process, as in every worker of a many-run job
    (local workers and Dask's get THREAD_VARIABLES = 1): a threaded BLAS sums in another order, so
    tasks run here would otherwise differ in the last digits from the same tasks on a worker."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1)
