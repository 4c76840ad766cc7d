"""Design sweeps: one model run per design of a list, grid or Latin hypercube, on the executor layer.

Designs come from a CSV file (one column per variable name), a grid (``name=lo:hi:n`` per variable) or
a seeded Latin hypercube over the scene's bounds; a variable a source does not set keeps its start
value. The variables are the scene's shapes, then its ``[gait]`` variables: a design's gait drives the
scene's muscles (``apply_gait``, io/scene_gait.py) for the FOM and the reduced models alike. Each design is one task (:func:`evaluate`) on a backend of :mod:`aquarom_fenics.parallel`
(model prom: the designs of one centre of the PROM atlas, :mod:`~aquarom_fenics.studies.atlas`, are one
task, integrated together, and atlas.json lists the centres); its row is written to ``sweep.csv`` as it finishes. The FOM's answer at a design is cached in the
FOM cache (:func:`aquarom_fenics.studies.fom_cache.fom_answer`, one entry format shared with the
optimiser's FOM checks), so a re-run computes only what is missing; ``--resume`` keeps the rows already in
``sweep.csv`` and runs the designs it lacks.

A design the design check refuses, a PROM that cannot be built or is outside its validity radius, a FOM that stops or a task
that fails is a row with its status and reason, never the end of the sweep.
"""
from __future__ import annotations

import csv
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file
from aquarom_fenics.parallel import run_all, worker_name
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.geometry.fish_cache import shared_fish
from aquarom_fenics.studies.sweep_designs import (  # noqa: F401 — the design sources, also imported from here
    MAX_DESIGN_FILE_BYTES, MAX_DESIGNS, csv_designs, driven, grid_designs, latin_hypercube, variable_names)


log = logging.getLogger("aquarom")

MODELS = ("fom", "rom", "prom")
STATUSES = ("completed", "refused", "stopped", "error")
"""completed: the model ran to the horizon; refused: the design check (or the PROM's validity
radius) refused the design; stopped: the solver stopped early; error: the task failed otherwise."""


# ---------------------------------------------------------------------- one design
@dataclass(frozen=True)
class SweepTask:
    """One design of a sweep: its number in the sweep (0-based), variable values (shapes, gait) and model."""

    index: int
    design: dict
    model: str
    scene: Scene


class _Stopped(Exception):
    """A model run that stopped before the horizon (not cached: a run is retried next time)."""


def evaluate(task: SweepTask) -> dict:
    """The row of one design: status, distance [m], tail amplitude [m], wall time [s], worker.

    Never raises for the model's own outcomes (a refused design, a solver stop)."""
    started = time.perf_counter()
    row = {"design": task.index, **task.design, "status": "completed", "distance_m": None,
           "tail_amplitude_m": None, "cached": False, "reason": ""}
    try:
        run = {"fom": _fom_answer, "rom": _reduced_answer, "prom": _reduced_answer}[task.model]
        row.update(run(task))
    except InputError as refused:
        row.update(status="refused", reason=str(refused))
    except _Stopped as stop:
        row.update(status="stopped", reason=str(stop))
    row["wall_time_s"] = time.perf_counter() - started
    row["worker"] = worker_name()
    return row


def _fom_answer(task: SweepTask) -> dict:
    """The FOM's distance and tail amplitude at the design, through the FOM cache (an entry of the
    optimiser's FOM check is reused when it holds the tail amplitude)."""
    from aquarom_fenics.studies.fom_cache import fom_answer

    scene, shapes = driven(task.scene, task.design)
    answer = fom_answer(scene, shapes, need_tail=True)
    if not answer.completed:
        raise _Stopped(answer.stop_reason)
    return {"distance_m": answer.distance, "tail_amplitude_m": answer.tail_amplitude, "cached": answer.cached}


