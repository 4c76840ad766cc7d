"""An optimisation study end to end: optimise with the PROM, verify with the FOM, write the report."""
from __future__ import annotations

import csv
import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from .cache import cache_root, entry_key, read_intact, require_cache_writable, store
from .cost import CostWeights, design_space
from .errors import InputError, Interrupted, SolverError
from .fish import Fish, load_fish
from .optimize import DEFAULT_MAX_TIME, Checkpoint, OptimizationResult, history_columns, optimize
from .outputs import software_versions, write_json_atomic
from .scene import Scene
from .simulate import simulate_fom

log = logging.getLogger("aquarom")


@dataclass
class FomCheck:
    """FOM distances [m] of the nominal (start) and optimal designs and their ratio.

    A FOM run that stops leaves its distance None and the reason in ``error``.
    """

    nominal_distance: float | None
    optimal_distance: float | None
    prom_nominal_distance: float
    prom_optimal_distance: float
    time: float
    error: str | None = None

    @property
    def ratio(self) -> float | None:
        if self.nominal_distance is None or self.optimal_distance is None:
            return None
        return self.optimal_distance / self.nominal_distance


def fom_distance(scene: Scene, fish: Fish, design: dict[str, float], amplitude: float | None) -> float:
    """Swimming distance of the FOM at a design, cached by scene hash, design and amplitude."""
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    path = cache_root() / "fom" / f"{entry_key('fom', scene.hash, sorted(design.items()))}.json"
    if path.exists():
        distance = read_intact(path, lambda entry: json.loads(entry.read_text())["distance"])
        if distance is not None:
            log.info("FOM at %s: reused from the cache (%s)", design, path.name)
            return distance
    require_cache_writable("fom")
    result = simulate_fom(scene, design, fish=fish, progress=MPI.COMM_WORLD.rank == 0)
    if not result.completed:
        raise SolverError(f"FOM at {design} stopped: {result.error}")
    if MPI.COMM_WORLD.rank == 0:
        entry = {"design": design, "scene_hash": scene.hash, "distance": result.distance}
        store(path, lambda target: write_json_atomic(target, entry))
    return result.distance


def fom_check(scene: Scene, fish: Fish, result: OptimizationResult) -> FomCheck:
    started = time.perf_counter()
    space = result.space
    shapes = space.n_shapes

    def split(z):
        return dict(zip(space.names[:shapes], map(float, z[:shapes]))), (float(z[-1]) if space.with_amplitude else None)

    distances, errors = [], []
    for z in (space.start, result.optimum):
        try:
            distances.append(fom_distance(scene, fish, *split(z)))
        except SolverError as failure:
            distances.append(None)
            errors.append(str(failure))
    first_built = next(row for row in result.history if row["prom"] == "built")
    return FomCheck(*distances, first_built["distance"], result.evaluation.distance,
                    time.perf_counter() - started, "; ".join(errors) or None)


def run_optimization(scene: Scene, out_dir: Path, resume: bool = False, weights: CostWeights | None = None,
                     fish: Fish | None = None, render: bool = True,
                     max_time: float = DEFAULT_MAX_TIME) -> tuple[OptimizationResult, FomCheck]:
    """Optimise, check with the FOM and write history.csv, summary.json, plots, renders, XDMF.

    A checkpoint to resume from is validated before anything is written; Ctrl-C leaves the
    history, a valid checkpoint and a summary.json with the stop reason.
    """
    out_dir = Path(out_dir)
    is_writer = MPI.COMM_WORLD.rank == 0
    space = design_space(scene)
    checkpoint = out_dir / "checkpoint.json"
    if resume and not checkpoint.exists():
        raise InputError(f"--resume: no checkpoint in {out_dir}; run without --resume")
    saved = Checkpoint(checkpoint, scene, scene.optimizer.method).load() if resume else None
    require_cache_writable()
    fish = fish or load_fish(scene)
    if is_writer:
        out_dir.mkdir(parents=True, exist_ok=True)
    history_file = out_dir / "history.csv"
    writer = HistoryWriter(history_file, history_columns(space), saved["history"] if saved else []) if is_writer else None
    try:
        result = optimize(scene, fish=fish, weights=weights, checkpoint_path=checkpoint, resume=resume,
                          on_iteration=writer.write if writer else None, write_checkpoint=is_writer,
                          max_time=max_time)
        check = fom_check(scene, fish, result)
    except KeyboardInterrupt as stop:
        rows = writer.rows if writer else 0
        reason = f"{stop or 'interrupted'}" if isinstance(stop, Interrupted) else "interrupted (Ctrl-C)"
        if is_writer:
            writer.close()
            write_json_atomic(out_dir / "summary.json", {
                "scene": scene.name, "scene_hash": scene.hash, "method": scene.optimizer.method, "completed": False,
                "stop_reason": f"{reason} after {rows} history row(s)", "history": history_file.name,
                "resume": f"aquarom optimize {scene.source} --out {out_dir} --resume"})
        raise Interrupted(f"{reason} after {rows} history row(s); continue with --resume") from None
    if is_writer:
        writer.close()
        _write_summary(out_dir, scene, result, check, weights or CostWeights())
        _write_figures(out_dir, scene, fish, result, render)
    return result, check


