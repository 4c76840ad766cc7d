"""Sweep benchmark: a 16-design FOM sweep at mesh level 1 (degree 2 unless --degree 1) in this process (serial), on 2 local worker
processes and on a Dask LocalCluster of 2 worker processes (TCP, one thread each).

Every backend starts from an empty result cache (each computes all 16 designs; the compiled forms
and the level-1 mesh are warmed once before). Reported per backend: wall time of the sweep, the
sum of the designs' own run times (``wall_time_s`` of sweep.csv), the speed-up against the serial
run, and the scheduling overhead per task,

    overhead = (wall time × workers − Σ task time) / tasks,

the worker time per design not spent running a model (process start, imports, hand-out of tasks,
idle time at the end). A fresh worker's first task also imports dolfinx and loads the mesh and
compiled forms (the serial run has them warm): ``first_tasks_extra`` = Σ task time − designs ×
median task time estimates that start-up. The distances of the three runs are compared bit for bit.
The Dask cluster is started before the clock starts (a running cluster is what --scheduler uses);
its start-up time is reported apart. Writes results/bench/sweep.json.

    .venv/bin/python scripts/bench_sweep.py            # ~5 min on 2 cores (--degree 1: ~1 min)
"""
from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]

SCENE = {"name": "bench-sweep", "mesh": {"level": 1}, "solver": {"duration": 2.0},
         "shapes": {"z_tail": {"bounds": [-0.3, 0.3]}, "y_thin": {"bounds": [0.0, 0.1]}}, "output": {"plots": False}}
GRID = ["z_tail=-0.3:0.3:4", "y_thin=0:0.1:4"]
"""4 × 4 = 16 designs (--per-axis changes the 4)."""


def timed_sweep(scene, designs, pool, folder: Path) -> dict:
    """One sweep from an empty cache on ``pool``: wall time, rows."""
    from aquarom_fenics.studies.sweep import run_sweep

    os.environ["AQUAROM_CACHE"] = str(folder / "cache")
    started = time.perf_counter()
    rows = run_sweep(scene, designs, "fom", folder / "out", pool)
    return {"wall_time": time.perf_counter() - started, "rows": rows}


def summary(name: str, workers: int, run: dict, serial_wall: float | None) -> dict:
    rows = run["rows"]
    task_time = sum(row["wall_time_s"] for row in rows)
    median = sorted(row["wall_time_s"] for row in rows)[len(rows) // 2]
    return {"backend": name, "workers": workers, "designs": len(rows), "wall_time": run["wall_time"],
            "task_time_sum": task_time, "mean_task_time": task_time / len(rows),
            "median_task_time": median, "first_tasks_extra": task_time - median * len(rows),
            "speedup": None if serial_wall is None else serial_wall / run["wall_time"],
            "overhead_per_task": (run["wall_time"] * workers - task_time) / len(rows),
            "completed": sum(row["status"] == "completed" for row in rows),
            "workers_seen": sorted({row["worker"] for row in rows})}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "bench" / "sweep.json")
    parser.add_argument("--per-axis", type=int, default=4, help="grid values per shape (default 4: 16 designs)")
    parser.add_argument("--duration", type=float, default=2.0, help="horizon of each FOM run [s] (default 2)")
    parser.add_argument("--degree", type=int, default=2, choices=(1, 2),
                        help="element degree (default 2, the shipped scenes'; a degree-1, level-1 run takes "
                             "about 1 s, less than a worker's start-up)")
    args = parser.parse_args()
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[variable] = "1"
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")     # Dask's configuration, read by the workers too
    from distributed import LocalCluster

    from aquarom_fenics.dynamics.simulate import simulate_fom
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.parallel import ClusterSettings, DaskCluster, InProcess, LocalProcesses
    from aquarom_fenics.io.versions import software_versions
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.io.scene import scene_from_dict
    from aquarom_fenics.studies.sweep import grid_designs
    from aquarom_fenics.verification.validation.suite import machine


    scene = (scene_from_dict(SCENE, source="bench_sweep.py").replace("solver", duration=args.duration)
             .replace("mesh", degree=args.degree))
    grid = [spec.rsplit(":", 1)[0] + f":{args.per_axis}" for spec in GRID]
    designs = grid_designs(grid, scene)
    simulate_fom(scene.replace("solver", duration=0.1), progress=False)    # compiled forms and mesh, warmed
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench-sweep-") as scratch:
        scratch = Path(scratch)
        serial = timed_sweep(scene, designs, InProcess(), scratch / "serial")
        runs.append(summary("serial (this process)", 1, serial, None))
        print(f"serial: {serial['wall_time']:.1f} s", flush=True)
        local = LocalProcesses(2, SWIMMER_WORKERS)
        try:
            result = timed_sweep(scene, designs, local, scratch / "local")
        finally:
            local.shutdown()
        runs.append(summary("local processes", 2, result, serial["wall_time"]))
        print(f"local, 2 workers: {result['wall_time']:.1f} s", flush=True)
        started = time.perf_counter()
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tcp://",
                          dashboard_address=None, silence_logs=logging.ERROR) as cluster:
            cluster_start = time.perf_counter() - started
            pool = DaskCluster(ClusterSettings(scheduler=cluster.scheduler_address), SWIMMER_WORKERS)
            try:
                dask = timed_sweep(scene, designs, pool, scratch / "dask")
            finally:
                pool.shutdown()
        runs.append(summary("dask LocalCluster (TCP)", 2, dask, serial["wall_time"]) | {"cluster_start": cluster_start})
        print(f"dask, 2 workers: {dask['wall_time']:.1f} s (cluster start {cluster_start:.1f} s)", flush=True)
        distances = [[row["distance_m"] for row in run["rows"]] for run in (serial, result, dask)]
    report = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(), "versions": software_versions(),
              "load_average_at_end": os.getloadavg(), "scene": SCENE | {"solver": {"duration": args.duration}, "mesh": {"level": 1, "degree": args.degree}}, "grid": grid, "designs": len(designs),
              "steps_per_design": scene.n_steps, "runs": runs,
              "identical_distances": distances[0] == distances[1] == distances[2],
              "definition": "overhead_per_task = (wall_time * workers - task_time_sum) / designs"}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, report)
    for run in runs[1:]:
        print(f"{run['backend']}: speed-up {run['speedup']:.2f}, overhead {run['overhead_per_task']:.2f} s per task")
    print(f"identical distances: {report['identical_distances']}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
