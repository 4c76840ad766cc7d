"""Choosing a pool, running a list of items on it, and shutting it down whatever happens."""
from __future__ import annotations

from concurrent.futures import as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator

from aquarom_fenics.parallel.dask_cluster import DaskCluster
from aquarom_fenics.parallel.in_process import InProcess
from aquarom_fenics.parallel.interface import WorkerSetup
from aquarom_fenics.parallel.local import LocalProcesses
from aquarom_fenics.parallel.settings import ClusterSettings

LOCAL_RESTARTS = 2
"""Times a task whose local worker process died (killed, out of memory) is submitted again."""


def open_pool(workers: int = 1, cluster: ClusterSettings | None = None, setup: WorkerSetup | None = None):
    """The backend for ``workers`` parallel tasks: Dask when ``cluster`` names a scheduler (its
    workers count, not ``workers``), else local processes, else (one worker) this process."""
    if cluster is not None and cluster.distributed:
        return DaskCluster(cluster, setup)
    if workers <= 1:
        return InProcess()
    return LocalProcesses(workers, setup)


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