class HistoryWriter:
    """history.csv, one row per iteration in the columns of :func:`history_columns`, flushed at
    once; a resumed run starts from the checkpoint's rows (a row written after the last
    checkpoint is made again, not duplicated)."""

    def __init__(self, path: Path, columns: list[str], checkpoint_rows: list[dict]):
        self.stream = open(path, "w", newline="")
        self.header = columns
        self.rows = 0
        csv.writer(self.stream).writerow(self.header)
        for row in checkpoint_rows:
            self.write(row)

    def write(self, row: dict) -> None:
        csv.writer(self.stream).writerow([_csv_value(row.get(key)) for key in self.header])
        self.stream.flush()
        self.rows += 1

    def close(self) -> None:
        self.stream.close()


def _csv_value(value):
    """An empty cell for a missing value (a JSON null in a resumed row is the same as None)."""
    return "" if value is None else value


def _write_summary(out_dir, scene, result, check, weights):
    space = result.space
    summary = {
        "scene": scene.name, "scene_hash": scene.hash, "method": scene.optimizer.method,
        "optimum": space.as_dict(result.optimum), "start": space.as_dict(space.start),
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(space.names, space.lower, space.upper)},
        "bounds_active": space.active_bounds(result.optimum), "stop_reason": result.stop_reason,
        "iterations": result.history[-1]["iteration"], "prom_builds": result.builds,
        "prom_builds_reused_from_cache": result.reused, "prom_size": result.prom_size,
        "cost_weights": {"distance": weights.distance, "energy": weights.energy, "alpha": weights.alpha},
        "prom_distance_optimal": result.evaluation.distance,
        "fom_check": {"nominal_distance": check.nominal_distance, "optimal_distance": check.optimal_distance,
                      "prom_nominal_distance": check.prom_nominal_distance,
                      "prom_optimal_distance": check.prom_optimal_distance, "ratio": check.ratio,
                      "error": check.error},
        "timings": result.timings | {"fom_check": check.time},
        "time_per_build": result.timings["prom_builds"] / max(result.builds, 1),
        "versions": software_versions()}
    write_json_atomic(out_dir / "summary.json", summary)


def _write_figures(out_dir, scene, fish, result, render):
    from .report import plot_optimization_history, render_nominal_and_optimal

    space = result.space
    if scene.output.plots:
        plot_optimization_history(result.history, list(space.names), list(zip(space.lower, space.upper)), out_dir)
    shapes = space.n_shapes
    optimal = dict(zip(space.names[:shapes], map(float, result.optimum[:shapes])))
    if render and scene.output.render and shapes:
        from .render import render_design

        render_design(fish, fish.design(optimal), optimal, out_dir / "optimal")
        nominal = dict(zip(space.names[:shapes], map(float, space.start[:shapes])))
        render_nominal_and_optimal(fish, fish.design(nominal), fish.design(optimal), out_dir / "nominal_vs_optimal.png",
                                   f"{scene.name}: nominal and optimal design")


def pareto_sweep(scene: Scene, out_dir: Path, fish: Fish | None = None) -> list[dict]:
    """Co-optimisation over the scene's weights w_1 (w_2 = 1 - w_1): pareto.csv and pareto.png."""
    fish = fish or load_fish(scene)
    co = scene.cooptimization
    points = []
    for w1 in co.weights:
        weights = CostWeights(distance=w1, energy=1.0 - w1, alpha=co.energy_weight)
        result, check = run_optimization(scene, Path(out_dir) / f"w1_{w1:g}", weights=weights, fish=fish, render=False)
        amplitude = float(result.optimum[-1])
        points.append({"w1": w1, "amplitude": amplitude, "energy": weights.energy_term(amplitude),
                       "distance": check.optimal_distance if check.optimal_distance is not None else float("nan"),
                       "prom_distance": result.evaluation.distance,
                       **{f"xi_{n}": float(v) for n, v in zip(result.space.names[:-1], result.optimum[:-1])}})
    if MPI.COMM_WORLD.rank == 0:
        with open(Path(out_dir) / "pareto.csv", "w", newline="") as stream:
            writer = csv.DictWriter(stream, fieldnames=list(points[0]))
            writer.writeheader()
            writer.writerows(points)
        from .report import plot_pareto

        plot_pareto(points, Path(out_dir) / "pareto.png")
    return points
