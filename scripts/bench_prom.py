"""PROM benchmark: build and solve costs per mesh level and number of parameters, FOM in the same run.

For each element degree and level (degree 1: --levels, default 1–5; degree 2: --quadratic-levels,
default 1–3) and p ∈ {0, 3, 5, 8} (no shapes, SO1, SO2, SO3 shape sets): the build time as a
process's first build and as a later one (K_0's factorisation analysis kept, as in an
optimisation), the later build's split (FOM set-up, vibration modes, static solves, the basis in all,
internal-force tensors, other tensors), basis time, tensor time, number of form evaluations
(vector/matrix assemblies and cell-wise expression evaluations), reduced solve time with and
without sensitivities (fastest and median of 20), and the FOM time on the same mesh.

The reduced solves (``--only solve``, quick: level-1 PROMs, no FOM): one ``simulate_reduced`` with
sensitivities (fastest and median of 20) and ``simulate_batch`` per design with the compiled kernel for batches
of 1, 10, 100 and 1000 designs with sensitivities, and for 100 designs without them and with the numpy engine
(fastest of a few runs), for SO1, SO2, SO3 and bases of 24 and 26 vectors; per scene its "targets": the CPU time of one
design (a batch of one) against 5 ms and the least per design in batches of 100 or more against 1 ms.
Writes results/bench/prom.json (``--only solve`` its "reduced_solves" entry, the rest kept).
"""
import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from aquarom_fenics.dynamics.batched import simulate_batch
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.fem import dolfinx_adapter as adapter
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.basis import KEPT_FACTORS
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]

SHAPE_SETS = {0: "nominal", 3: "so1", 5: "so2", 8: "so3"}
SOLVE_REPEATS = 20
"""Reduced solves are timed over this many runs (one run is tens of milliseconds: a single sample
carries the host's noise and the first call's set-up; the fastest of 5 varied by 40 % between
benchmark runs on an idle host)."""


def timed_runs(repeats: int, run):
    """(the result of ``run()`` with the smallest ``wall_time``, the median ``wall_time`` [s]) of
    ``repeats`` calls."""
    results = sorted((run() for _ in range(repeats)), key=lambda result: result.wall_time)
    return results[0], float(np.median([result.wall_time for result in results]))


class EvaluationCounter:
    """Counts form assemblies and expression evaluations at the dolfinx adapter's entry points."""

    def __init__(self):
        self.counts = {"vector_assemblies": 0, "matrix_assemblies": 0, "expression_evaluations": 0}
        self._wrap("assemble_vector_into", "vector_assemblies")
        self._wrap("assemble_matrix_into", "matrix_assemblies")
        self._wrap("evaluate_expression", "expression_evaluations")

    def _wrap(self, name, key):
        original = getattr(adapter, name)

        def counted(*args, **kwargs):
            self.counts[key] += 1
            return original(*args, **kwargs)

        setattr(adapter, name, counted)

    def take(self) -> dict:
        counts = dict(self.counts)
        for key in self.counts:
            self.counts[key] = 0
        return counts


SOLVE_SCENES = {"so1": {}, "so2": {}, "so3": {}, "wave-24": {"vibration_modes": 4}, "so1-26": {"vibration_modes": 4}}
"""Scenes of the reduced-solve benchmark and their [reduction] changes (wave-24: 24 basis vectors, no shape parameter; so1-26: 26 and SO1's three)."""
BATCH_SIZES = (1, 10, 100, 1000)


def random_designs(prom, count: int, seed: int = 0) -> np.ndarray:
    """``count`` designs uniform in the PROM's validity box."""
    rng = np.random.default_rng(seed)
    return prom.xi_center + prom.validity_radius * rng.uniform(-1.0, 1.0, (count, prom.n_parameters))


def batch_seconds(prom, scene, xis, repeats: int, engine: str = "compiled",
                  sensitivities: bool = True) -> tuple[float, float]:
    """(wall, CPU) seconds per design of the fastest of ``repeats`` runs of ``simulate_batch`` (the CPU time of
    the calling thread: a shared host inflates it less than the wall time)."""
    times, cpu = [], []
    for _ in range(repeats):
        result = simulate_batch(prom, scene, xis, sensitivities=sensitivities, engine=engine)
        assert result.completed.all(), [error for error in result.errors if error]
        times.append(result.wall_time / len(xis))
        cpu.append(result.timings["cpu_time"] / len(xis))
    return min(times), min(cpu)


ONE_DESIGN_TARGET, PER_DESIGN_TARGET = 5e-3, 1e-3
"""[s] of CPU with sensitivities: one design (a batch of one), and per design in a batch of 100 or more."""


def targets(cpu_per_design: dict) -> dict:
    """The issue's targets against the CPU times per design (``batch_seconds``) of a scene: one design ≤ 5 ms,
    ≤ 1 ms per design in a batch of 100 or more (both with sensitivities)."""
    one = cpu_per_design["1"]
    batched = min(value for size, value in cpu_per_design.items() if int(size) >= 100)
    return {"one_design": one, "one_design_target": ONE_DESIGN_TARGET, "one_design_met": one <= ONE_DESIGN_TARGET,
            "per_design_in_batch": batched, "per_design_target": PER_DESIGN_TARGET,
            "per_design_met": batched <= PER_DESIGN_TARGET}


