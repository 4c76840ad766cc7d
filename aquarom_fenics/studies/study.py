"""An optimisation study end to end: optimise with the PROM, verify with the FOM, write the report."""
from __future__ import annotations

import csv
import io
import logging
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.studies.background_fom import BackgroundFom, start_if_useful
from aquarom_fenics.studies.fom_cache import fom_cache_path, fom_distance
from aquarom_fenics.optimization.cost import CostWeights, amplitude_of, design_space, scene_at
from aquarom_fenics.errors import InputError, Interrupted, SolverError
from aquarom_fenics.parallel import worker_threads
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.optimization.history import Checkpoint, design_columns, history_columns
from aquarom_fenics.optimization.optimize import DEFAULT_MAX_TIME, OptimizationResult, optimization_space, optimize
from aquarom_fenics.optimization.screen import multistart_starts
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.io.outputs import holds_file
from aquarom_fenics.io.run_record import check_run_record, write_run_record
from aquarom_fenics.io.tables import IncrementalCSV
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import require_cache_writable, write_json_atomic, write_text_atomic
from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")


@dataclass
class FomCheck:
    """FOM distances [m] of the start and optimal designs and their ratio.

    A FOM run that stops leaves its distance None and the reason in ``error``; the PROM's start
    distance is None for a run from another start (multi-start).
    """

    start_distance: float | None
    optimal_distance: float | None
    prom_start_distance: float | None
    prom_optimal_distance: float
    time: float
    error: str | None = None

    @property
    def ratio(self) -> float | None:
        if self.start_distance is None or self.optimal_distance is None:
            return None
        return self.optimal_distance / self.start_distance


def design_and_amplitude(space, z: np.ndarray) -> tuple[dict[str, float], float | None]:
    """The shape values of z by name, and the amplitude A when it is optimised too."""
    shapes = space.n_shapes
    return dict(zip(space.names[:shapes], map(float, z[:shapes]))), amplitude_of(space, z)


def fom_check(scene: Scene, fish: Fish, result: OptimizationResult,
              start_run: BackgroundFom | None = None) -> FomCheck:
    """FOM distances of the scene's start design (its start point) and of the optimum; the optimum
    first, while the start design's ``start_run`` (if any) finishes in the background."""
    started = time.perf_counter()
    space = result.space
    errors = []

    def distance(z):
        try:
            return fom_distance(scene_at(scene, space, z), fish, *design_and_amplitude(space, z))
        except SolverError as failure:
            errors.append(str(failure))
            return None

    start = design_space(scene).start
    optimal_distance = distance(result.optimum)
    if start_run is not None:
        start_run.finish(patience=time.perf_counter() - started)
    start_distance = distance(start)
    first_built = next(row for row in result.history if row["prom"] == "built")
    prom_start = first_built["distance"] if np.array_equal(space.start, start) else None
    return FomCheck(start_distance, optimal_distance, prom_start, result.evaluation.distance,
                    time.perf_counter() - started, "; ".join(errors[::-1]) or None)


def checkpoint_pattern(scene: Scene) -> str:
    """Where an optimisation's output folder keeps its checkpoint: at the top, or one per multi-start run."""
    return "start_*/checkpoint.json" if scene.optimizer.multistart else "checkpoint.json"


