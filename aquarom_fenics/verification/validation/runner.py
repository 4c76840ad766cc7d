"""Running validation cases once: cache, progress lines, a time limit per case, parallel workers
(local processes or a Dask cluster, :mod:`aquarom_fenics.parallel`)."""
from __future__ import annotations

import logging
import os
import resource
import signal
import sys
import threading
import time
import traceback
from functools import partial
from pathlib import Path

from aquarom_fenics import __version__
from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
from aquarom_fenics.parallel import DaskCluster, LocalProcesses, run_all
from aquarom_fenics.io.persistence import get_or_compute, read_intact, write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.studies.estimate import case_seconds
from aquarom_fenics.geometry.fish_cache import shared_fish
from aquarom_fenics.verification.validation.cases import CACHED_STATUSES, Case, describe, read_record
from aquarom_fenics.verification.validation.compute import compute_fom, compute_mesh, compute_mpi, compute_reduced


class CaseTimeLimit(BaseException):
    """Raised by the alarm when a case runs past its time limit; a BaseException (like Ctrl-C), so
    that code catching Exception (e.g. a probe of gmsh's state) cannot swallow it."""


class CasesCollected(Exception):
    """Raised by a collecting Runner: the study's case list is known, nothing was run."""


class Runner:
    """Runs cases once: cached records are read, missing ones computed and written.

    ``collect`` True: ``run`` only records the cases it is given and raises CasesCollected (the
    study functions call ``run`` once each), so that a driver can list every case of a set of
    studies and compute them in parallel first (see ``compute_in_parallel``).
    """

    def __init__(self, out: Path, time_limit: float = 1800.0, recompute_failed: bool = False, stream=None,
                 collect: bool = False, concurrent_jobs: int = 1):
        self.out = Path(out)
        self.cases_dir = self.out / "cases"
        self.time_limit = float(time_limit)
        self.recompute_failed = recompute_failed
        self.stream = stream or sys.stdout
        self.collect = collect
        self.collected: list[Case] = []
        self.concurrent_jobs = concurrent_jobs
        self.outcomes: dict[str, str] = {}      # key → "cached" | "computed" | "not cached (…)", once per case
        self.this_run: dict[str, dict] = {}      # records computed in this run (also the uncached ones)
        self.computed_elsewhere: set[str] = set()
        self.compute_time = 0.0
        self._warm = set()
        logging.getLogger("aquarom").setLevel(logging.ERROR)   # dropped vectors etc. are in the records

    @property
    def counts(self) -> dict:
        counts = {"cached": 0, "computed": 0, "not cached (time limit or crash)": 0}
        for outcome in self.outcomes.values():
            counts[outcome] += 1
        return counts

    # ----------------------------------------------------------------- public
    def run(self, study: str, cases: list[Case]) -> list[dict]:
        """Records of ``cases`` in order, computing those missing; one progress line per case."""
        if self.collect:
            self.collected += cases
            raise CasesCollected(study)
        records = []
        width = len(str(len(cases)))
        for number, case in enumerate(cases, start=1):
            prefix = f"[{study} {number:>{width}}/{len(cases)}] {case.label}"
            record = self.this_run.get(case.key) or self.cached(case)
            if record is not None:
                if case.key not in self.outcomes:
                    self.outcomes[case.key] = "computed" if case.key in self.computed_elsewhere else "cached"
                done = "computed in parallel" if case.key in self.computed_elsewhere else (
                    "done" if case.key in self.this_run else "cached")
                self._say(f"{prefix}: {done} — {describe(record)}")
                records.append(record)
                continue
            self._say(f"{prefix}: computing …", end="")
            record, elapsed = self.compute_and_store(case)
            self._say(f" {elapsed:.1f} s — {describe(record)}")
            records.append(record)
        return records

    def cached(self, case: Case) -> dict | None:
        """The case's record from the cache when it is intact and usable, else None."""
        path = self.cases_dir / case.file_name
        if not path.exists():
            return None
        try:
            return read_intact(path, lambda entry: self._usable_record(case, entry))
        except ValueError:
            return None

    def _usable_record(self, case: Case, path: Path) -> dict:
        """A cached record, or ValueError: unreadable, no answer of the model, or a failure to recompute."""
        record = read_record(path)
        if record is None:
            raise ValueError("no record of a model answer")
        if self.recompute_failed and record["status"] != "completed" and case.key not in self.computed_elsewhere:
            raise ValueError(f"status {record['status']}, recomputed on request")
        return record

    def compute_and_store(self, case: Case) -> tuple[dict, float]:
        """Compute a case through the cache (stored when it is an answer of the model); (record, seconds)."""
        started = time.perf_counter()

        def compute() -> dict:
            record = self.compute(case)
            record["compute_time"] = time.perf_counter() - started
            record["concurrent_jobs"] = self.concurrent_jobs
            return record

        record = get_or_compute(self.cases_dir / case.file_name, compute,
                                save=lambda value, target: write_json_atomic(target, value),
                                load=lambda entry: self._usable_record(case, entry), label="validation cache",
                                store_if=lambda value: value["status"] in CACHED_STATUSES)
        elapsed = time.perf_counter() - started
        self.compute_time += elapsed
        self.outcomes[case.key] = ("computed" if record["status"] in CACHED_STATUSES
                                   else "not cached (time limit or crash)")
        self.this_run[case.key] = record
        return record, elapsed

    def compute(self, case: Case) -> dict:
        """The record of one case (never raises for the model's own failures)."""
        record = {"kind": case.kind, "key": case.key, "label": case.label, "scene_hash": case.scene.hash,
                  "scene": case.scene.to_dict(), "options": case.options, "version": __version__,
                  "computed_at": time.strftime("%Y-%m-%d %H:%M:%S")}
        try:
            if case.kind == "mpi":
                record.update(compute_mpi(self, case))
            else:
                compute = {"fom": compute_fom, "reduced": compute_reduced, "mesh": compute_mesh}[case.kind]
                record.update(with_time_limit(self.time_limit, lambda: compute(self, case)))
        except CaseTimeLimit:
            record.update(status="time-limit", message=f"stopped by the validation's time limit of "
                                                          f"{self.time_limit:g} s per case (not cached; rerun to retry)")
        except Exception as error:  # noqa: BLE001 — a crash of one case must not end the study
            record.update(status="crashed", message=f"{type(error).__name__}: {error}",
                          traceback=traceback.format_exc(limit=6))
        record["peak_rss_mb_process"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        return record

    def fish(self, scene: Scene):
        """load_fish, shared by cases with the same mesh, regions and shape set (and with a sweep's
        designs in the same process: :func:`aquarom_fenics.geometry.fish_cache.shared_fish`)."""
        return shared_fish(scene)

    def warm_up(self, scene: Scene, parametric: bool | None) -> None:
        """Compile (or load from the JIT cache) the forms of a model kind and run it briefly on level 1.

        Keeps form compilation and first-call costs out of the first timed case, which would bend
        the cost fits.
        ``parametric`` None: the FOM's forms.
        """
        order = scene.reduction.taylor_order if parametric and scene.shapes else 0
        key = ("fom",) if parametric is None else ("reduced", order)
        if key in self._warm:
            return
        self._warm.add(key)
        coarse = scene.replace("mesh", level=1) if not scene.mesh.file else scene
        coarse = coarse.replace("solver", duration=0.1, time_step=0.02)
        if parametric is None:
            from aquarom_fenics.dynamics.simulate import simulate_fom

            simulate_fom(coarse, fish=self.fish(coarse), progress=False)
        else:
            from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
            from aquarom_fenics.reduction.reductor import build_prom

            simulate_reduced(build_prom(coarse, fish=self.fish(coarse), parametric=parametric), coarse,
                             sensitivities=True)

    def _say(self, text: str, end: str = "\n") -> None:
        print(text, end=end, file=self.stream, flush=True)


_WORKER: Runner | None = None
"""The Runner of a worker process, made by its first case and kept for the cases after it (the
mesh and the warmed-up forms are reused)."""


def estimated_cost(case: Case) -> float:
    """A rough run time [s] of a case (:func:`aquarom_fenics.studies.estimate.case_seconds`, on the
    cells of the mesh recipe), to start the longest cases first."""
    return case_seconds(case.kind, case.scene, bool(case.options.get("parametric")))


def compute_case(settings: tuple, case: Case) -> tuple[dict, float]:
    """A worker's ``compute_and_store(case)``; ``settings`` = (out, time_limit, recompute_failed, jobs)."""
    global _WORKER
    out, time_limit, recompute_failed, jobs = settings
    if _WORKER is None or (_WORKER.out, _WORKER.time_limit, _WORKER.recompute_failed,
                           _WORKER.concurrent_jobs) != (Path(out), float(time_limit), recompute_failed, jobs):
        _WORKER = Runner(out, time_limit, recompute_failed, stream=open(os.devnull, "w"), concurrent_jobs=jobs)
    return _WORKER.compute_and_store(case)


def compute_in_parallel(runner: Runner, cases: list[Case], jobs: int, pool=None) -> int:
    """Compute the missing (non-MPI) cases on ``jobs`` local worker processes, or on ``pool`` (an
    open backend of :mod:`aquarom_fenics.parallel`, e.g. a Dask cluster; left open), longest first.

    Local workers are fresh interpreters (spawn), each with one BLAS thread; their records are
    written to the cache as usual (on a cluster ``runner.out`` must be on a shared file system),
    and the uncached outcomes (time limit, crash) are handed to ``runner`` so that the studies do
    not retry them in the same run. Returns the number of cases computed.
    """
    pending = {}
    for case in cases:
        if case.kind != "mpi" and case.key not in pending and runner.cached(case) is None:
            pending[case.key] = case
    if not pending:
        return 0
    order = sorted(pending.values(), key=estimated_cost, reverse=True)
    own_pool = pool is None
    pool = LocalProcesses(jobs, SWIMMER_WORKERS) if own_pool else pool
    where = (f"on {pool.workers} workers of the {pool.settings.describe()}" if isinstance(pool, DaskCluster)
             else f"with {pool.workers} parallel workers")
    print(f"== computing {len(order)} missing cases {where} (longest first) ==", file=runner.stream, flush=True)
    width = len(str(len(order)))
    settings = (str(runner.out.resolve()), runner.time_limit, runner.recompute_failed, jobs)
    try:
        finished = run_all(pool, partial(compute_case, settings), order, key=lambda case: case.key)
        for number, (case, outcome, error) in enumerate(finished, start=1):
            prefix = f"[parallel {number:>{width}}/{len(order)}] {case.label}"
            if error is not None:   # a dead worker: the studies compute the case again
                print(f"{prefix}: worker failed ({type(error).__name__}: {error}); computed again below",
                      file=runner.stream, flush=True)
                continue
            record, elapsed = outcome
            if record["status"] in CACHED_STATUSES:
                runner.computed_elsewhere.add(case.key)
            else:
                runner.this_run[case.key] = record
                runner.outcomes[case.key] = "not cached (time limit or crash)"
            print(f"{prefix}: {elapsed:.1f} s — {describe(record)}", file=runner.stream, flush=True)
    finally:
        if own_pool:
            pool.shutdown()
    return len(order)


RAISE_AGAIN = 0.1
"""Seconds between the alarms after a case's time limit, until the case has unwound."""


def with_time_limit(seconds: float, function):
    """``function()`` under a SIGALRM time limit (raises CaseTimeLimit).

    Signals reach the main thread only: in another thread (a Dask worker runs its tasks in a
    thread pool) ``function()`` runs without the limit. Once the limit is reached the alarm comes
    again every :data:`RAISE_AGAIN` seconds until ``function()`` has unwound: a CaseTimeLimit raised
    where it cannot propagate (a ``__del__`` or a finaliser running at that moment, a C++ call that
    catches every exception) is not lost. The first statement of the ``finally`` (a store, where no
    signal handler can run) ends the raising, so no alarm escapes the call.
    """
    if threading.current_thread() is not threading.main_thread():
        return function()
    running = [True]

    def on_alarm(signum, frame):
        if running[0]:
            raise CaseTimeLimit(f"time limit of {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds, RAISE_AGAIN)
    try:
        return function()
    finally:
        running[0] = False
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
