"""Optimisation benchmark: SO1, SO2 and SO3 with both methods, and the ROM grid search over SO1's box.

Per run: wall time of the optimisation (PROM builds and solves), the FOM check timed separately
(the start design's FOM is computed before the timed runs, so the check times the optimum's FOM
and no background FOM shares the cores with the optimisation), PROM builds (every one built: the runs use a
fresh PROM cache) with what each reused (the basis of an earlier PROM, its time), iterations
re-linearised by the last PROM inside its validity radius (paper method), how it stopped, iterations, the first-order measure and the active set at the
optimum, FOM-verified ratio, and the optimisation's time over one serial FOM run of the start design on the
same mesh (timed in the same process just before, no cache: the ratio the targets are stated in). Per scene: the
trust region's FOM distance over the paper method's.
For SO1, the bound corners on the face of the paper optimum's active bounds (the other parameters
at either bound) are FOM-checked against it. The grid search builds a ROM at every point of SO1's
box at spacing 0.15 (designs the mesh check refuses are counted, not simulated) and reports its
time and best point. With ``--atlas`` each method runs again with ``[optimizer] atlas = true``, on its own
empty PROM cache. Writes results/bench/optimize.json.
"""
import argparse
import itertools
import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from aquarom_fenics.dynamics import reduced_kernel
from aquarom_fenics.dynamics.reduced_dynamics import blas_thread_pools, simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import design_space
from aquarom_fenics.studies.study import design_and_amplitude, fom_distance, run_optimization
from aquarom_fenics.io.paths import cache_root
from aquarom_fenics.reduction.basis import KEPT_FACTORS
from aquarom_fenics.reduction.kept_model import KEPT_MODEL
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]


def grid_search(scene: Scene, fish, spacing: float = 0.15) -> dict:
    axes = [np.arange(s.lower, s.upper + 1e-9, spacing) for s in scene.shapes]
    started = time.perf_counter()
    best, refused, evaluated = None, 0, 0
    for point in itertools.product(*axes):
        design = dict(zip(scene.shape_names, map(float, point)))
        try:
            rom = build_prom(scene, xi_center=design, fish=fish, parametric=False)
        except InputError:
            refused += 1
            continue
        result = simulate_reduced(rom, scene)
        evaluated += 1
        if result.completed and (best is None or result.distance > best[1]):
            best = (design, result.distance)
    return {"spacing": spacing, "points": int(np.prod([a.size for a in axes])), "evaluated": evaluated,
            "refused_by_mesh_check": refused, "time": time.perf_counter() - started,
            "best": best[0], "best_rom_distance": best[1]}


@contextmanager
def fresh_prom_cache():
    """A temporary cache root whose FOM folder is the shared one: every PROM is built (and timed),
    FOM checks already computed are reused."""
    shared_fom = cache_root() / "fom"
    shared_fom.mkdir(parents=True, exist_ok=True)
    previous = os.environ.get("AQUAROM_CACHE")
    with tempfile.TemporaryDirectory(prefix="aquarom-bench-") as root:
        (Path(root) / "fom").symlink_to(shared_fom.resolve())
        os.environ["AQUAROM_CACHE"] = root
        try:
            yield
        finally:
            if previous is None:
                del os.environ["AQUAROM_CACHE"]
            else:
                os.environ["AQUAROM_CACHE"] = previous