def reduced_model(scene: Scene, design: dict, model: str):
    """The ROM built at the design's shapes, or the PROM of the atlas centre whose cell holds them (both through
    the PROM cache; :mod:`~aquarom_fenics.studies.atlas`), built on ``scene`` itself: its gait's patterns (with
    each pair's where the lag or a pair's amplitude is a variable) span every gait of its ``[gait]`` box.

    InputError for a design beyond that PROM's validity radius."""
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.dynamics.batched import reduced_distances
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom
    from aquarom_fenics.studies import atlas

    fish = shared_fish(scene)
    shapes = {name: design[name] for name in scene.shape_names}
    if model == "prom":
        refiner = atlas.Refiner(scene, atlas.cover(scene), distances=reduced_distances)
        prom = refiner.prom(refiner.leaf(np.array([design[name] for name in scene.shape_names], dtype=float)).node)
        ReducedModel.refuse_outside_radius(prom.shape_names, fish.parameter_vector(shapes), prom.xi_center,
                                           prom.validity_radius)
        return prom
    center = fish.parameter_vector(shapes)
    return cached_prom(scene, center, lambda: build_prom(scene, xi_center=center, fish=fish, parametric=False),
                       parametric=False)


def _reduced_answer(task: SweepTask) -> dict:
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced

    scene, _ = driven(task.scene, task.design)
    reduced = reduced_model(task.scene, task.design, task.model)
    result = simulate_reduced(reduced, scene, np.array([task.design[name] for name in reduced.shape_names]))
    if not result.completed:
        raise _Stopped(result.error)
    return {"distance_m": result.distance, "tail_amplitude_m": result.tail_amplitude}


# ---------------------------------------------------------------------- the sweep
def columns(scene: Scene, model: str = "fom") -> list[str]:
    """sweep.csv's header; a PROM sweep's rows also name the atlas centre that answered them (``prom_center``)."""
    return ["design", *variable_names(scene), "status", "distance_m", "tail_amplitude_m", "wall_time_s", "cached",
            "worker", "reason", *(["prom_center"] if model == "prom" else [])]


def _cell(value) -> str:
    """A CSV cell; floats in full precision (repr round-trips), None empty."""
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


MAX_SWEEP_FILE_BYTES = 256 * 1024 * 1024
"""Largest sweep.csv read back by --resume [bytes]."""


def read_rows(path: Path, scene: Scene, model: str = "fom") -> list[dict]:
    """The rows of a sweep.csv, schema-checked (numbers as floats, empty cells None): a whole
    design number, finite shape values, a known status, a completed row's distance and amplitude.
    A last line cut short (a run killed while writing it) is dropped with a note; anything else
    damaged is an InputError naming the line and column."""
    remedy = "run without --resume, or into another --out"
    where = f"--resume: {path}"
    text = read_text_file(path, "--resume:", MAX_SWEEP_FILE_BYTES, remedy)
    lines = text.splitlines(keepends=True)
    if len(lines) > 1 and not lines[-1].endswith(("\n", "\r")):
        log.warning("--resume: %s: partial last line %d dropped (a run stopped while writing it); its design "
                    "runs again", path, len(lines))
        lines = lines[:-1]
    try:
        table = list(csv.reader(lines))
    except csv.Error as error:
        raise InputError(f"{where}: not a CSV file ({error}); {remedy}") from None
    header = table[0] if table else []
    if header != columns(scene, model):
        raise InputError(f"{where} has the columns {header}, not those of scene {scene.name}'s sweep; {remedy}")
    return [_parsed_row(dict(zip(header, cells)), number, scene, f"{where} line {number}", remedy)
            for number, cells in enumerate(table[1:], start=2) if cells and _cell_count(cells, header, number,
                                                                                      where, remedy)]


def _cell_count(cells: list[str], header: list[str], number: int, where: str, remedy: str) -> bool:
    if len(cells) != len(header):
        raise InputError(f"{where} line {number} has {len(cells)} cells, not {len(header)}; {remedy}")
    return True


def _parsed_row(row: dict, number: int, scene: Scene, where: str, remedy: str) -> dict:
    """One row of sweep.csv with its values checked and converted."""
    def refuse(column: str, expected: str):
        raise InputError(f"{where}, column {column}: {row[column][:30]!r} is not {expected}; {remedy}")

    parsed = dict(row)
    if not row["design"].isdigit():
        refuse("design", "a whole number ≥ 0")
    parsed["design"] = int(row["design"])
    names = variable_names(scene)
    for name in (*names, "distance_m", "tail_amplitude_m", "wall_time_s"):
        optional = name not in names
        if row[name] == "" and optional:
            parsed[name] = None
            continue
        try:
            value = float(row[name])
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            refuse(name, "a finite number" + (" or empty" if optional else ""))
        parsed[name] = value
    if row["status"] not in STATUSES:
        refuse("status", f"one of {', '.join(STATUSES)}")
    if row["status"] == "completed":
        for name in ("distance_m", "tail_amplitude_m"):
            if parsed[name] is None:
                refuse(name, "empty in a completed row (a number)")
    if row["cached"] not in ("True", "False"):
        refuse("cached", "True or False")
    parsed["cached"] = row["cached"] == "True"
    return parsed