def run_optimization(scene: Scene, out_dir: Path, resume: bool = False, weights: CostWeights | None = None,
                     fish: Fish | None = None, render: bool = True, max_time: float = DEFAULT_MAX_TIME,
                     start: np.ndarray | None = None, pool=None) -> tuple[OptimizationResult, FomCheck]:
    """Optimise, check with the FOM and write history.csv, summary.json, plots, renders, XDMF.

    From ``start`` when given; otherwise ``[optimizer] starts`` > 1 or a screen runs :func:`run_multistart`
    (its starts on ``pool`` when given). A checkpoint to resume from is validated before anything
    is written; Ctrl-C leaves the history, a valid checkpoint and a summary.json with the stop reason.
    """
    if start is None and scene.optimizer.multistart:
        return run_multistart(scene, out_dir, resume, weights, fish, render, max_time, pool=pool)
    out_dir = Path(out_dir)
    is_writer = MPI.COMM_WORLD.rank == 0
    space = design_space(scene)
    checkpoint = out_dir / "checkpoint.json"
    if resume and not checkpoint.exists():
        raise InputError(f"--resume: no checkpoint in {out_dir}; run without --resume")
    record = optimization_record(scene, weights, start)
    if resume:                 # another run's folder is refused before its checkpoint is read ...
        check_run_record(out_dir, record, warn_if_missing=False)
    saved = Checkpoint(checkpoint, scene, scene.optimizer.method).load() if resume else None
    if resume:                 # ... and an older version's (no run.json) is resumed with a warning
        check_run_record(out_dir, record)
    require_cache_writable()
    fish = fish or load_fish(scene)
    if is_writer:
        out_dir.mkdir(parents=True, exist_ok=True)
        write_run_record(out_dir, record)
    history_file = out_dir / "history.csv"
    writer = HistoryWriter(history_file, history_columns(space), saved["history"] if saved else []) if is_writer else None
    start_design = design_and_amplitude(space, space.start)
    start_scene = scene_at(scene, space, space.start)
    start_run = start_if_useful(start_scene, *start_design, cached=fom_cache_path(start_scene, *start_design).exists())
    try:
        result = optimize(scene, fish=fish, weights=weights, checkpoint_path=checkpoint, resume=resume,
                          on_iteration=writer.write if writer else None, write_checkpoint=is_writer,
                          max_time=max_time, start=start)
        check = fom_check(scene, fish, result, start_run)
    except BaseException as stop:
        if start_run is not None:
            start_run.stop()
        if not isinstance(stop, KeyboardInterrupt):
            raise
        rows = writer.rows if writer else 0
        reason = f"{stop or 'interrupted'}" if isinstance(stop, Interrupted) else "interrupted (Ctrl-C)"
        if is_writer:
            writer.close()
            write_json_atomic(out_dir / "summary.json", {
                "scene": scene.name, "scene_hash": scene.hash, "method": scene.optimizer.method, "completed": False,
                "stop_reason": f"{reason} after {rows} history row(s)", "history": history_file.name,
                "resume": f"aquarom optimize {scene.source} --out {out_dir} --resume"})
        kind = type(stop) if isinstance(stop, Interrupted) else Interrupted
        raise kind(f"{reason} after {rows} history row(s); continue with --resume") from None
    if is_writer:
        writer.close()
        _write_summary(out_dir, scene, result, check, weights or CostWeights())
    _write_figures(out_dir, scene, fish, result, render)
    return result, check


def optimization_record(scene: Scene, weights: CostWeights | None, start: np.ndarray | None) -> dict:
    """What makes an optimisation's answers, compared by --resume (run.json): the scene's hash,
    the method, the cost weights (w_1, w_2, α) and the start point of a multi-start's run."""
    weights = weights or CostWeights()
    return {"command": "optimize", "scene_hash": scene.hash, "method": scene.optimizer.method,
            "cost_weights": [weights.distance, weights.energy, weights.alpha],
            "start": None if start is None else np.asarray(start, dtype=float).tolist()}


def run_multistart(scene: Scene, out_dir: Path, resume: bool = False, weights: CostWeights | None = None,
                   fish: Fish | None = None, render: bool = True,
                   max_time: float = DEFAULT_MAX_TIME, pool=None) -> tuple[OptimizationResult, FomCheck]:
    """One optimisation per start of ``multistart_starts`` (in ``start_<k>/``, sharing the PROM
    cache; with ``[optimizer] screen`` the starts of least cost among the screened), each FOM-checked; summary.json lists every local optimum and is the summary of the
    best FOM-verified one (the best PROM distance when no FOM check finished).

    ``pool``: a backend of :mod:`aquarom_fenics.parallel` running one start per task; None runs
    them one after the other here. ``resume``: a start with a checkpoint continues from it, one
    without (not begun when the run stopped) runs from the start."""
    out_dir = Path(out_dir)
    fish = fish or load_fish(scene)
    space = optimization_space(scene, fish)
    settings = scene.optimizer
    starts, screened = multistart_starts(scene, space, weights or CostWeights(), PromBuilder(scene, fish, space).meshes,
                                         pool)
    if pool is None:
        with worker_threads():
            runs = [start_run(scene, out_dir, resume, weights, max_time, (k, z), fish) for k, z in enumerate(starts)]
    else:
        from aquarom_fenics.parallel import run_all

        task = partial(start_run, scene, str(out_dir.resolve()), resume, weights, max_time)
        found = {}
        for (k, _), run, error in run_all(pool, task, list(enumerate(starts)), key=lambda item: item[0]):
            if error is not None:
                raise error
            found[k] = run
        runs = [found[k] for k in range(len(starts))]
    best = max(range(len(runs)), key=lambda k: _verified_distance(*runs[k]))
    result, check = runs[best]
    if MPI.COMM_WORLD.rank == 0:
        optima = [_local_optimum(k, z, *run) for k, (z, run) in enumerate(zip(starts, runs))]
        _write_summary(out_dir, scene, result, check, weights or CostWeights(),
                       {"starts": settings.starts, "seed": settings.seed, "best_start": best + 1,
                        "distinct_optima": _distinct_optima(space, [r.optimum for r, _ in runs],
                                                            settings.active_tolerance),
                        "local_optima": optima} | ({"screen": screened} if screened else {}))
    _write_figures(out_dir, scene, fish, result, render)
    return result, check


