"""Where the toolkit's many independent runs go: one executor layer with two backends.

Every many-run job (a design sweep, the validation cases, the nominal FOM run beside an
optimisation) submits plain functions to a :class:`Pool`, a ``concurrent.futures``-shaped object:

* :class:`LocalProcesses` (the default): fresh interpreters on this machine (``spawn``), each with
  one BLAS/OpenMP thread; nothing to start beforehand.
* :class:`DaskCluster`: the workers of a running Dask distributed scheduler
  (``dask.distributed.Client``), given by its address (``tcp://host:8786``), by the JSON file
  ``dask scheduler --scheduler-file`` writes, or by a ``[cluster]`` table of a scene. A worker that
  dies mid-task has its task run again on another worker by the scheduler.
* :class:`InProcess`: one worker and no cluster runs each task here, at submission (serial).

A task runs with the submitting process's result cache ($AQUAROM_CACHE, see
:func:`aquarom_fenics.io.paths.cache_root`), so workers on other machines read and fill the same
content-addressed cache when it lies on a shared file system.
"""
from __future__ import annotations

import atexit
import math
import os
import socket
import sys
import time
from concurrent.futures import Future, as_completed
from contextlib import contextmanager
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

from aquarom_fenics.errors import InputError

DEFAULT_CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a Dask scheduler before the command is refused."""

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

LOCAL_RESTARTS = 2
"""Times a task whose local worker process died (killed, out of memory) is submitted again."""


@dataclass(frozen=True)
class ClusterSettings:
    """Where the work goes: a Dask scheduler (``scheduler`` address or ``scheduler_file``) or,
    with neither, local worker processes. ``connect_timeout`` [s] bounds the wait for the scheduler."""

    scheduler: str = ""
    scheduler_file: str = ""
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT

    @property
    def distributed(self) -> bool:
        return bool(self.scheduler or self.scheduler_file)

    def describe(self) -> str:
        if self.scheduler:
            return f"Dask scheduler {self.scheduler}"
        if self.scheduler_file:
            return f"Dask scheduler of {self.scheduler_file}"
        return "local worker processes"


CLUSTER_KEYS = {"scheduler": str, "scheduler_file": str, "connect_timeout": float}


def cluster_from_table(table: dict, where: str, base_dir: str = ".") -> ClusterSettings:
    """The ``[cluster]`` table of a scene or configuration file; a relative scheduler file is taken
    relative to ``base_dir`` (the file's folder). InputError names a bad key or value."""
    if not isinstance(table, dict):
        raise InputError(f"{where}: [cluster] must be a table, got {table!r}")
    values = {}
    for key, value in table.items():
        if key not in CLUSTER_KEYS:
            raise InputError(f"{where}: unknown key [cluster] {key}; valid keys: {', '.join(CLUSTER_KEYS)}")
        if CLUSTER_KEYS[key] is str and not isinstance(value, str):
            raise InputError(f"{where}: [cluster] {key} must be a string, got {value!r}")
        if CLUSTER_KEYS[key] is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise InputError(f"{where}: [cluster] {key} must be a positive number of seconds, got {value!r}")
            value = float(value)
        values[key] = value
    if values.get("scheduler") and values.get("scheduler_file"):
        raise InputError(f"{where}: [cluster] give scheduler or scheduler_file, not both")
    if values.get("scheduler_file"):
        values["scheduler_file"] = str(Path(base_dir) / values["scheduler_file"])
    return ClusterSettings(**values)


def choose_cluster(scheduler: str | None, scheduler_file: Path | None,
                   configured: ClusterSettings | None = None, connect_timeout: float | None = None) -> ClusterSettings:
    """The command line's --scheduler / --scheduler-file, else the configured ``[cluster]``, else local."""
    if scheduler and scheduler_file:
        raise InputError("--scheduler and --scheduler-file: give one of them")
    if scheduler is not None and not scheduler.strip():
        raise InputError(f"--scheduler {scheduler!r}: an empty address; give one such as tcp://head-node:8786, "
                         "or leave --scheduler out to run on local worker processes")
    if scheduler_file is not None and not str(scheduler_file).strip():
        raise InputError("--scheduler-file '': an empty file name; give the file `dask scheduler --scheduler-file` writes")
    base = configured or ClusterSettings()
    timeout = base.connect_timeout if connect_timeout is None else connect_timeout
    if not (timeout > 0 and math.isfinite(timeout)):
        raise InputError(f"--connect-timeout {timeout}: must be a positive, finite number of seconds")
    if scheduler:
        check_address(scheduler, f"--scheduler {scheduler}")
    if scheduler or scheduler_file:
        return ClusterSettings(scheduler or "", str(scheduler_file or ""), timeout)
    return ClusterSettings(base.scheduler, base.scheduler_file, timeout)


SCHEMES = ("tcp", "tls")
"""Dask protocols the toolkit connects with (ucx:// needs packages it does not install)."""
MAX_SCHEDULER_FILE_BYTES = 1024 * 1024


def check_address(address: str, where: str) -> str:
    """A Dask scheduler address ``[tcp://|tls://]host[:port]``, checked before any connection is
    made (a malformed one would fail inside ``Client`` and print a traceback from its finaliser)."""
    if not isinstance(address, str) or not address.strip() or any(c.isspace() or ord(c) < 32 for c in address):
        raise InputError(f"{where}: not a scheduler address; give one such as tcp://head-node:8786")
    scheme, separator, rest = address.partition("://")
    if not separator:
        scheme, rest = "tcp", address
    if scheme not in SCHEMES:
        raise InputError(f"{where}: the protocol {scheme}:// is not supported; use "
                         f"{' or '.join(s + '://' for s in SCHEMES)}, e.g. tcp://head-node:8786")
    host, colon, port = rest.rpartition(":") if not rest.endswith("]") else (rest, "", "")
    if not colon:
        host, port = rest, ""
    if not host or "/" in host or (colon and not (port.isdigit() and 0 < int(port) < 65536)):
        raise InputError(f"{where}: expected {scheme}://HOST:PORT with a port in 1 … 65535, e.g. tcp://head-node:8786")
    return address if separator else f"tcp://{address}"


def scheduler_file_address(path: Path) -> str:
    """The scheduler address in a ``dask scheduler --scheduler-file`` JSON file, checked (a regular
    file, JSON, an ``address`` string that :func:`check_address` accepts)."""
    from aquarom_fenics.io.readback import TEXT, load_json, record, require_regular_file

    require_regular_file(path, "scheduler file", MAX_SCHEDULER_FILE_BYTES)
    data = load_json(path, record({"address": TEXT}), "scheduler file",
                     "give the file `dask scheduler --scheduler-file FILE` writes")
    return check_address(data["address"], f"scheduler file {path}: address {data['address']!r}")


# ---------------------------------------------------------------------- running a task anywhere
def run_task(cache: str, function: Callable, args: tuple):
    """``function(*args)`` in a worker, with the submitter's result cache (what every backend runs)."""
    os.environ["AQUAROM_CACHE"] = cache
    return function(*args)


_IN_LOCAL_WORKER = False
"""Set in a worker process of :class:`LocalProcesses` when it starts (:func:`_local_worker_started`)."""


def _local_worker_started() -> None:
    """What a local worker process does first: it knows it is a worker (Python 3.9+ pool workers
    are not daemonic, so ``in_worker`` cannot tell from that), and it ignores Ctrl-C, which the
    terminal sends to the whole process group: the submitting process alone handles it and ends
    its workers (no worker traceback, none left running)."""
    import signal

    global _IN_LOCAL_WORKER
    _IN_LOCAL_WORKER = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def in_worker() -> bool:
    """True inside a task of a worker (a local worker process, or a Dask worker), where starting
    more worker processes is not allowed or would compete for the worker's core: one pool level only."""
    import multiprocessing

    if _IN_LOCAL_WORKER or multiprocessing.current_process().daemon:
        return True
    return _dask_worker() is not None


def _dask_worker():
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
    worker = _dask_worker()
    return worker.address if worker is not None else f"{socket.gethostname()}:{os.getpid()}"


def _cache_root() -> str:
    from aquarom_fenics.io.paths import cache_root

    return str(Path(cache_root()).resolve())


def worker_threads():
    """A context with one BLAS and OpenMP thread in this process, as in every worker of a many-run job
    (local workers and Dask's get THREAD_VARIABLES = 1): a threaded BLAS sums in another order, so
    tasks run here would otherwise differ in the last digits from the same tasks on a worker."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1)


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


class LocalProcesses:
    """``workers`` fresh interpreters on this machine (a spawn ``ProcessPoolExecutor``), one BLAS
    thread each; the default backend."""

    name = "local"

    def __init__(self, workers: int):
        if workers < 1:
            raise InputError(f"workers = {workers}: must be at least 1")
        self.workers = workers
        self._pool = None

    def _executor(self):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        if self._pool is None:
            for variable in THREAD_VARIABLES:
                os.environ[variable] = "1"     # the spawned workers inherit it
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_local_worker_started)
            _open_pools.add(self)
        return self._pool

    def submit(self, function: Callable, *args) -> Future:
        return self._executor().submit(run_task, _cache_root(), function, args)

    def restart(self) -> None:
        """A new set of worker processes after one died (a broken pool takes no more tasks)."""
        self.shutdown(cancel=True)

    def shutdown(self, cancel: bool = False) -> None:
        """Stop the workers: after their running tasks, or at once with ``cancel`` (running tasks
        are ended with SIGTERM)."""
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


STOP_GRACE = 5.0
"""Seconds a local worker is given to end on SIGTERM before it is killed."""

_open_pools: set = set()
"""Local pools with worker processes, ended when the interpreter exits (whatever ended the command)."""


@atexit.register
def _end_open_pools() -> None:
    for pool in list(_open_pools):
        pool.shutdown(cancel=True)


class MainThreadImports:
    """A Dask worker plugin: imports done when a worker starts (and restarts), on its main thread.

    Dask runs tasks in a thread pool, and importing gmsh installs a signal handler, which Python
    allows on the main thread only. dolfinx and the FOM are imported too, so that a long-lived
    worker's first task does not pay for them."""

    name = "aquarom-main-thread-imports"

    def setup(self, worker) -> None:
        from aquarom_fenics.geometry.gmsh_session import import_gmsh

        import_gmsh()
        import aquarom_fenics.dynamics.simulate  # noqa: F401 — dolfinx, petsc4py, the FOM


class DaskCluster:
    """The workers of a Dask distributed scheduler, through ``Client.get_executor``."""

    name = "dask"

    def __init__(self, settings: ClusterSettings):
        self.settings = settings
        self.client = connect(settings)
        try:
            usable_workers(self.client, settings)
            self.client.register_worker_plugin(MainThreadImports(), name=MainThreadImports.name)
        except BaseException:
            self.client.close()
            raise
        self._executor = self.client.get_executor(pure=False)

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def submit(self, function: Callable, *args) -> Future:
        return self._executor.submit(run_task, _cache_root(), function, args)

    def shutdown(self, cancel: bool = False) -> None:
        """Close the connection (the scheduler and its workers keep running); ``cancel`` first
        cancels this client's pending tasks."""
        self._executor.shutdown(wait=not cancel)
        self.client.close()


def _import_probe() -> str:
    """What a worker runs first: the package imports (a worker without it fails here)."""
    import aquarom_fenics

    return aquarom_fenics.__version__


def usable_workers(client, settings: ClusterSettings) -> None:
    """Wait at most ``settings.connect_timeout`` seconds for a worker of the cluster to run a task of
    the package; InputError (one line) when none does (no worker, or workers that cannot import
    aquarom_fenics), never a wait without end."""
    where = settings.scheduler or f"of {settings.scheduler_file}"
    timeout = settings.connect_timeout
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (TimeoutError, OSError) as error:
        raise InputError(f"Dask scheduler {where}: no worker within {timeout:g} s ({type(error).__name__}); "
                         "start workers (`dask worker ADDRESS`) or check the scheduler") from None
    probe = client.submit(_import_probe, pure=False)
    try:
        probe.result(timeout=timeout)
    except Exception as error:  # noqa: BLE001 — any failure of the probe is the cluster's
        probe.cancel()
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise InputError(f"Dask scheduler {where}: no worker could run a task of aquarom_fenics within {timeout:g} s "
                         f"({reason[:120]}); install the package on the workers or check them") from None


def connect(settings: ClusterSettings):
    """A ``dask.distributed.Client`` of the scheduler; InputError (one line) when it cannot be
    reached within ``settings.connect_timeout`` seconds, or its scheduler file does not appear
    within that time."""
    try:
        from distributed import Client
    except ImportError:
        raise InputError("Dask distributed is not installed (Debian package python3-distributed; "
                         "`make setup` installs it)") from None
    if settings.scheduler_file and not _appears(Path(settings.scheduler_file), settings.connect_timeout):
        raise InputError(f"scheduler file {settings.scheduler_file}: not found within {settings.connect_timeout:g} s "
                         "(written by `dask scheduler --scheduler-file FILE` when the scheduler starts)")
    timeout = f"{settings.connect_timeout:g}s"
    address = (scheduler_file_address(Path(settings.scheduler_file)) if settings.scheduler_file
               else check_address(settings.scheduler, f"Dask scheduler {settings.scheduler}"))
    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as error:
        where = settings.scheduler or f"of {settings.scheduler_file}"
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise InputError(f"Dask scheduler {where}: not reachable within {settings.connect_timeout:g} s "
                         f"({reason}); start it or check the address") from None


def _appears(path: Path, seconds: float) -> bool:
    """Whether ``path`` exists now or within ``seconds`` (a scheduler started in the same job
    script writes its file a moment later)."""
    deadline = time.monotonic() + seconds
    while not path.is_file():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.2)
    return True


