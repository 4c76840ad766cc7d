"""The validation suite (`make validate`): every selected study, its JSON file, figures and report.

Studies (SPEC §11): a accuracy, b cost, c run time against error, d time-step convergence, e MPI,
stress tests, mesh convergence (the block's and the shipped fish's); cases are computed once and cached (:mod:`.cases`, :mod:`.runner`).
"""
from __future__ import annotations

import json
import os
import platform
import sys
import time
from dataclasses import asdict
from pathlib import Path

from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
from aquarom_fenics.parallel import ClusterSettings, DaskCluster
from aquarom_fenics.io.versions import software_versions

from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.verification.validation.accuracy import study_a, study_b, study_c
from aquarom_fenics.verification.validation.calibration import study_calibration
from aquarom_fenics.verification.validation.convergence_studies import (study_d, study_fish_mesh_convergence,
                                                                        study_mesh_convergence, study_stations,
                                                                        time_convergence_summary)
from aquarom_fenics.verification.validation.figures import make_figures
from aquarom_fenics.verification.validation.report import write_report
from aquarom_fenics.verification.validation.runner import CasesCollected, Runner, compute_in_parallel
from aquarom_fenics.verification.validation.settings import Settings
from aquarom_fenics.verification.validation.stability import study_e, study_stress

STUDIES = ("a", "b", "c", "d", "e", "stress", "mesh_convergence", "stations", "fish_mesh_convergence", "calibration")

STUDY_FUNCTIONS = {"a": study_a, "b": study_b, "c": study_c, "d": study_d, "e": study_e, "stress": study_stress,
                   "mesh_convergence": study_mesh_convergence, "stations": study_stations,
                   "fish_mesh_convergence": study_fish_mesh_convergence, "calibration": study_calibration}


def run(settings: Settings, out: Path, report_path: Path, studies=STUDIES, recompute_failed=False,
        time_limit: float | None = None, stream=None, jobs: int = 1, cluster: ClusterSettings | None = None) -> dict:
    """Every selected study (missing cases first in ``jobs`` local workers when jobs > 1, or on the
    workers of the Dask scheduler ``cluster`` names), figures, report.

    The scheduler is reached first: an unreachable one is refused (InputError) before any case runs.
    """
    started = time.perf_counter()
    time_limit = time_limit or settings.time_limit
    pool = DaskCluster(cluster, SWIMMER_WORKERS) if cluster is not None and cluster.distributed else None
    try:
        runner = Runner(out, time_limit, recompute_failed=recompute_failed, stream=stream, concurrent_jobs=1)
        parallel = 0
        if jobs > 1 or pool is not None:
            collector = Runner(out, time_limit, recompute_failed=recompute_failed, stream=stream, collect=True)
            for study in studies:
                try:
                    STUDY_FUNCTIONS[study](collector, settings)
                except CasesCollected:
                    pass
            parallel = compute_in_parallel(runner, collector.collected, jobs, pool=pool)
    finally:
        if pool is not None:
            pool.shutdown()
    for study in studies:
        study_started = time.perf_counter()
        print(f"== study {study} ==", file=runner.stream, flush=True)
        result = STUDY_FUNCTIONS[study](runner, settings)
        result["settings"] = asdict(settings)
        result["written_at"] = time.strftime("%Y-%m-%d %H:%M:%S")
        result["study_time"] = time.perf_counter() - study_started
        write_json_atomic(out / f"{study}.json", result)
        if study == "d":
            write_json_atomic(out / "time_convergence.json", time_convergence_summary(result))
    info = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "versions": software_versions(), "machine": machine(),
            "quick": settings.quick, "studies": list(studies), "cases": dict(runner.counts), "jobs": jobs,
            "cluster": cluster.describe() if cluster is not None else "local worker processes",
            "computed_in_parallel": parallel, "compute_time": runner.compute_time, "command": " ".join(sys.argv)}
    figures = make_figures(out)
    info["wall_time"] = time.perf_counter() - started
    write_json_atomic(out / "run.json", info)
    history_path = out / "run_history.json"
    history = json.loads(history_path.read_text()) if history_path.exists() else []
    history.append({"date": info["date"], "wall_time": info["wall_time"], "cases": info["cases"],
                    "quick": settings.quick, "studies": list(studies), "cores": info["machine"]["cores"], "jobs": jobs,
                    "from_empty": runner.counts["cached"] == 0 and runner.counts["computed"] > 0
                    and tuple(studies) == STUDIES})
    write_json_atomic(history_path, history[-20:])
    write_report(out, report_path)
    print(f"{sum(runner.counts.values())} cases: " + ", ".join(f"{n} {what}" for what, n in runner.counts.items())
          + f"; {info['wall_time']:.1f} s; figures {len(figures)}; report {report_path}", file=runner.stream, flush=True)
    return info


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        memory = None
    return {"cores": os.cpu_count(), "cpu": cpu, "platform": platform.platform(),
            "memory_gib": memory, "hostname": platform.node()}