def start_run(scene: Scene, out_dir: str | Path, resume: bool, weights: CostWeights | None, max_time: float,
              item: tuple[int, np.ndarray], fish: Fish | None = None) -> tuple[OptimizationResult, FomCheck]:
    """The optimisation of multi-start ``item`` = (k, z_start), in ``out_dir/start_<k+1>`` (a worker's
    task); ``resume`` continues it from its checkpoint if it has one."""
    k, z = item
    folder = Path(out_dir) / f"start_{k + 1}"
    return run_optimization(scene, folder, resume and holds_file(folder, "checkpoint.json"), weights, fish,
                            render=False, max_time=max_time, start=z)


def _verified_distance(result: OptimizationResult, check: FomCheck) -> tuple[bool, float]:
    """Sort key: FOM-verified first, then the distance (FOM, else PROM)."""
    verified = check.optimal_distance is not None
    return verified, check.optimal_distance if verified else result.evaluation.distance


def _local_optimum(k: int, start, result: OptimizationResult, check: FomCheck) -> dict:
    space = result.space
    return {"start_index": k + 1, "directory": f"start_{k + 1}", "start": space.as_dict(start),
            "optimum": space.as_dict(result.optimum), "prom_distance": result.evaluation.distance,
            "fom_distance": check.optimal_distance, "fom_error": check.error, "stop_reason": result.stop_reason,
            "converged": result.converged, "iterations": result.iterations, "prom_builds": result.prom_builds,
            "active": [row["constraint"] for row in result.optimality.active]}


def _distinct_optima(space, optima: list[np.ndarray], tolerance: float) -> list[list[int]]:
    """Starts grouped by optimum: two optima are the same when every |z_i - z'_i| ≤ tolerance ·
    (upper_i - lower_i)."""
    groups: list[list[int]] = []
    width = space.upper - space.lower
    for k, z in enumerate(optima):
        for group in groups:
            if np.all(np.abs(z - optima[group[0] - 1]) <= tolerance * width):
                group.append(k + 1)
                break
        else:
            groups.append([k + 1])
    return groups


HISTORY_FILE_UNITS = {"distance": "distance_m", "cost": "cost_m", "wall_time": "wall_time_s"}
"""history.csv's header names of the columns with a unit (ξ, gradients and ratios are dimensionless)."""


class HistoryWriter(IncrementalCSV):
    """history.csv, one row per iteration in the columns of :func:`history_columns`; a resumed run
    starts from the checkpoint's rows (a row written after the last checkpoint is made again, not
    duplicated)."""

    def __init__(self, path: Path, columns: list[str], checkpoint_rows: list[dict]):
        super().__init__(path, [HISTORY_FILE_UNITS.get(column, column) for column in columns])
        self.header = columns
        for row in checkpoint_rows:
            self.write(row)

    def write(self, row: dict) -> None:
        self.write_row([_csv_value(row.get(key)) for key in self.header])


def _csv_value(value):
    """An empty cell for a missing value (a JSON null in a resumed row is the same as None)."""
    return "" if value is None else value


OPTIMIZATION_SUMMARY_UNITS = {
    "optimum": "1 (ξ dimensionless; amplitude A as [actuation] amplitude)", "prom_distance_optimal": "m",
    "fom_check": "m for the distances, 1 for ratio", "timings": "s", "time_per_build": "s",
    "cost_weights": "1"}
"""The ``units`` block of an optimisation's summary.json."""