def resumed_rows(path: Path, scene: Scene, designs: list[dict], model: str = "fom") -> dict[int, dict]:
    """The rows of an earlier run of the same designs, by design number; InputError when the file
    was made for other designs."""
    kept = {}
    for row in read_rows(path, scene, model):
        index = row["design"]
        if not 0 <= index < len(designs) or any(row[n] != designs[index][n] for n in variable_names(scene)):
            raise InputError(f"--resume: {path} row of design {index} does not match this sweep's designs "
                             "(other --designs, --grid or --samples/--seed?); run without --resume")
        if index in kept:
            raise InputError(f"--resume: {path} holds design {index} twice; run without --resume")
        kept[index] = row
    return kept


class SweepCSV:
    """sweep.csv, one row per design as it finishes (flushed at once, so an interrupted sweep keeps
    its rows for --resume)."""

    def __init__(self, path: Path, scene: Scene, earlier: list[dict], model: str = "fom"):
        from aquarom_fenics.io.tables import IncrementalCSV

        self.header = columns(scene, model)
        self.table = IncrementalCSV(path, self.header)
        for row in earlier:
            self.write(row)

    def write(self, row: dict) -> None:
        self.table.write_row([_cell(row.get(name)) for name in self.header])

    def close(self) -> None:
        self.table.close()


def prepare(scene: Scene, model: str) -> None:
    """What every worker would otherwise find out at once: an unwritable cache is refused here."""
    from aquarom_fenics.io.persistence import require_cache_writable

    require_cache_writable("fom" if model == "fom" else "prom")