def bound_corners(scene: Scene, fish, result) -> list[dict]:
    """FOM distance of every corner of the box face the optimum's active bounds span (each
    inactive parameter at its lower or upper bound, the active ones at their active bound)."""
    space = result.space
    active = {row["constraint"] for row in result.optimality.active}
    choices = []
    for name, lower, upper in zip(space.names, space.lower, space.upper):
        held = [value for side, value in (("lower", lower), ("upper", upper)) if f"{name} = {side}" in active]
        choices.append(held or [lower, upper])
    corners = []
    for point in itertools.product(*choices):
        design = dict(zip(space.names, map(float, point)))
        try:
            fish.design(np.array(point))
        except InputError as refused:
            corners.append({"design": design, "fom_distance": None, "refused": str(refused)})
            continue
        corners.append({"design": design, "fom_distance": fom_distance(scene, fish, design, None)})
    return corners


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--level", type=int, default=None, help="mesh level (default: each scene's own)")
    parser.add_argument("--scenes", nargs="+", default=["so1", "so2", "so3"])
    parser.add_argument("--methods", nargs="+", default=["paper", "trust-region"])
    parser.add_argument("--atlas", action="store_true",
                        help="also run each method with [optimizer] atlas = true (its own empty PROM cache)")
    parser.add_argument("--no-grid", action="store_true", help="skip the ROM grid search (no speedup then)")
    parser.add_argument("--no-corners", action="store_true", help="skip the FOM checks of SO1's bound corners")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "bench" / "optimize.json")
    args = parser.parse_args()
    runs, corners = [], None
    for name in args.scenes:
        base = at_level(Scene.load(name), args.level)
        fish = load_fish(base)
        build_prom(base, fish=fish)        # compile the forms once, outside the timings;
        KEPT_FACTORS.release()             # but not the FOM set-up: every run sets its builds' model up, as the
        KEPT_MODEL.release()               # FOM it is divided by does (the paper run reused this one, 0.1 s)
        if reduced_kernel.available():     # and load the compiled reduced kernel (numba's cache), about 1 s a process
            reduced_kernel.warm_up()
        blas_thread_pools()                # and inspect the BLAS libraries once (0.09 s a process)
        # the start design's FOM before the timings: no background FOM run shares the cores with them
        space = design_space(base)
        fom_distance(base, fish, *design_and_amplitude(space, space.start))
        xi, amplitude = design_and_amplitude(space, space.start)
        fom_time = simulate_fom(base if amplitude is None else base.replace("actuation", amplitude=amplitude), xi,
                                fish=fish, progress=False).wall_time        # one serial FOM, no cache
        for method, atlas in itertools.product(args.methods, (False, True) if args.atlas else (False,)):
            scene = base.replace("optimizer", method=method, starts=1, atlas=atlas)
            label = f"{name}-{method}" + ("-atlas" if atlas else "")
            with fresh_prom_cache():
                result, check = run_optimization(scene, args.out.parent / "optimize-runs" / label,
                                                 fish=fish, render=False)
            runs.append({"scene": name, "method": method, "atlas": atlas, "level": base.mesh.level,
                         "degree": base.mesh.degree,
                         "cells": fish.mesh.cells.shape[0],
                         "parameters": len(base.shapes), "optimisation_time": result.timings["total"],
                         "prom_build_time": result.timings["prom_builds"], "prom_builds": result.prom_builds,
                         "prom_builds_on_an_earlier_basis": result.basis_reuses, "builds": result.build_records,
                         "surrogate_iterations": sum(row["prom"] == "surrogate" for row in result.history),
                         "iterations": result.iterations, "stop_reason": result.stop_reason,
                         "converged": result.converged, "optimality_measure": result.optimality.measure,
                         "optimality_tolerance": scene.optimizer.optimality_tolerance,
                         "active": result.optimality.active,
                         "optimum": result.space.as_dict(result.optimum),
                         "prom_distance_optimal": result.evaluation.distance,
                         "fom_start_distance": check.start_distance, "fom_optimal_distance": check.optimal_distance,
                         "fom_ratio": check.ratio, "fom_check_time": check.time, "fom_time": fom_time,
                         "optimisation_over_fom": result.timings["total"] / fom_time})
            print(runs[-1], flush=True)
            if name == "so1" and method == "paper" and not atlas and not args.no_corners:
                corners = bound_corners(scene, fish, result)
                print(corners, flush=True)
    report = {"benchmark": "optimize", "level": args.level or "each scene's own", "runs": runs,
              "trust_region_over_paper_fom_distance": _method_ratios(runs), "cores": os.cpu_count(),
              "versions": software_versions(), "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    if corners is not None:
        paper_so1 = next(r for r in runs if r["scene"] == "so1" and r["method"] == "paper" and not r["atlas"])
        report["so1_bound_corners"] = {"corners": corners, "paper_fom_distance": paper_so1["fom_optimal_distance"],
                                       "any_corner_better": any((c["fom_distance"] or -np.inf)
                                                                > paper_so1["fom_optimal_distance"] for c in corners)}
    if not args.no_grid:
        so1 = at_level(Scene.load("so1"), args.level)
        with fresh_prom_cache():
            grid = grid_search(so1, load_fish(so1))
        print(grid, flush=True)
        so1_runs = [r for r in runs if r["scene"] == "so1" and not r["atlas"]]
        report["rom_grid_search_so1"] = grid
        report["speedup_over_grid_search"] = {r["method"]: grid["time"] / r["optimisation_time"] for r in so1_runs}
    write_json_atomic(args.out, report)
    print(f"wrote {args.out}")


def at_level(scene: Scene, level: int | None) -> Scene:
    """The scene on mesh ``level``, or on its own mesh when ``level`` is None."""
    return scene if level is None else scene.replace("mesh", level=level)


def _method_ratios(runs: list[dict]) -> dict:
    """Per scene: FOM distance of the trust region's optimum over the paper method's."""
    ratios = {}
    for name in dict.fromkeys(r["scene"] for r in runs):
        by_method = {r["method"]: r["fom_optimal_distance"] for r in runs if r["scene"] == name and not r["atlas"]}
        if by_method.get("paper") and by_method.get("trust-region"):
            ratios[name] = by_method["trust-region"] / by_method["paper"]
    return ratios


if __name__ == "__main__":
    main()
