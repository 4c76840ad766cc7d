"""The Pareto front of distance against effort traced by budgets (SPEC §11 CO, by constraint).

For each budget A_k of an ascending list: maximise d(ξ, A) subject to A ≤ A_k (and the scene's
bounds), i.e. min L = -d over the design space with the amplitude's upper bound A_k. A weighted
sum L = w₁(-d) + (1 - w₁) α A² reaches only the convex part of a front; a budget reaches every
point. Each budget starts from the previous budget's optimum (continuation) with A = A_k, and one
:class:`PromBuilder` serves them all, so a PROM whose shapes recur comes from the cache and one
within half the validity radius of the last built basis reuses that basis (the PROM is exact in
A, so a budget changes no PROM). Every optimum is checked by the FOM.

pareto.csv: one row per budget (the columns of :data:`COLUMNS` and one ``xi_<name>`` per shape);
pareto.png: the PROM and FOM distances against the budget, and the optimal shapes along them.
"""
from __future__ import annotations

import csv
import dataclasses
import io
import logging
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.io.persistence import write_json_atomic, write_text_atomic
from aquarom_fenics.io.readback import load_budget_front
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import CostWeights, DesignSpace
from aquarom_fenics.optimization.optimize import OptimizationResult, optimization_space, optimize
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.studies.fom_cache import fom_distance
from aquarom_fenics.studies.study import design_and_amplitude

log = logging.getLogger("aquarom")

COLUMNS = ["mode", "w1", "budget", "amplitude", "energy", "distance_m", "prom_distance_m", "fom_check",
           "fom_check_reason", "converged", "first_order_measure", "stop_reason", "prom_builds", "seconds"]
"""pareto.csv's columns of a budget front before the shapes (``xi_<name>``); ``w1`` stays empty."""

CHECKPOINT = "budget_front.json"
"""What ``--resume`` reads: the scene's hash and the rows of the budgets done, each with its optimum
(written after every budget)."""


def parse_budgets(text: str, bounds: tuple[float, float], where: str = "--budgets") -> tuple[float, ...]:
    """Budgets from ``LOW:HIGH:COUNT`` (COUNT evenly spaced values, both ends included) or a comma
    list ``A1,A2,...``; each within the scene's amplitude bounds, in ascending order, distinct.
    Raises InputError with one line saying what is wrong and what would be valid."""
    lower, upper = bounds
    try:
        if ":" in text:
            low, high, count = text.split(":")
            count = int(count)
            if count < 1:
                raise ValueError
            values = tuple(round(float(v), 12) for v in np.linspace(float(low), float(high), count))   # 0.15, not 0.15000000000000002
        else:
            values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"{where} {text!r}: give LOW:HIGH:COUNT (e.g. 0.05:0.4:8, COUNT ≥ 1) or a comma list "
                         "of amplitudes (e.g. 0.05,0.1,0.2)") from None
    outside = [v for v in values if not (np.isfinite(v) and lower - 1e-12 <= v <= upper + 1e-12)]
    if outside:
        raise InputError(f"{where} {text!r}: budget {outside[0]:g} is outside the amplitude bounds "
                         f"[{lower:g}, {upper:g}] of [cooptimization] amplitude_bounds; give budgets inside them")
    if any(b <= a for a, b in zip(values, values[1:])):
        raise InputError(f"{where} {text!r}: budgets must increase strictly (each point continues from the "
                         "previous, smaller budget's optimum); list them in ascending order, each once")
    return tuple(min(max(v, lower), upper) for v in values)


def budget_space(space: DesignSpace, budget: float) -> DesignSpace:
    """The design space with the amplitude's upper bound A ≤ budget (a budget at the lower bound
    fixes A there)."""
    upper = space.upper.copy()
    upper[-1] = budget
    return dataclasses.replace(space, upper=upper)


def continuation_start(space: DesignSpace, previous: np.ndarray | None) -> np.ndarray:
    """The start of a budget's optimisation: the previous budget's optimum (the scene's start for
    the first), inside this budget's box, with A at the budget (the distance grows with A)."""
    start = np.array(space.start if previous is None else previous, dtype=float)
    start = np.clip(start, space.lower, space.upper)
    start[-1] = space.upper[-1]
    return start


