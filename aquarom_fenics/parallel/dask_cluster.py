"""The workers of a running Dask distributed scheduler, given by address or scheduler file.

A worker that dies mid-task has its task run again on another worker by the scheduler. A cluster
is used only once a worker has run the caller's probe task (:func:`usable_workers`): no worker, or
workers that cannot import the caller's code, are one line after the connect timeout, never a
wait without end.
"""
from __future__ import annotations

import time
from concurrent.futures import Future
from pathlib import Path
from typing import Callable

from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel.addresses import check_address, scheduler_file_address
from aquarom_fenics.parallel.interface import WorkerSetup, run_task
from aquarom_fenics.parallel.settings import ClusterSettings


class StartOnMainThread:
    """A Dask worker plugin: the caller's ``on_start`` when a worker starts (and restarts), on its
    main thread (Dask runs tasks in a thread pool; some imports install signal handlers, which
    Python allows on the main thread only)."""

    def __init__(self, on_start: Callable[[], None], name: str):
        self.on_start = on_start
        self.name = name

    def setup(self, worker) -> None:
        self.on_start()


class DaskCluster:
    """The workers of a Dask distributed scheduler, through ``Client.get_executor``; ``setup``'s
    start function runs on each worker, its variables reach every task."""

    name = "dask"

    def __init__(self, settings: ClusterSettings, setup: WorkerSetup | None = None):
        self.settings = settings
        self.setup = setup or WorkerSetup()
        self.client = connect(settings)
        try:
            usable_workers(self.client, settings, self.setup.probe)
            if self.setup.on_start is not None:
                try:
                    self.client.register_worker_plugin(StartOnMainThread(self.setup.on_start, self.setup.name),
                                                       name=self.setup.name)
                except Exception as error:    # raised on a worker, handed back by the scheduler
                    raise worker_import_error(settings, error) from None
        except BaseException:                 # refused, or Ctrl-C while waiting: no client left open
            self.client.close()
            raise
        self._executor = self.client.get_executor(pure=False)

    @property
    def workers(self) -> int:
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def submit(self, function: Callable, *args) -> Future:
        return self._executor.submit(run_task, self.setup.variables(), function, args)

    def shutdown(self, cancel: bool = False) -> None:
        """Close the connection (the scheduler and its workers keep running); ``cancel`` first
        cancels this client's pending tasks."""
        self._executor.shutdown(wait=not cancel)
        self.client.close()


def worker_import_error(settings: ClusterSettings, error: Exception) -> Exception:
    """InputError (one line, with the fix) when the workers cannot import what their start-up needs
    (the toolkit); otherwise ``error`` itself (a bug)."""
    text = str(error)
    if isinstance(error, ImportError) or "ModuleNotFoundError" in text or "No module named" in text:
        reason = text.splitlines()[0] if text else type(error).__name__
        return InputError(f"the workers of the {settings.describe().removeprefix('Dask ')} cannot import the toolkit "
                          f"({reason}): start them with the Python of a checkout's .venv, "
                          "`.venv/bin/python -m distributed.cli.dask_worker ADDRESS --nthreads 1` "
                          "(docs/user/cluster.rst)")
    return error


def usable_workers(client, settings: ClusterSettings, probe: Callable[[], object] | None = None) -> None:
    """Wait at most ``settings.connect_timeout`` seconds for a worker of the cluster and, with a
    ``probe`` (:attr:`WorkerSetup.probe`), for a worker to run it; InputError (one line) when none
    does: no worker, workers that cannot import the caller's code (:func:`worker_import_error`), or
    a probe that fails or does not finish in time."""
    where = settings.describe()
    timeout = settings.connect_timeout
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (TimeoutError, OSError) as error:
        raise InputError(f"{where}: no worker within {timeout:g} s ({type(error).__name__}); "
                         "start workers (`dask worker ADDRESS`) or check the scheduler") from None
    if probe is None:
        return
    future = client.submit(probe, pure=False)
    try:
        future.result(timeout=timeout)
    except Exception as error:  # noqa: BLE001 — any failure of the probe is the cluster's
        future.cancel()
        refusal = worker_import_error(settings, error)
        if refusal is not error:
            raise refusal from None
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise InputError(f"{where}: no worker could run a task of the toolkit within {timeout:g} s "
                         f"({reason[:120]}); install the toolkit on the workers or check them") from None


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
               else check_address(settings.scheduler, settings.describe()))
    where = settings.scheduler or f"of {settings.scheduler_file}"
    if address.startswith("tls://") and not _tls_configured():
        raise InputError(f"Dask scheduler {where}: tls:// needs Dask's TLS settings (distributed.comm.tls.ca-file, "
                         ".client.cert and .client.key in the Dask configuration); set them, or use tcp://")
    client = Client.__new__(Client)
    try:
        client.__init__(address, timeout=timeout, set_as_default=False)
    except Exception as error:  # noqa: BLE001 — whatever Dask raises while connecting is one line
        _abandon(client)
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise InputError(f"Dask scheduler {where}: not reachable within {settings.connect_timeout:g} s "
                         f"({reason[:200]}); start it or check the address") from None
    except BaseException:                 # Ctrl-C or SIGTERM while connecting
        _abandon(client)
        raise
    return client


def _tls_configured() -> bool:
    """Whether Dask's configuration gives a client TLS context (without one, Dask's tls:// connect
    fails with a TypeError)."""
    from distributed.security import Security

    return Security().get_connection_args("client").get("ssl_context") is not None


def _abandon(client) -> None:
    """A client whose start failed, closed now and never again: Dask's finaliser would otherwise
    close it at garbage collection, seconds later, and print its own timeout as a traceback."""
    try:
        client.close(timeout=1)
    except Exception:  # noqa: BLE001 — nothing was connected; the failure is already reported
        pass
    finally:
        client.__dict__["_Client__loop"] = None     # Client.__del__ closes only a client with a loop


def _appears(path: Path, seconds: float) -> bool:
    """Whether ``path`` exists now or within ``seconds`` (a scheduler started in the same job
    script writes its file a moment later)."""
    deadline = time.monotonic() + seconds
    while not path.is_file():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.2)
    return True