def open_pool(workers: int = 1, cluster: ClusterSettings | None = None):
    """The backend for ``workers`` parallel tasks: Dask when ``cluster`` names a scheduler (its
    workers count, not ``workers``), else local processes, else (one worker) this process."""
    if cluster is not None and cluster.distributed:
        return DaskCluster(cluster)
    if workers <= 1:
        return InProcess()
    return LocalProcesses(workers)


def run_all(pool, function: Callable, items: Iterable, key: Callable = repr) -> Iterator[tuple[object, object, BaseException | None]]:
    """``function(item)`` for every item on ``pool``, yielding ``(item, result, error)`` as each
    finishes (``error`` None on success), every item exactly once.

    A local worker process that dies takes the pool down with it: the unfinished items are then
    submitted again to fresh processes, at most :data:`LOCAL_RESTARTS` times each (Dask re-runs a
    dead worker's tasks by itself).
    """
    items = list(items)
    if isinstance(pool, InProcess):      # one at a time, so that each result is seen as it is made
        for item in items:
            future = pool.submit(function, item)
            error = future.exception()
            yield item, None if error else future.result(), error
        return
    restarts = {key(item): 0 for item in items}
    waiting = items
    while waiting:
        futures = {pool.submit(function, item): item for item in waiting}
        waiting = []
        broken = False
        for future in as_completed(futures):
            item = futures[future]
            try:
                result = future.result()
            except BrokenProcessPool as error:
                broken = True
                if restarts[key(item)] < LOCAL_RESTARTS:
                    restarts[key(item)] += 1
                    waiting.append(item)
                else:
                    yield item, None, error
                continue
            except Exception as error:  # noqa: BLE001 — one task's failure is reported, not raised
                yield item, None, error
                continue
            yield item, result, None
        if broken and isinstance(pool, LocalProcesses):
            pool.restart()


@contextmanager
def shutting_down(pool):
    """``pool`` (a backend, or None to run here) for the block, shut down afterwards: its unfinished
    tasks cancelled when the block fails or is interrupted (Ctrl-C, SIGTERM), awaited otherwise."""
    try:
        yield pool
    except BaseException:
        if pool is not None:
            pool.shutdown(cancel=True)
        raise
    if pool is not None:
        pool.shutdown()
