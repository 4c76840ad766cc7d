"""A PROM atlas: the design box covered by PROM centres, built where designs fall, for ``sweep --model prom``.

The cover of the box by cells of half-width h ≤ s r (r the validity radius, s the scene's ``[reduction]
atlas_scale``, default :data:`RADIUS_SCALE`) and
the PROM at a cell's centre (:func:`center_prom`, through the PROM cache) are
:mod:`~aquarom_fenics.reduction.atlas_cover`'s, below the optimisers, whose multi-start screen uses them too (:mod:`~aquarom_fenics.optimization.screen`); a design's cell's centre holds it within h_k ≤ r_k, so that
centre's PROM answers it. Where ``[reduction] validity_change`` caps a PROM's radius R below the cell
(s R_k < h_k), the cell is bisected until it holds (:mod:`~aquarom_fenics.reduction.atlas_refine`; a cell
left at the depth limit answers only within R, refusing the others as rows). Only the centres whose cells hold
designs are built, each through the PROM cache (a second sweep reuses them), one task per centre on the sweep's
pool, and the designs of a centre are integrated together, one ``simulate_batch`` per centre (split
in tasks of at most :data:`CENTER_ROWS` designs).

A scene with ``[gait]`` variables is cut in cells over its shapes only: a centre's PROM is built on the scene
itself, whose basis holds its gait's patterns and, where the phase lag or a pair's amplitude is a variable, each
pair's pattern (``scene_gait.pair_patterns``), so that one basis spans every lag and amplitude of the ``[gait]``
box, and the frequency enters only a(t). No validity radius bounds the gait: how far such a PROM follows a gait
other than the one it was built at is measured in docs/devlog.md ("gait variables as design variables"). The
designs of a centre are integrated together, each with its own gait's activations (:func:`_answer`).

The atlas's radius is h: inside it the PROM is to stay within 3 % of the FOM in distance, tighter than
SPEC §8's 5 %. It is set by s, the scale of the validity radius, checked by ``scripts/validate_atlas.py``
(results/validation/atlas.json): the FOM at 20 random designs of a 20,000-design atlas sweep of SO1's box and
at the 5 designs farthest from their centres (on the cells' faces, where the Taylor terms in Δξ are largest),
with ``--corners`` at the corners of the cells that erred most, with ``--every-corner`` at every cell's corners
(with capped radii: every corner of the leaves that answered the sweep's designs).
On SO1: at s = 1 (4 × 4 × 6 cells, h = r) the largest error was 3.19 %; at s = 0.9 (5 × 5 × 7 cells) 2.22 %, but
3.38 % at a cell's corner; at s = 0.8 (5 × 5 × 8 cells: h = 0.8 r for the heights, 0.75 r for the thickness)
2.15 %, but 3.51 % at a cell's corner with a third seed; at s = 0.7 (6 × 6 × 9 cells: h = 2/3 r) 1.43 %, and at
most 2.93 % at the 2,592 corners of all 324 cells (docs/devlog.md, "2026-12-06: the atlas at its targets" and
"issue 51, the second round merged"). That holds on SO1's box (and CO's), not on every box: on SO3's (eight
shapes) at s = 0.7 the PROM errs +22.8 % at ξ = 0, a corner of its cell, and up to +31 % at that cell's corners;
the corner errors fall a little faster than s², within 3 % at s = 0.2 (``validate_atlas.py --start-corners``; docs/devlog.md,
"the atlas's cells on scenes with many shapes"). A scene sets its s in ``[reduction] atlas_scale``.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.parallel import worker_name
from aquarom_fenics.geometry.fish_cache import shared_fish
from aquarom_fenics.reduction.atlas_cover import (BUILT_HERE, RADIUS_SCALE, Cover, assign, cell_of,  # noqa: F401
                                                   center_id, center_prom, cover)
from aquarom_fenics.reduction.atlas_refine import MAX_DEPTH, Refiner, RefusedNode, met_status, node_of
from aquarom_fenics.studies.sweep_designs import driven

CENTER_ROWS = 512
"""Most designs of one centre integrated in one task (a centre holding more is split, to share the workers)."""
ATLAS_FILE = "atlas.json"
MAX_ATLAS_FILE_BYTES = 64 * 1024 * 1024
"""Largest atlas.json read back by --resume [bytes]."""


# ---------------------------------------------------------------------- one centre
@dataclass(frozen=True)
class CenterTask:
    """Designs of one centre answered together: (sweep number, design) pairs, the cell, the scene."""

    cell: tuple
    designs: tuple
    scene: Scene
    scale: float | None = None          # the atlas's s; None: the scene's [reduction] atlas_scale

    @property
    def index(self) -> int:
        return self.designs[0][0]

    @property
    def center(self) -> dict:
        grid = cover(self.scene, self.scale)
        return dict(zip(grid.names, grid.center(self.cell).tolist()))


def center_tasks(scene: Scene, numbered: list[tuple[int, dict]], scale: float | None = None) -> list[CenterTask]:
    """The tasks of a sweep's (number, design) pairs: per centre, chunks of at most :data:`CENTER_ROWS`."""
    groups = assign(cover(scene, scale), [design for _, design in numbered])
    tasks = []
    for cell, members in groups.items():
        for start in range(0, len(members), CENTER_ROWS):
            tasks.append(CenterTask(cell, tuple(numbered[k] for k in members[start:start + CENTER_ROWS]), scene, scale))
    return tasks