def _write_summary(out_dir, scene, result, check, weights, multistart: dict | None = None):
    space = result.space
    settings = scene.optimizer
    summary = {
        "scene": scene.name, "scene_hash": scene.hash, "method": settings.method,
        "optimum": space.as_dict(result.optimum), "start": space.as_dict(space.start),
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(space.names, space.lower, space.upper)},
        "bounds_active": [row["constraint"] for row in result.optimality.active], "stop_reason": result.stop_reason,
        "converged": result.converged,
        "optimality": {"measure": result.optimality.measure, "tolerance": settings.optimality_tolerance,
                       "definition": "‖D r‖_∞ / |L|: KKT residual r over the active set, D the parameter ranges",
                       "active_tolerance": settings.active_tolerance,
                       "active_definition": "slack ≤ active_tolerance · range of the bound or constraint row; "
                                            "multiplier > 0: the constraint holds the optimum",
                       "active": result.optimality.active},
        "iterations": result.iterations, "prom_builds": result.prom_builds,
        "prom_builds_reused_from_cache": result.reused, "prom_builds_on_an_earlier_basis": result.basis_reuses,
        "prom_size": result.prom_size,
        "cost_weights": {"distance": weights.distance, "energy": weights.energy, "alpha": weights.alpha},
        "prom_distance_optimal": result.evaluation.distance,
        "fom_check": {"start_distance": check.start_distance, "optimal_distance": check.optimal_distance,
                      "prom_start_distance": check.prom_start_distance,
                      "prom_optimal_distance": check.prom_optimal_distance, "ratio": check.ratio,
                      "error": check.error},
        "timings": result.timings | {"fom_check": check.time},
        "time_per_build": result.timings["prom_builds"] / max(result.prom_builds, 1),
        "versions": software_versions(), "units": OPTIMIZATION_SUMMARY_UNITS}
    if multistart is not None:
        summary["multistart"] = multistart
    write_json_atomic(out_dir / "summary.json", summary)


def _write_figures(out_dir, scene, fish, result, render):
    """The history plots and the renders of the optimum. Called on every rank: the optimal design's
    XDMF is written collectively; rank 0 draws."""
    from aquarom_fenics.viz.report import plot_optimization_history, render_start_and_optimal

    is_writer = MPI.COMM_WORLD.rank == 0
    space = result.space
    if scene.output.plots and is_writer:
        active = [row["constraint"] for row in result.optimality.active]
        plot_optimization_history(result.history, list(space.names), list(zip(space.lower, space.upper)), out_dir,
                                  active=active, columns=design_columns(space))
    shapes = space.n_shapes
    optimal = dict(zip(space.names[:shapes], map(float, result.optimum[:shapes])))
    if render and scene.output.render and shapes:
        from aquarom_fenics.geometry.export import write_design_stl
        from aquarom_fenics.viz.render import render_design

        render_design(fish, fish.design(optimal), optimal, out_dir / "optimal")
        if is_writer:
            write_design_stl(scene, fish, optimal, out_dir / "optimal" / "design.stl")
            start = dict(zip(space.names[:shapes], map(float, space.start[:shapes])))
            render_start_and_optimal(fish, fish.design(start), fish.design(optimal),
                                       out_dir / "start_vs_optimal.png", f"{scene.name}: start and optimal design")


