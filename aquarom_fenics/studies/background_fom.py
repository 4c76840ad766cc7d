"""The start design's FOM run in a worker process while the optimiser works.

The FOM check after an optimisation needs two FOM runs, the start design's and the
optimum's. The start design's is known before the optimisation starts: on a single MPI rank with a
spare core, a worker of the pool layer (:mod:`aquarom_fenics.parallel`: one local process,
or a Dask cluster's worker) runs it meanwhile and stores its distance in the FOM cache
(``fom_cache.fom_distance``), where the check finds it. If the run fails or is still running when the
check has finished the optimum's run and waited as long again, the check runs it itself.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import os
import time

from mpi4py import MPI

from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
from aquarom_fenics.parallel import LocalProcesses, in_worker
from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")

GRACE = 60.0
"""Seconds the check waits for the worker beyond the duration of its own FOM run."""


def start_fom(scene: Scene, design: dict[str, float], amplitude: float | None) -> float:
    """``fom_distance`` at the design, stored in the FOM cache (what the worker runs; its progress
    bar and log lines are discarded)."""
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.studies.fom_cache import fom_distance

    with open(os.devnull, "w") as sink, contextlib.redirect_stderr(sink), contextlib.redirect_stdout(sink):
        return fom_distance(scene, load_fish(scene), design, amplitude)


class BackgroundFom:
    """A worker computing ``fom_distance(scene, fish, design, amplitude)`` into the FOM cache.

    ``pool``: a backend of :mod:`aquarom_fenics.parallel` to run it on (left open); None: a local
    worker process of its own, ended by :meth:`finish` or :meth:`stop`.
    """

    def __init__(self, scene: Scene, design: dict[str, float], amplitude: float | None, pool=None):
        self.own_pool = pool is None
        self.pool = LocalProcesses(1, SWIMMER_WORKERS) if pool is None else pool
        self.started = time.perf_counter()
        self.future = self.pool.submit(start_fom, scene, design, amplitude)
        log.info("FOM check: the start design's FOM runs in a background worker during the optimisation")

    def finish(self, patience: float) -> None:
        """Wait for the worker at most ``patience`` + GRACE seconds, then stop it."""
        try:
            self.future.result(timeout=patience + GRACE)
        except concurrent.futures.TimeoutError:
            log.warning("FOM check: the background run of the start design is still running after %.0f s; "
                        "stopping it and running it here", time.perf_counter() - self.started)
        except Exception as error:  # noqa: BLE001 — the check runs the design itself
            log.warning("FOM check: the background run of the start design failed (%s: %s); running it here",
                        type(error).__name__, error)
        self.stop()

    def stop(self) -> None:
        """End the run (optimisation interrupted or failed, or finished): cancel the task; an own
        worker process still running it is ended at once (SIGTERM), an idle one closed."""
        running = not self.future.done()
        self.future.cancel()
        if self.own_pool:
            self.pool.shutdown(cancel=running)


def start_if_useful(scene: Scene, design: dict[str, float], amplitude: float | None, cached: bool) -> BackgroundFom | None:
    """A background run of the start design's FOM, or None: on several MPI ranks (they use the cores), on one
    core, inside a worker of a parallel sweep (the other workers use the cores), when the start
    distance is in the cache already, or for a scene with a shape field registered in this process
    (a fresh worker process does not know it)."""
    from aquarom_fenics.geometry.shape_registry import uses_registered

    if cached or MPI.COMM_WORLD.size > 1 or (os.cpu_count() or 1) < 2 or in_worker() \
            or uses_registered(scene.shape_names):
        return None
    return BackgroundFom(scene, design, amplitude)