def evaluate_center(task: CenterTask) -> dict:
    """The rows of a base cell's designs and the records of the atlas nodes that answered them or were split
    on the way (``atlas_refine.Refiner``: a cell is bisected where its PROM's capped radius needs it; an uncapped
    scene's cell is its own leaf, one record).

    Each leaf's designs inside its PROM's validity radius are integrated at once (``simulate_batch``; a design
    whose steps fail there is integrated alone, with step cutting); the others are refused rows, as are all
    whose way down meets a node where no PROM can be built. The task's wall time is shared among its rows. A
    record times the build (or cache read) and the solve, wall [s] and the worker thread's CPU [s], and names
    the worker and how many atlas PROMs it had built by then (``builds_in_worker`` 1: its first, which sets up
    its FOM)."""
    from aquarom_fenics.dynamics.batched import reduced_distances, simulate_batch
    from aquarom_fenics.reduction.prom import ReducedModel

    started = time.perf_counter()
    scene, grid = task.scene, cover(task.scene, task.scale)
    refiner = Refiner(scene, grid, max_depth=MAX_DEPTH, distances=reduced_distances)
    rows = [{"design": index, **design, "status": "completed", "distance_m": None, "tail_amplitude_m": None,
             "cached": False, "reason": "", "prom_center": center_id(task.cell)} for index, design in task.designs]
    leaves: dict = {}
    for k, (_, design) in enumerate(task.designs):
        try:
            leaf = refiner.leaf(np.array([design[name] for name in grid.names], dtype=float), task.cell)
            leaves.setdefault(leaf.node, (leaf, []))[1].append(k)
        except RefusedNode as refused:
            rows[k].update(status="refused", prom_center=refused.node.id,
                           reason=f"no PROM at its centre {refused.node.id}: {refused}")
    solves, answered = {}, {}
    for node, (leaf, members) in leaves.items():
        for k in members:
            rows[k]["prom_center"] = node.id
        try:
            prom = refiner.prom(node)
        except RefusedNode as refused:
            for k in members:
                rows[k].update(status="refused", reason=f"no PROM at its centre {node.id}: {refused}")
            continue
        solve_at, solve_cpu = time.perf_counter(), time.thread_time()
        _answer(prom, scene, [rows[k] for k in members], tuple(task.designs[k] for k in members), simulate_batch,
                ReducedModel.refuse_outside_radius)
        answered[node] = {"size": prom.size, "prom_radius": dict(zip(prom.shape_names, prom.validity_radius.tolist())),
                          **({"at_depth_limit": True} if leaf.at_limit else {})}
        solves[node] = {"solve_time_s": time.perf_counter() - solve_at, "solve_cpu_s": time.thread_time() - solve_cpu}
    records = [_node_record(grid, node, met, refiner.radii.get(node, grid.radius)) | answered.get(node, {})
               | solves.get(node, {"solve_time_s": 0.0, "solve_cpu_s": 0.0}) for node, met in refiner.met.items()]
    share = (time.perf_counter() - started) / len(rows)
    for row in rows:
        row.update(wall_time_s=share, worker=worker_name())
    return {"rows": rows, "records": records}