def reduced_solves() -> list[dict]:
    """One reduced solve and batched solves per design, with sensitivities, per scene of SOLVE_SCENES."""
    solves = []
    for label, reduction in SOLVE_SCENES.items():
        scene = Scene.load(label.split("-")[0]).replace("mesh", level=1)
        if reduction:
            scene = scene.replace("reduction", **reduction)
        prom = build_prom(scene)
        simulate_reduced(prom, scene, sensitivities=True)                      # first-call set-up
        simulate_batch(prom, scene, random_designs(prom, 1), sensitivities=True)   # the kernel loaded
        fastest, median = timed_runs(SOLVE_REPEATS, lambda: simulate_reduced(prom, scene, sensitivities=True))
        entry = {"scene": label, "reduced_size": prom.size, "parameters": prom.n_parameters,
                 "solve_time_with_sensitivities": fastest.wall_time,
                 "solve_time_with_sensitivities_median": median, "batched_time_per_design": {},
                 "batched_cpu_time_per_design": {}}
        for size in BATCH_SIZES:
            xis = random_designs(prom, size)
            repeats = 5 if size < 100 else 2 if prom.size <= 13 else 1       # a large basis: minutes per batch
            wall, cpu = batch_seconds(prom, scene, xis, repeats)
            entry["batched_time_per_design"][str(size)] = wall
            entry["batched_cpu_time_per_design"][str(size)] = cpu
        xis = random_designs(prom, 100)
        entry["batched_time_per_design_no_sensitivities"] = {"100": batch_seconds(prom, scene, xis, 2,
                                                                                  sensitivities=False)[0]}
        entry["batched_time_per_design_numpy"] = {"100": batch_seconds(prom, scene, xis, 1, engine="numpy")[0]}
        entry["targets"] = targets(entry["batched_cpu_time_per_design"])
        solves.append(entry)
        print(entry, flush=True)
    return solves


def write_reduced_solves(path: Path) -> None:
    """The "reduced_solves" entry of the benchmark file, its other entries kept."""
    record = json.loads(path.read_text()) if path.exists() else {"benchmark": "prom"}
    record["reduced_solves"] = {"runs": reduced_solves(), "cores": os.cpu_count(), "load_average": os.getloadavg(),
                                "threads": {name: os.environ.get(name) for name in ("OMP_NUM_THREADS",
                                                                                    "OPENBLAS_NUM_THREADS")},
                                "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    write_json_atomic(path, record)
    print(f"wrote {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--only", choices=["solve"], help="only the reduced solves (single and batched)")
    parser.add_argument("--levels", type=int, nargs="*", default=[1, 2, 3, 4, 5], help="levels at degree 1")
    parser.add_argument("--quadratic-levels", type=int, nargs="*", default=[1, 2, 3], help="levels at degree 2")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "bench" / "prom.json")
    args = parser.parse_args()
    if args.only == "solve":
        write_reduced_solves(args.out)
        return
    counter = EvaluationCounter()
    runs = []
    cases = [(1, level) for level in args.levels] + [(2, level) for level in args.quadratic_levels]
    for degree, level in cases:
        fom_scene = Scene.load("nominal").replace("mesh", level=level, degree=degree)
        fom = simulate_fom(fom_scene, progress=False)
        for p, name in SHAPE_SETS.items():
            scene = Scene.load(name).replace("mesh", level=level, degree=degree)
            fish = load_fish(scene)
            build_prom(scene, fish=fish)          # compiles the forms once (JIT cache)
            KEPT_FACTORS.release()
            started = time.perf_counter()
            build_prom(scene, fish=fish)          # as a process's first build: K_0 analysed and factorised
            first_build_time = time.perf_counter() - started
            counter.take()
            started = time.perf_counter()
            prom = build_prom(scene, fish=fish)   # as the next builds of an optimisation: K_0's analysis kept
            build_time = time.perf_counter() - started
            evaluations = counter.take()
            plain, plain_median = timed_runs(SOLVE_REPEATS, lambda: simulate_reduced(prom, scene))
            with_sensitivities, sensitivities_median = timed_runs(
                SOLVE_REPEATS, lambda: simulate_reduced(prom, scene, sensitivities=True))
            runs.append({
                "degree": degree, "level": level, "cells": prom.cells, "dofs": prom.dofs, "parameters": p,
                "scene": name, "reduced_size": prom.size, "basis": prom.labels, "dropped": prom.dropped,
                "build_time": build_time, "first_build_time": first_build_time,
                "build_split": {key: value for key, value in prom.timings.items() if key != "total"},
                "basis_time": prom.timings["basis_total"],
                "tensor_time": prom.timings["internal_force_tensors"] + prom.timings["other_tensors"],
                "form_evaluations": evaluations,
                "solve_time": plain.wall_time, "solve_time_with_sensitivities": with_sensitivities.wall_time,
                "solve_time_median": plain_median, "solve_time_with_sensitivities_median": sensitivities_median,
                "distance": plain.distance, "fom_time": fom.wall_time, "fom_distance": fom.distance,
                "fom_over_prom_total_time": fom.wall_time / (build_time + plain.wall_time)})
            print({key: runs[-1][key] for key in ("degree", "level", "cells", "parameters", "reduced_size",
                                                  "build_time", "solve_time", "solve_time_with_sensitivities", "fom_time")},
                  flush=True)
    previous = json.loads(args.out.read_text()) if args.out.exists() else {}
    write_json_atomic(args.out, {"benchmark": "prom", "runs": runs, "cores": os.cpu_count(),
                                 "versions": software_versions(), "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                                 "reduced_solves": previous.get("reduced_solves")})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