def run_sweep(scene: Scene, designs: list[dict], model: str, out: Path, pool, resume: bool = False,
              on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Every design on ``pool``: sweep.csv (rows as they finish), sweep.png, and for model prom atlas.json
    (:mod:`~aquarom_fenics.studies.atlas`: one task per centre of the atlas); the rows by design number.

    ``on_row(row)`` is called after each new row is written (progress lines)."""
    out = Path(out)
    path = out / "sweep.csv"
    earlier = resumed_rows(path, scene, designs, model) if resume and path.exists() else {}
    tasks = [SweepTask(k, design, model, scene) for k, design in enumerate(designs) if k not in earlier]
    prepare(scene, model)
    atlas = _AtlasFile(out, scene, resume, earlier.values()) if model == "prom" else None
    table = SweepCSV(path, scene, list(earlier.values()), model)
    rows = dict(earlier)
    items = atlas.tasks(tasks) if atlas else tasks
    try:
        for item, answer, error in run_all(pool, atlas.function if atlas else evaluate, items,
                                           key=lambda item: item.index):
            if isinstance(error, OSError):      # a cache or output write that failed: the sweep stops
                raise error
            for number, design, row in (atlas.answered(item, answer, error) if atlas else
                                        [(item.index, item.design, answer if error is None else None)]):
                if row is None:
                    row = _error_row(number, design, error)
                rows[number] = row
                table.write(row)
                if on_row is not None:
                    on_row(row)
            if atlas:
                atlas.write(rows.values())
    finally:
        table.close()
    ordered = [rows[k] for k in sorted(rows)]
    if atlas:
        atlas.write(ordered)
    if scene.output.plots:
        from aquarom_fenics.viz.sweep_plot import plot_sweep

        plot_sweep(ordered, variable_names(scene), out / "sweep.png", f"{scene.name}: {model.upper()} design sweep")
    return ordered


def _error_row(number: int, design: dict, error: BaseException) -> dict:
    """The row of a design whose task failed."""
    return {"design": number, **design, "status": "error", "cached": False, "worker": "",
            "reason": f"{type(error).__name__}: {error}".splitlines()[0]}


class _AtlasFile:
    """A PROM sweep's atlas: its tasks (per centre), and atlas.json rewritten after each centre's task with
    every centre the rows use (an earlier run's records kept by --resume)."""

    def __init__(self, out: Path, scene: Scene, resume: bool, earlier_rows):
        from aquarom_fenics.studies import atlas

        self.atlas, self.scene, self.path = atlas, scene, out / atlas.ATLAS_FILE
        self.grid = atlas.cover(scene)
        self.records = atlas.read_records(self.path) if resume and any(True for _ in earlier_rows) else {}
        self.function = atlas.evaluate_center

    def tasks(self, tasks: list[SweepTask]):
        return self.atlas.center_tasks(self.scene, [(task.index, task.design) for task in tasks])

    def answered(self, item, answer, error) -> list[tuple[int, dict, dict | None]]:
        """(number, design, row) of each design of a finished centre task; row None where it failed."""
        name = self.atlas.center_id(item.cell)
        if error is not None:
            self.records[name] = self.atlas.merged_record(self.records.get(name), {
                "id": name, "cell": list(item.cell), "center": item.center,
                "status": f"error: {type(error).__name__}: {error}".splitlines()[0]})
            return [(number, design, _error_row(number, design, error) | {"prom_center": name})
                    for number, design in item.designs]
        for record in answer["records"]:
            self.records[record["id"]] = self.atlas.merged_record(self.records.get(record["id"]), record)
        return [(number, design, row) for (number, design), row in zip(item.designs, answer["rows"])]

    def write(self, rows) -> None:
        from aquarom_fenics.io.persistence import write_json_atomic

        write_json_atomic(self.path, self.atlas.atlas_report(self.scene, self.grid, self.records, list(rows)))


def summary(rows: list[dict]) -> dict:
    """Counts per status and the best completed design."""
    counts = {status: sum(row["status"] == status for row in rows) for status in STATUSES}
    completed = [row for row in rows if row["status"] == "completed"]
    best = max(completed, key=lambda row: row["distance_m"]) if completed else None
    return {"designs": len(rows), "counts": counts, "best": best,
            "cached": sum(bool(row.get("cached")) for row in rows)}


BATCHED_SECONDS_PER_DESIGN = 0.006
"""A design's share of a batched reduced solve (the 2 s swim, level 1, the compiled kernel) [s of a worker's wall
time]: in 20,000-design atlas sweeps of SO1 on the shared two-core host (load average 1.4–4.8), 2.8–5.2 ms of the
worker thread's CPU and 3.9–9.6 ms of its wall time (docs/devlog.md, "2026-12-06: the atlas at its targets")."""


def estimate(scene: Scene, missing: int, model: str, workers: int, centres: int = 1) -> float:
    """Estimated wall time [s] of the missing designs on ``workers`` workers (:mod:`~aquarom_fenics.studies.estimate`);
    model prom: ``centres`` PROM builds of the atlas, shared by the workers, and
    :data:`BATCHED_SECONDS_PER_DESIGN` per design (each with its own gait too: ``simulate_batch``'s ``scenes``)."""
    from aquarom_fenics.studies.estimate import fom_seconds, prom_build_seconds, scene_cells

    cells = scene_cells(scene)
    degree = scene.mesh.degree
    start_up = 5.0 * min(workers, max(missing, 1)) / max(workers, 1)   # a worker's imports and first mesh
    if model == "fom":
        per_design = fom_seconds(cells, scene.n_steps, degree)
        return start_up + math.ceil(missing / workers) * per_design
    if model == "rom":
        return start_up + math.ceil(missing / workers) * (prom_build_seconds(cells, 0, degree) + 0.2)
    return (math.ceil(centres / workers) * prom_build_seconds(cells, len(scene.shapes), degree) + start_up
            + math.ceil(missing / workers) * BATCHED_SECONDS_PER_DESIGN)


def cached_designs(scene: Scene, designs: list[dict], model: str) -> int:
    """How many designs the FOM cache answers already (model fom; 0 for the reduced models)."""
    if model != "fom":
        return 0
    from aquarom_fenics.studies.fom_cache import cached_answer

    def cached(design: dict) -> bool:
        try:
            return cached_answer(*driven(scene, design), need_tail=True) is not None
        except InputError:          # a gait the scene refuses: a refused row, nothing to compute
            return False

    return sum(map(cached, designs))
