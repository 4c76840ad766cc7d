"""FOM benchmark: the 2 s reference simulation on every mesh level, serial and `mpirun -n 2`.

Writes results/bench/fom.json: cells, dofs, wall time and its split (factorisations, Newton-matrix
assembly, residuals, solves, the rest), mean Newton iterations, factorisations, peak memory,
distance and tail amplitude per element degree, level and rank count, and the -n 2 speed-up. Each
rank uses one BLAS thread; on the shipped scenes' mesh a third run is one rank with two BLAS
threads (what a serial run gets by default on two cores: MUMPS factorises with OpenBLAS).
Linear tetrahedra on --levels (default 1–5), quadratic ones on --quadratic-levels (default 1–3).
Each run records the 1-minute load average before it starts: the cores may be shared.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene

REPOSITORY = Path(__file__).resolve().parents[1]

SCENE = """name = "bench-degree{degree}-level{level}"
[mesh]
level = {level}
degree = {degree}
"""


def run_level(level: int, ranks: int, work: Path, degree: int = 1, blas_threads: int = 1) -> dict:
    """One `aquarom simulate` of the reference scene; ``blas_threads`` per rank (OpenBLAS, in MUMPS)."""
    scene = work / f"degree{degree}-level{level}.toml"
    scene.write_text(SCENE.format(level=level, degree=degree))
    out = work / f"degree{degree}-level{level}-n{ranks}-t{blas_threads}"
    shutil.rmtree(out, ignore_errors=True)
    command = [str(Path(sys.executable).with_name("aquarom")), "simulate", str(scene), "--out", str(out), "--no-progress"]
    if ranks > 1:
        command = ["mpirun", "-n", str(ranks)] + command
    environment = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                       OMP_NUM_THREADS=str(blas_threads), OPENBLAS_NUM_THREADS=str(blas_threads))
    load = os.getloadavg()[0]
    started = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True, env=environment)
    elapsed = time.perf_counter() - started
    if completed.returncode != 0:
        return {"degree": degree, "level": level, "ranks": ranks, "blas_threads": blas_threads, "load_average": load,
                "failed": completed.stderr.strip().splitlines()[-1:]}
    summary = json.loads((out / "summary.json").read_text())
    return {"degree": degree, "level": level, "ranks": ranks, "blas_threads": blas_threads,
            "cells": summary["cells"], "dofs": summary["dofs"],
            "wall_time_simulation": summary["wall_time"], "wall_time_process": elapsed,
            "time_integration": summary["timings"]["time_integration"],
            "profile_rank0": profile_split(summary["timings"]),
            "mean_newton_iterations": summary["mean_newton_iterations"],
            "newton_factorizations": summary["newton_factorizations"],
            "peak_memory_mb_rank0": summary["peak_memory_mb"], "distance": summary["distance"],
            "tail_amplitude": summary["tail_amplitude"], "load_average": load}


def profile_split(timings: dict) -> dict:
    """Rank 0's time integration split [s]: MUMPS factorisations, Newton-matrix assembly, residual
    assembly, solves, and the rest (the integrator's Python: predictor, Broyden updates, observers)."""
    newton = timings["newton"]
    parts = {key: newton[key] for key in ("factorizations", "newton_matrix_assembly", "residuals", "solves")}
    parts["python_and_other"] = timings["time_integration"] - sum(parts.values())
    parts["counts"] = newton["counts"]
    return parts


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--levels", type=int, nargs="*", default=[1, 2, 3, 4, 5], help="levels at degree 1")
    parser.add_argument("--quadratic-levels", type=int, nargs="*", default=[1, 2, 3], help="levels at degree 2")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "bench" / "fom.json")
    args = parser.parse_args()
    work = args.out.parent / "fom-runs"
    work.mkdir(parents=True, exist_ok=True)
    runs = []
    cases = [(1, level) for level in args.levels] + [(2, level) for level in args.quadratic_levels]
    default = Scene.load("nominal").mesh
    for degree, level in cases:
        two_threads = [(1, 2)] if (degree, level) == (default.degree, default.level) else []
        for ranks, threads in [(1, 1), (2, 1)] + two_threads:
            runs.append(run_level(level, ranks, work, degree, threads))
            print(json.dumps(runs[-1]), flush=True)
    speedups = {}
    for degree, level in cases:
        serial, parallel = (next(r for r in runs if (r["degree"], r["level"], r["ranks"], r["blas_threads"])
                                 == (degree, level, n, 1)) for n in (1, 2))
        if "failed" not in serial and "failed" not in parallel:
            name = f"level{level}" if degree == 1 else f"degree{degree}-level{level}"
            speedups[name] = serial["wall_time_simulation"] / parallel["wall_time_simulation"]
    write_json_atomic(args.out, {"benchmark": "fom", "horizon_s": 2.0, "time_step_s": 0.02, "runs": runs,
                                 "speedup_2_ranks": speedups, "cores": os.cpu_count(),
                                 "versions": software_versions(), "date": time.strftime("%Y-%m-%d %H:%M:%S")})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