def _node_record(grid: Cover, node, met: dict, radius=None) -> dict:
    """A node's record: its cell, centre, build (or cache read) status and time, split shapes, the halvings of
    each (and its PROM's radius, which split it) if split."""
    record = {"id": node.id, "cell": list(node.index), "center": dict(zip(grid.names, node.center(grid).tolist())),
              "status": met_status(met), "build_time_s": met["time_s"], "build_cpu_s": met["cpu_s"],
              "worker": worker_name(), "builds_in_worker": met.get("builds_in_worker", BUILT_HERE[0])}
    if any(node.levels):
        record["levels"] = list(node.levels)
    if "split" in met:
        record.update(split=met["split"], halvings=met.get("halvings", {}),
                      prom_radius=dict(zip(grid.names, np.asarray(radius).tolist())))
    if "check" in met:
        record["check"] = met["check"]
    return record


def _answer(prom, scene: Scene, rows: list[dict], designs: tuple, simulate_batch, refuse_outside) -> None:
    """Fill the rows of the designs inside the PROM's radius from one batched solve; refuse the others. With
    ``[gait]`` variables each design runs the scene driven by its own gait (``sweep_designs.driven``: its own activation
    law, ``simulate_batch``'s ``scenes``), as ``simulate_reduced`` would one by one; a gait the scene refuses is
    a refused row."""
    fish = shared_fish(scene)
    inside = []
    for row, (_, design) in zip(rows, designs):
        try:
            shapes = {name: design[name] for name in scene.shape_names}
            refuse_outside(prom.shape_names, fish.parameter_vector(shapes), prom.xi_center, prom.validity_radius)
            inside.append((row, shapes, driven(scene, design)[0]))
        except InputError as refused:
            row.update(status="refused", reason=str(refused))
    if not inside:
        return
    xis = np.array([[shapes[name] for name in prom.shape_names] for _, shapes, _ in inside]).reshape(len(inside), -1)
    result = simulate_batch(prom, scene, xis, scenes=[own for _, _, own in inside] if scene.gait else None)
    for b, (row, _, _) in enumerate(inside):
        if result.completed[b]:
            row.update(distance_m=float(result.distance[b]), tail_amplitude_m=float(result.tail_amplitude[b]))
        else:
            row.update(status="stopped", reason=result.errors[b])


# ---------------------------------------------------------------------- atlas.json
SOLVE_TIMES = ("solve_time_s", "solve_cpu_s")


def merged_record(earlier: dict | None, record: dict) -> dict:
    """A centre's record after another task of it: its first build (time, status) is kept, the solve times
    of its tasks are summed."""
    if earlier is None:
        return record
    kept = earlier if earlier.get("status") == "built" and record.get("status") != "built" else record
    solves = {key: (earlier.get(key) or 0.0) + (record.get(key) or 0.0) for key in SOLVE_TIMES
              if key in earlier or key in record}
    return kept | solves