def pareto_sweep(scene: Scene, out_dir: Path, fish: Fish | None = None, pool=None, resume: bool = False) -> list[dict]:
    """Co-optimisation over the scene's weights w_1 (w_2 = 1 - w_1): pareto.csv and pareto.png.

    A point whose FOM check does not complete is no optimum of the model: it is marked
    ``fom_check = infeasible`` with the FOM's stop reason, and left off the front.
    ``pool``: a backend of :mod:`aquarom_fenics.parallel` (local worker processes or a Dask
    cluster) running one weight per task; None runs them one after the other here (under MPI too).
    ``resume``: a weight whose run completed is read back from its summary.json, one with a
    checkpoint continues from it, and the others run from the start (:func:`pareto_point`).
    """
    require_distinct_weights(scene.cooptimization.weights, f"scene {scene.source}")
    if pool is None:
        fish = fish or load_fish(scene)
        with worker_threads():
            points = [pareto_point(scene, out_dir, w1, fish, resume) for w1 in scene.cooptimization.weights]
    else:
        from aquarom_fenics.parallel import run_all

        found = {}
        for w1, point, error in run_all(pool, partial(pareto_point, scene, str(Path(out_dir).resolve()), resume=resume),
                                        scene.cooptimization.weights):
            if error is not None:
                raise error
            found[w1] = point
        points = [found[w1] for w1 in scene.cooptimization.weights]
    if MPI.COMM_WORLD.rank == 0:
        table = io.StringIO()
        writer = csv.DictWriter(table, fieldnames=list(points[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(points)
        write_text_atomic(Path(out_dir) / "pareto.csv", table.getvalue())
        from aquarom_fenics.viz.report import plot_pareto

        plot_pareto(points, Path(out_dir) / "pareto.png")
    return points


def pareto_point(scene: Scene, out_dir: Path, w1: float, fish: Fish | None = None, resume: bool = False) -> dict:
    """The co-optimisation at weight w_1 (in ``out_dir/w1_<w1>``) and its row of pareto.csv.

    ``resume``: a completed run there (:func:`completed_summary`) is kept, an interrupted one
    continues from its checkpoint, and a folder without a checkpoint runs from the start.
    """
    co = scene.cooptimization
    weights = CostWeights(distance=w1, energy=1.0 - w1, alpha=co.energy_weight)
    folder = Path(out_dir) / weight_folder(w1)
    summary = completed_summary(folder, scene, weights) if resume else None
    if summary is not None:
        check, space = summary["fom_check"], design_space(scene)
        return _pareto_row(w1, weights, space, np.array([summary["optimum"][n] for n in space.names]),
                           summary["prom_distance_optimal"], check["optimal_distance"], check["error"],
                           bool(summary.get("converged", False)))
    result, check = run_optimization(scene, folder, resume=resume and holds_file(folder, checkpoint_pattern(scene)),
                                     weights=weights, fish=fish or load_fish(scene), render=False)
    return _pareto_row(w1, weights, result.space, result.optimum, result.evaluation.distance,
                       check.optimal_distance, check.error, result.converged)


def weight_folder(w1: float) -> str:
    """``w1_<w1>``, unique by the weight's exact value: the short form (``w1_0.9``) when it reads
    back as the same number, else every digit (``w1_0.9000001``), so that two weights never share
    a folder."""
    short = f"{w1:g}"
    return f"w1_{short}" if float(short) == w1 else f"w1_{float(w1)!r}"


def require_distinct_weights(weights, where: str) -> None:
    """Refuse (InputError) a Pareto sweep that names a weight twice: both runs would share a folder."""
    seen = set()
    for w1 in weights:
        if float(w1) in seen:
            raise InputError(f"{where}: [cooptimization] weights names w1 = {w1!r} twice; give each weight once")
        seen.add(float(w1))


def completed_summary(folder: Path, scene: Scene, weights: CostWeights | None = None) -> dict | None:
    """The summary.json of a completed optimisation in ``folder`` (None if there is none, or if the
    run there was interrupted); a summary of another scene or other cost weights is refused
    (InputError), since resuming would mix two studies in one table."""
    from aquarom_fenics.io.readback import load_optimization_summary

    path = Path(folder) / "summary.json"
    if not path.is_file():
        return None
    summary = load_optimization_summary(path, design_space(scene).names)
    if summary["scene_hash"] != scene.hash:
        raise InputError(f"--resume: {path} was written for scene hash {summary['scene_hash']}, this scene "
                         f"is {scene.hash}; resume with the scene it was run with, or choose another --out")
    if summary.get("completed") is False:
        return None
    expected = weights or CostWeights()
    written = summary["cost_weights"]
    if [written[k] for k in ("distance", "energy", "alpha")] != [expected.distance, expected.energy, expected.alpha]:
        raise InputError(f"--resume: {path} was written for cost weights {written}, this run uses "
                         f"distance {expected.distance:g}, energy {expected.energy:g}, alpha {expected.alpha:g}; "
                         "choose another --out")
    return summary


def _pareto_row(w1: float, weights: CostWeights, space, optimum: np.ndarray, prom_distance: float,
                fom_distance: float | None, fom_error: str | None, converged: bool) -> dict:
    """A row of pareto.csv: the amplitude A (z's entry after the shapes), ``xi_<name>`` per shape and
    ``gait_<name>`` per ``[gait]`` variable; a FOM check that did not complete leaves the distance NaN and
    gives the FOM's stop reason; ``converged``: the optimiser stopped at a first-order point (a point that did
    not is left off the front)."""
    amplitude = float(optimum[space.amplitude_index])
    completed = fom_distance is not None
    return {"mode": "weight", "w1": w1, "amplitude": amplitude, "energy": weights.energy_term(amplitude),
            "distance_m": fom_distance if completed else float("nan"),
            "prom_distance_m": prom_distance,
            "fom_check": "completed" if completed else "infeasible",
            "fom_check_reason": "" if completed else (fom_error or ""), "converged": converged,
            **{column: float(v) for column, v in zip(design_columns(space), optimum) if column != "xi_amplitude"}}