def budget_front(scene: Scene, out_dir: Path, budgets: tuple[float, ...], fish: Fish | None = None,
                 resume: bool = False) -> list[dict]:
    """max d subject to A ≤ A_k for every budget, each optimum FOM-checked; returns the rows
    (:func:`budget_row`). pareto.csv, pareto.png and :data:`CHECKPOINT` in ``out_dir`` are written
    after every budget, so that a stopped front keeps the budgets it finished and ``resume``
    continues it from the last one's optimum."""
    if not scene.cooptimization.enabled:
        raise InputError(f"scene {scene.source}: a budget front needs [cooptimization] enabled = true")
    fish = fish or load_fish(scene)
    space = optimization_space(scene, fish)
    rows = resumed_budgets(scene, Path(out_dir), budgets, space) if resume else []
    builder = PromBuilder(scene, fish, space)
    weights = CostWeights(distance=1.0, energy=0.0, alpha=scene.cooptimization.energy_weight)
    previous = row_optimum(space, rows[-1]) if rows else None
    for budget in budgets[len(rows):]:
        started, builds = time.perf_counter(), builder.builds
        builder.space = budget_space(space, budget)
        result = optimize(scene, fish=fish, weights=weights, builder=builder, write_checkpoint=False,
                          start=continuation_start(builder.space, previous))
        distance, error = _fom_distance(scene, fish, result)
        rows.append(budget_row(budget, weights, result, distance, error, builder.builds - builds,
                               time.perf_counter() - started))
        log.info("budget A ≤ %.4g: A = %.4g, PROM %.3f cm, FOM %s, %s", budget, result.optimum[-1],
                 100 * result.evaluation.distance, "stopped" if distance is None else f"{100 * distance:.3f} cm",
                 "converged" if result.converged else f"not converged ({result.stop_reason})")
        previous = result.optimum
        if MPI.COMM_WORLD.rank == 0:
            write_front(rows, Path(out_dir))
            write_json_atomic(Path(out_dir) / CHECKPOINT, {"scene_hash": scene.hash, "rows": rows})
    return rows


def row_optimum(space: DesignSpace, row: dict) -> np.ndarray:
    """z of a budget's row: its shapes (``xi_<name>``), then its amplitude."""
    return np.array([row[f"xi_{name}"] for name in space.names[: space.n_shapes]] + [row["amplitude"]], dtype=float)


def resumed_budgets(scene: Scene, out_dir: Path, budgets: tuple[float, ...], space: DesignSpace) -> list[dict]:
    """The rows of the budgets an earlier run of this front finished (its :data:`CHECKPOINT`);
    InputError when it was another scene or its budgets do not begin ``budgets``."""
    path = out_dir / CHECKPOINT
    data = load_budget_front(path, space.names[: space.n_shapes])
    done = [row["budget"] for row in data["rows"]]
    if data["scene_hash"] != scene.hash:
        raise InputError(f"--resume: {path} was written for scene hash {data['scene_hash']}, not this scene "
                         f"({scene.hash}); run without --resume")
    if done != list(budgets[: len(done)]):
        raise InputError(f"--resume: {path} holds the budgets {', '.join(f'{b:g}' for b in done)}, which do not "
                         f"begin the budgets asked for ({', '.join(f'{b:g}' for b in budgets)}); give a list "
                         "that starts with them, or run without --resume")
    rows = [{**row, "distance_m": float("nan") if row.get("distance_m") is None else row["distance_m"]}
            for row in data["rows"]]
    log.info("budget front: %d of %d budgets kept from %s", len(done), len(budgets), path)
    return rows


def _fom_distance(scene: Scene, fish: Fish, result: OptimizationResult) -> tuple[float | None, str | None]:
    try:
        return fom_distance(scene, fish, *design_and_amplitude(result.space, result.optimum)), None
    except SolverError as failure:
        return None, str(failure)


def budget_row(budget: float, weights: CostWeights, result: OptimizationResult, fom: float | None,
               error: str | None, builds: int, seconds: float) -> dict:
    """A row of pareto.csv for one budget: A and the shapes at the optimum, the PROM and FOM
    distances [m] (NaN and the FOM's reason when its run stopped), whether the optimiser ended
    at a first-order point, its measure and stop reason, the PROM builds and seconds it took."""
    shapes, amplitude = design_and_amplitude(result.space, result.optimum)
    return {"mode": "budget", "w1": None, "budget": float(budget), "amplitude": amplitude,
            "energy": weights.alpha * amplitude ** 2, "distance_m": float("nan") if fom is None else fom,
            "prom_distance_m": result.evaluation.distance, "fom_check": "infeasible" if fom is None else "completed",
            "fom_check_reason": error or "", "converged": result.converged,
            "first_order_measure": result.optimality.measure, "stop_reason": result.stop_reason,
            "prom_builds": builds, "seconds": round(seconds, 1),
            **{f"xi_{name}": value for name, value in shapes.items()}}


def write_front(rows: list[dict], out_dir: Path) -> None:
    """pareto.csv (an empty cell for a missing value) and pareto.png in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows([{k: "" if v is None else v for k, v in row.items()} for row in rows])
    write_text_atomic(out_dir / "pareto.csv", table.getvalue())
    from aquarom_fenics.viz.report import plot_budget_front

    plot_budget_front(rows, out_dir / "pareto.png")