def read_records(path: Path) -> dict[str, dict]:
    """The centre records of an earlier run's atlas.json, by centre id (none when the file is missing)."""
    if not path.exists():
        return {}
    remedy = "run without --resume, or into another --out"
    text = read_text_file(path, "--resume:", MAX_ATLAS_FILE_BYTES, remedy, nesting="json")
    try:
        centres = json.loads(text)["centres"]
        return {str(record["id"]): dict(record) for record in centres}
    except (ValueError, KeyError, TypeError) as error:
        raise InputError(f"--resume: {path}: not an atlas file ({type(error).__name__}: {error}); {remedy}") from None


def atlas_report(scene: Scene, grid: Cover, records: dict[str, dict], rows: list[dict]) -> dict:
    """atlas.json: the cover (scale, radii, half-widths, cells), every centre used by the rows (its
    record, its number of designs), and the totals."""
    designs: dict[str, int] = {}
    for row in rows:
        if row.get("prom_center"):
            designs[row["prom_center"]] = designs.get(row["prom_center"], 0) + 1
    centres = []
    for name, count in sorted(designs.items(), key=lambda item: _order(node_of(item[0], grid))):
        node = node_of(name, grid)
        record = records.get(name) or {"id": name, "cell": list(node.index), "status": "unrecorded (a run stopped "
                                       "before it)", "center": dict(zip(grid.names, node.center(grid).tolist()))}
        centres.append(record | {"designs": count})
    split = sorted((record for name, record in records.items() if "split" in record and name not in designs),
                   key=lambda record: _order(node_of(record["id"], grid)))
    statuses = [record["status"] for record in centres + split]
    names = list(grid.names)
    return {"scene": scene.name, "scene_hash": scene.hash, "shape_names": names, "radius_scale": grid.scale,
            "validity_radius": dict(zip(names, grid.radius.tolist())),
            "cell_half_width": dict(zip(names, grid.half_width.tolist())),
            "cells_per_shape": dict(zip(names, grid.counts.tolist())),
            "box": {name: [lo, hi] for name, lo, hi in zip(names, grid.lower.tolist(), grid.upper.tolist())},
            "cells_in_box": grid.box_cells(), "centres": centres,
            "refinement": {"max_depth": MAX_DEPTH, "split_centres": split,
                           "at_depth_limit": [record["id"] for record in centres if record.get("at_depth_limit")],
                           **check_failed(centres, split)},
            "totals": {"centres": len(centres), "built": statuses.count("built"),
                       "from_the_cache": statuses.count("from the cache"),
                       "build_time_s": _total(centres + split, "build_time_s", built_only=True),
                       "build_cpu_s": _total(centres + split, "build_cpu_s", built_only=True),
                       "solve_time_s": _total(centres, "solve_time_s"), "solve_cpu_s": _total(centres, "solve_cpu_s"),
                       "designs": sum(designs.values()), **check_totals(centres + split)}}


def check_failed(centres: list[dict], split: list[dict]) -> dict:
    """With the atlas check (``[reduction] atlas_check``): the leaves whose check failed at the depth limit."""
    if not any("check" in record for record in centres + split):
        return {}
    return {"check_failed_at_depth_limit": [record["id"] for record in centres
                                            if not record.get("check", {}).get("passed", True)]}


def check_totals(records: list[dict]) -> dict:
    """With the atlas check: the corner PROMs its checks built and the checks' wall time [s]."""
    checks = [record["check"] for record in records if "check" in record]
    if not checks:
        return {}
    return {"checked": len(checks), "check_corner_builds": sum(check["corner_builds"] for check in checks),
            "check_time_s": _total(checks, "time_s")}


def _order(node) -> tuple:
    """Centres in atlas.json: by base cell, then refinement, then index."""
    return node.base_cell(), node.levels, node.index


def _total(centres: list[dict], key: str, built_only: bool = False) -> float:
    """Σ of a time [s] over the centres' records (over those built here with ``built_only``)."""
    return math.fsum(r.get(key) or 0.0 for r in centres if not built_only or r["status"] == "built")
