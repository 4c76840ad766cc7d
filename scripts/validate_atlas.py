"""The PROM atlas of `aquarom sweep --model prom` on SO1's whole design box: its time and its accuracy.

1. The atlas sweep: the Latin hypercube of --samples designs (default 20 000, seed 0) over SO1's box on
   --workers local worker processes, from an empty PROM cache (the mesh cache copied in): wall time
   including worker start-up and every build, centres built, designs answered.
2. Its accuracy against the FOM: the FOM (through the FOM cache, on the same kind of pool) at --random
   designs of the sweep drawn with --check-seed and at the --farthest designs farthest from their
   centre relative to the cell's half-width (the atlas's radius); per design the relative distance error
   (d_PROM - d_FOM) / |d_FOM|, and the largest, against the limit 3 % (the atlas's radius is set so that
   it holds: the scene's [reduction] atlas_scale, default aquarom_fenics.studies.atlas.RADIUS_SCALE = 0.7,
   which holds on SO1, not on every scene: docs/user/sweep.rst, "Check s").
3. With --corners K, apart from that check: the FOM at the 2^p corners of the K cells whose checked designs
   erred most (every shape at its cell's half-width from the centre at once).
4. With --start-corners K instead of 1-3: the start design (the scene's shape starts) and K seeded random
   corners (--check-seed) of the start's cell and of one other seeded random cell of the box, each answered by
   its cell's PROM, against the FOM (a quick check of a scene with many shapes, whose cells have too many
   corners to visit all: SO3's have 2^8).
5. With --every-corner instead of 1-3: every cell of the box at its 2^p corners, each cell's PROM against the
   FOM at the grid's vertices (a vertex is the corner of up to 2^p cells: one FOM run each), written to
   results/validation/atlas_corners.json. On a scene with capped radii ([reduction] validity_change or
   atlas_change > 0, whose cells are divided as their PROMs ask) the cells walked are the leaves that answered
   the atlas sweep of --samples designs (--seed): the cells whose PROMs answered designs.

Writes results/validation/atlas.json (and results/bench/atlas_sweep.json: the sweep's time, builds and radii,
and where the workers' time went: builds and batched solves, wall and thread CPU, each worker's first build
apart; `--sweep-only`, as `make bench` runs it, skips the FOM check and writes only that).

    .venv/bin/python scripts/validate_atlas.py            # 1-1.5 min of sweep at s = 0.7 on 2 cores,
                                                          # then 25 FOM runs (through the FOM cache)
    .venv/bin/python scripts/validate_atlas.py --scene so3 --start-corners 6 --atlas-scale 0.5
                                                          # 13 FOM runs, 2 PROM builds

--atlas-scale s checks the scene with ``[reduction] atlas_scale`` = s (default: the scene's own); --atlas-check τ with
``[reduction] atlas_check`` = τ (the atlas's own check of its cells; default: the scene's own), the corner PROMs it
builds counted apart (``check_corner_builds``).
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import shutil
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
LIMIT = 0.03
"""Largest relative distance error of the atlas against the FOM."""


@contextmanager
def atlas_cache(folder: Path):
    """$AQUAROM_CACHE at ``folder``/cache for the block (the workers, spawned inside it, read it too), the mesh
    cache copied in on first use."""
    from aquarom_fenics.io.paths import mesh_cache

    meshes = mesh_cache()
    previous = os.environ.get("AQUAROM_CACHE")
    if meshes.is_dir() and not (folder / "cache" / "meshes").exists():
        shutil.copytree(meshes, folder / "cache" / "meshes")
    os.environ["AQUAROM_CACHE"] = str(folder / "cache")
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("AQUAROM_CACHE")
        else:
            os.environ["AQUAROM_CACHE"] = previous


def prom_sweep(scene, designs, workers: int, out: Path) -> list[dict]:
    """The atlas's rows of ``designs`` on a new pool of ``workers`` local processes."""
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.parallel import open_pool, shutting_down
    from aquarom_fenics.studies.sweep import run_sweep

    with shutting_down(open_pool(min(workers, len(designs)), None, SWIMMER_WORKERS)) as pool:
        return run_sweep(scene, designs, "prom", out, pool)


def atlas_sweep(scene, designs, workers: int, folder: Path) -> dict:
    """The PROM sweep of ``designs`` from an empty PROM cache in ``folder``: wall time, rows, atlas.json."""
    with atlas_cache(folder):
        started = time.perf_counter()
        rows = prom_sweep(scene, designs, workers, folder / "sweep")
        wall = time.perf_counter() - started
    return {"wall_time": wall, "rows": rows, "atlas": json.loads((folder / "sweep" / "atlas.json").read_text())}


def corner_designs(grid, results: list[dict], cells: int) -> list[dict]:
    """The 2^p corners c ± (1 - 1e-9) h of the ``cells`` cells whose checked designs erred most (distinct
    centres, by |relative error|), pulled inside by 1e-9 h so that the cell's own PROM answers them."""
    from aquarom_fenics.reduction.atlas_refine import node_of

    worst = []
    for entry in sorted(results, key=lambda entry: -abs(entry.get("relative_error", 0.0))):
        if entry["prom_center"] not in worst:
            worst.append(entry["prom_center"])
    corners = []
    for name in worst[:cells]:
        node = node_of(name, grid)                  # a regular cell, or one bisected for a capped radius
        center, half = node.center(grid), node.half_width(grid)
        for signs in itertools.product((-1.0, 1.0), repeat=len(grid.names)):
            corners.append(dict(zip(grid.names, (center + (1 - 1e-9) * np.array(signs) * half).tolist())))
    return corners


def corner_check(scene, results: list[dict], cells: int, workers: int, folder: Path) -> list[dict]:
    """The FOM against the atlas at the corners of :func:`corner_designs` (every shape at its largest offset at
    once), the atlas's answers from its PROM cache in ``folder``."""
    from aquarom_fenics.studies.atlas import cover

    grid = cover(scene)
    with atlas_cache(folder):
        rows = prom_sweep(scene, corner_designs(grid, results, cells), workers, folder / "corners")
    checked = [("corner", row | {"reach": leaf_reach(grid, row)}) for row in rows if row["status"] == "completed"]
    return fom_check(scene, checked, workers, folder)


def every_cell_corner(grid) -> tuple[list, list, dict]:
    """(the box's cells, (vertex, corner design) of each cell's 2^p corners c ± (1 - 1e-9) h, {vertex: ξ}): the
    grid vertex j (per shape 0 … n_k) is ξ_k = lower_k + 2 j_k h_k, the corner of up to 2^p cells."""
    nodes = regular_cells(grid)
    corners, vertices = leaf_corners(grid, nodes)
    return [node.index for node in nodes], [(vertex, design) for vertex, design, _ in corners], vertices


def regular_cells(grid) -> list:
    """Every regular cell of the box, as atlas nodes (``atlas_refine.base_node``)."""
    from aquarom_fenics.reduction.atlas_refine import base_node

    return [base_node(cell) for cell in itertools.product(*(range(int(n)) for n in grid.counts))]


def leaf_corners(grid, nodes: list) -> tuple[list, dict]:
    """((vertex, corner design, node) of each node's 2^p corners c ± (1 - 1e-9) h, {vertex: ξ}) for atlas cells
    regular or refined (``atlas_refine.Node``). A vertex is an integer point of the grid of the most halvings D_k
    among the nodes, ξ_k = lower_k + 2 v_k h_k / 2^{D_k}: a node's corner is v_k = (j_k + (1 ± 1) / 2) 2^{D_k - L_k},
    shared by the cells meeting there whatever their levels (D = 0: the regular grid's vertices)."""
    depth = np.max([node.levels for node in nodes], axis=0) if nodes else np.zeros(len(grid.names), dtype=int)
    corners, vertices = [], {}
    for node in nodes:
        center, half = node.center(grid), node.half_width(grid)
        scale = 2 ** (depth - np.asarray(node.levels))
        for signs in itertools.product((-1.0, 1.0), repeat=len(grid.names)):
            vertex = tuple(int((j + (s + 1) // 2) * k) for j, s, k in zip(node.index, map(int, signs), scale))
            vertices.setdefault(vertex, grid.lower + 2.0 * np.array(vertex) * grid.half_width / 2.0 ** depth)
            corners.append((vertex, dict(zip(grid.names, (center + (1 - 1e-9) * np.array(signs) * half).tolist())),
                            node))
    return corners, vertices


def used_leaves(grid, rows: list[dict]) -> list:
    """The atlas cells (leaves, on a scene with capped radii) that answered the completed ``rows``, in the order
    of atlas.json (base cell, levels, index)."""
    from aquarom_fenics.reduction.atlas_refine import node_of

    names = {row["prom_center"] for row in rows if row["status"] == "completed"}
    return sorted((node_of(name, grid) for name in names), key=lambda node: (node.base_cell(), node.levels,
                                                                                 node.index))


def every_corner(scene, workers: int, folder: Path, designs: list[dict] | None = None) -> dict:
    """Each cell's PROM at its 2^p corners c ± (1 - 1e-9) h (pulled inside, so that the cell's own PROM answers)
    against the FOM at the vertex c ± h (one FOM run per vertex, shared by the cells meeting there; the 1e-9 h
    between the two moves the distance far below the 3 % tested). The cells: every regular cell of the box, or,
    on a scene with capped radii (``[reduction] validity_change`` or ``atlas_change`` > 0), whose cells are refined as PROMs are
    built, the leaves that answered an atlas sweep of ``designs`` (built first, in the same PROM cache)."""
    from aquarom_fenics.reduction.atlas_refine import divides
    from aquarom_fenics.studies.atlas import cover

    grid = cover(scene)
    capped = divides(scene)
    with atlas_cache(folder):
        if capped:
            if not designs:
                raise ValueError("a scene with capped radii needs the designs whose leaves are walked")
            nodes = used_leaves(grid, prom_sweep(scene, designs, workers, folder / "leaves"))
        else:
            nodes = regular_cells(grid)
        corners, vertices = leaf_corners(grid, nodes)
        rows = prom_sweep(scene, [design for _, design, _ in corners], workers, folder / "every-corner")
    keys = list(vertices)
    checked = [("vertex", dict(zip(grid.names, vertices[key].tolist())) | {"prom_center": "", "reach": 1.0,
                                                                            "distance_m": np.nan, "design": k})
               for k, key in enumerate(keys)]
    fom = {key: entry for key, entry in zip(keys, fom_check(scene, checked, workers, folder))}
    results = []
    for (vertex, design, node), row in zip(corners, rows):
        reference = fom[vertex]
        entry = {"design": design, "vertex": list(vertex), "cell": node.id, "prom_center": row.get("prom_center"),
                 "prom_status": row["status"], "prom_distance_m": row.get("distance_m"),
                 "fom_status": reference["fom_status"], "fom_distance_m": reference["fom_distance_m"]}
        if row["status"] == "completed" and reference["fom_status"] == "completed":
            entry["relative_error"] = (row["distance_m"] - reference["fom_distance_m"]) / abs(reference["fom_distance_m"])
        results.append(entry)
    errors = [abs(entry["relative_error"]) for entry in results if "relative_error" in entry]
    worst = max(results, key=lambda entry: abs(entry.get("relative_error", np.inf)))
    cell_errors = {}
    for entry in results:
        cell_errors.setdefault(entry["cell"], []).append(abs(entry.get("relative_error", np.inf)))
    return {"walked": f"the leaves that answered {len(designs)} designs" if capped else "every cell of the box",
            "cells": len(nodes), "corners": len(corners), "vertices": len(keys), "compared": len(errors),
            "answered_by_own_cell": sum(entry["prom_center"] == entry["cell"] for entry in results),
            "largest_relative_error": worst.get("relative_error"), "largest_at": worst["design"],
            "largest_cell": worst["cell"], "above_limit": sum(error > LIMIT for error in errors),
            "limit": LIMIT, "within_limit": bool(errors) and len(errors) == len(results) and max(errors) <= LIMIT
            and all(entry["prom_center"] == entry["cell"] for entry in results),
            "cells_above_limit": sorted(name for name, errs in cell_errors.items() if max(errs) > LIMIT),
            "designs": results, "cell_of": {node.id: list(node.index) for node in nodes}}


def start_corner_designs(scene, grid, count: int, seed: int) -> list[tuple[str, dict]]:
    """(why, design) of the start design and ``count`` random corners c ± (1 - 1e-9) h (signs drawn with ``seed``,
    pulled inside so that the cell's own PROM answers them) of the start's cell and of one other random cell."""
    rng = np.random.default_rng(seed)
    start = np.array([shape.start for shape in scene.shapes], dtype=float)
    home = grid.cells(start[None, :])[0]
    other = home
    while grid.box_cells() > 1 and np.array_equal(other, home):
        other = rng.integers(0, grid.counts)
    designs = [("start", dict(zip(grid.names, start.tolist())))]
    for why, cell in (("start cell corner", home), ("other cell corner", other)):
        center = grid.center(cell)
        for _ in range(count):
            signs = rng.choice((-1.0, 1.0), size=len(grid.names))
            designs.append((why, dict(zip(grid.names, (center + (1 - 1e-9) * signs * grid.half_width).tolist()))))
    return designs


def start_corners(scene, count: int, seed: int, workers: int, folder: Path) -> dict:
    """The atlas (its cells' PROMs, built in ``folder``'s empty PROM cache) against the FOM at
    :func:`start_corner_designs`."""
    from aquarom_fenics.studies.atlas import cover

    grid = cover(scene)
    designs = start_corner_designs(scene, grid, count, seed)
    with atlas_cache(folder):
        rows = prom_sweep(scene, [design for _, design in designs], workers, folder / "start-corners")
        atlas = json.loads((folder / "start-corners" / "atlas.json").read_text())
    checked = [(why, row | {"reach": leaf_reach(grid, row)}) for (why, _), row in zip(designs, rows)
               if row["status"] == "completed"]
    results = fom_check(scene, checked, workers, folder) if checked else []
    errors = [abs(entry["relative_error"]) for entry in results if "relative_error" in entry]
    worst = max(results, key=lambda entry: abs(entry.get("relative_error", np.inf)), default={})
    return {"atlas_scale": grid.scale, "cells_per_shape": dict(zip(grid.names, grid.counts.tolist())),
            "cells_in_box": grid.box_cells(), "half_width": dict(zip(grid.names, grid.half_width.tolist())),
            "designs_checked": len(designs), "prom_answered": len(checked), "fom_completed": len(errors),
            "builds": atlas["totals"]["built"], "build_time_s": atlas["totals"]["build_time_s"],
            "check_corner_builds": atlas["totals"].get("check_corner_builds", 0),
            "leaves": sorted({row["prom_center"] for row in rows if row.get("prom_center")}),
            "largest_relative_error": worst.get("relative_error"), "largest_at": worst.get("design"),
            "largest_why": worst.get("why"), "limit": LIMIT,
            "within_limit": bool(errors) and len(errors) == len(designs) and max(errors) <= LIMIT, "designs": results}


def cover_record(atlas: dict) -> dict:
    """The atlas's radii: the scale s, the validity radius r, the cells' half-width h ≤ s r, cells per shape."""
    return {key: atlas[key] for key in ("radius_scale", "validity_radius", "cell_half_width", "cells_per_shape",
                                        "cells_in_box")}


def time_split(atlas: dict) -> dict:
    """Where the sweep's worker time went, from atlas.json's centre records: builds (wall and thread CPU [s],
    the first of each worker apart: it sets up the FOM the later builds move; with capped radii the cells bisected
    on the way included) and batched solves."""
    centres = atlas["centres"]
    built = [c for c in centres + atlas.get("refinement", {}).get("split_centres", []) if c["status"] == "built"]
    first = [c["build_time_s"] for c in built if c.get("builds_in_worker") == 1]
    later = [c["build_time_s"] for c in built if c.get("builds_in_worker", 0) > 1]
    designs = max(atlas["totals"]["designs"], 1)
    return {"builds": len(built), "build_wall_s": sum(c["build_time_s"] for c in built),
            "build_cpu_s": sum(c.get("build_cpu_s", 0.0) for c in built),
            "workers": len({c.get("worker") for c in built}), "first_build_per_worker_s": first,
            "later_build_mean_s": float(np.mean(later)) if later else None,
            "later_build_cpu_mean_s": float(np.mean([c.get("build_cpu_s", 0.0) for c in built
                                                     if c.get("builds_in_worker", 0) > 1])) if later else None,
            "solve_wall_s": sum(c.get("solve_time_s", 0.0) for c in centres),
            "solve_cpu_s": sum(c.get("solve_cpu_s", 0.0) for c in centres),
            "solve_cpu_per_design_s": sum(c.get("solve_cpu_s", 0.0) for c in centres) / designs}


def checked_designs(scene, rows: list[dict], random: int, farthest: int, seed: int) -> list[tuple[str, dict]]:
    """(why, row) of ``random`` completed rows drawn with ``seed`` and the ``farthest`` completed rows
    farthest from the centre of the cell that answered them (max_k |ξ_k - c_k| / h_k, :func:`leaf_reach`), none
    twice."""
    from aquarom_fenics.studies.atlas import cover

    grid = cover(scene)
    completed = [row for row in rows if row["status"] == "completed"]
    reach = np.array([leaf_reach(grid, row) for row in completed])
    drawn = np.random.default_rng(seed).choice(len(completed), size=random, replace=False).tolist()
    far = [k for k in np.argsort(-reach, kind="stable").tolist() if k not in drawn][:farthest]
    return [("random", completed[k] | {"reach": float(reach[k])}) for k in drawn] + \
           [("farthest", completed[k] | {"reach": float(reach[k])}) for k in far]


def leaf_reach(grid, row: dict) -> float:
    """max_k |ξ_k - c_k| / h_k of a row from the centre of the atlas cell that answered it (``prom_center``: a
    regular cell, or a refined one where a capped radius split it; 1 on the cell's faces)."""
    from aquarom_fenics.reduction.atlas_refine import node_of

    node = node_of(row["prom_center"], grid)
    xi = np.array([row[name] for name in grid.names])
    half = node.half_width(grid)
    return float(np.max(np.divide(np.abs(xi - node.center(grid)), half, out=np.zeros_like(half), where=half > 0),
                        initial=0.0))


def fom_check(scene, checked: list[tuple[str, dict]], workers: int, folder: Path) -> list[dict]:
    """The FOM at the checked designs (a FOM sweep through the FOM cache) against the atlas's answers."""
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.parallel import open_pool, shutting_down
    from aquarom_fenics.studies.sweep import run_sweep

    designs = [{name: row[name] for name in scene.shape_names} for _, row in checked]
    with shutting_down(open_pool(min(workers, len(designs)), None, SWIMMER_WORKERS)) as pool:
        fom_rows = run_sweep(scene, designs, "fom", folder / f"fom-{checked[0][0]}", pool)
    results = []
    for (why, row), fom in zip(checked, fom_rows):
        entry = {"why": why, "design": {name: row[name] for name in scene.shape_names},
                 "sweep_row": row["design"], "prom_center": row["prom_center"], "reach": row["reach"],
                 "prom_distance_m": row["distance_m"], "fom_status": fom["status"],
                 "fom_distance_m": fom.get("distance_m"), "fom_cached": fom.get("cached")}
        if fom["status"] == "completed":
            entry["relative_error"] = (row["distance_m"] - fom["distance_m"]) / abs(fom["distance_m"])
        results.append(entry)
    return results


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="so1")
    parser.add_argument("--samples", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0, help="seed of the Latin hypercube (default 0)")
    parser.add_argument("--random", type=int, default=20, help="random designs checked with the FOM (default 20)")
    parser.add_argument("--farthest", type=int, default=5, help="farthest designs checked with the FOM (default 5)")
    parser.add_argument("--check-seed", type=int, default=0, help="seed of the random designs checked (default 0)")
    parser.add_argument("--corners", type=int, default=0,
                        help="also the FOM at the 2^p corners of this many cells, those of the largest errors "
                             "checked (default 0; reported apart from the check)")
    parser.add_argument("--every-corner", action="store_true",
                        help="instead: every cell's PROM at its 2^p corners against the FOM at the grid's vertices "
                             "(results/validation/atlas_corners.json; SO1: 324 builds, 490 FOM runs); with capped "
                             "radii the leaves that answered the sweep of --samples designs")
    parser.add_argument("--start-corners", type=int, default=0,
                        help="instead: the start design and this many random corners (--check-seed) of the start's "
                             "cell and of one other cell against the FOM (results/validation/atlas_start_corners.json)")
    parser.add_argument("--atlas-scale", type=float, default=None,
                        help="the scene's [reduction] atlas_scale s for this check (default: the scene's)")
    parser.add_argument("--atlas-check", type=float, default=None,
                        help="the scene's [reduction] atlas_check τ for this check (default: the scene's)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "atlas.json")
    parser.add_argument("--sweep-only", action="store_true",
                        help="the atlas sweep only (results/bench/atlas_sweep.json), no FOM check")
    parser.add_argument("--bench", type=Path, default=REPOSITORY / "results" / "bench" / "atlas_sweep.json")
    args = parser.parse_args()
    for option, least in (("samples", 1), ("workers", 1), ("random", 0), ("farthest", 0), ("corners", 0),
                          ("start_corners", 0)):
        if getattr(args, option) < least:
            parser.error(f"--{option} {getattr(args, option)}: a count, at least {least}")
    for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[variable] = "1"
    from aquarom_fenics.errors import InputError
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.io.scene import Scene
    from aquarom_fenics.io.versions import software_versions
    from aquarom_fenics.studies.sweep import latin_hypercube, summary
    from aquarom_fenics.reduction.atlas_refine import divides
    from aquarom_fenics.verification.validation.suite import machine

    scene = Scene.load(args.scene).replace("output", plots=False)
    if args.atlas_scale is not None:
        try:
            scene = scene.replace("reduction", atlas_scale=args.atlas_scale)
        except InputError as error:
            parser.error(f"--atlas-scale: {error}")
    if args.atlas_check is not None:
        try:
            scene = scene.replace("reduction", atlas_check=args.atlas_check)
        except InputError as error:
            parser.error(f"--atlas-check: {error}")
    if args.start_corners:
        out = args.out.with_name("atlas_start_corners.json") if args.out.name == "atlas.json" else args.out
        load_before = os.getloadavg()
        started = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="validate-atlas-") as scratch:
            report = start_corners(scene, args.start_corners, args.check_seed, args.workers, Path(scratch))
        report = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(), "versions": software_versions(),
                  "scene": args.scene, "check_seed": args.check_seed, "workers": args.workers,
                  "wall_time_s": time.perf_counter() - started, "load_average_before": load_before,
                  "load_average_after": os.getloadavg()} | report
        write_json_atomic(out, report)
        largest = report["largest_relative_error"]
        print(f"start corners at s = {report['atlas_scale']:g}: {report['fom_completed']} of {report['designs_checked']} "
              f"designs compared, {report['builds']} PROMs built (and {report['check_corner_builds']} corner PROMs of the "
              f"atlas check), largest relative distance error "
              f"{100 * (largest if largest is not None else np.nan):+.2f} % ({report['largest_why']}), "
              f"{report['wall_time_s']:.0f} s; wrote {out}")
        return 0 if report["within_limit"] else 1
    if args.every_corner:
        out = args.out.with_name("atlas_corners.json") if args.out.name == "atlas.json" else args.out
        load_before = os.getloadavg()
        started = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="validate-atlas-") as scratch:
            report = every_corner(scene, args.workers, Path(scratch), latin_hypercube(scene, args.samples, args.seed)
                                  if divides(scene) else None)
        report = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(), "versions": software_versions(),
                  "scene": args.scene, "workers": args.workers, "wall_time_s": time.perf_counter() - started,
                  "load_average_before": load_before, "load_average_after": os.getloadavg()} | report
        write_json_atomic(out, report)
        print(f"every corner ({report['walked']}): {report['compared']} of {report['corners']} corners of "
              f"{report['cells']} cells, {report['answered_by_own_cell']} answered by their own cell "
              f"({report['vertices']} FOM vertices), largest relative distance error "
              f"{100 * (report['largest_relative_error'] if report['largest_relative_error'] is not None else np.nan):+.2f} "
              f"% at {report['largest_at']} ({report['largest_cell']}), "
              f"{report['above_limit']} above {100 * LIMIT:g} %; wrote {out}")
        return 0 if report["within_limit"] else 1
    designs = latin_hypercube(scene, args.samples, args.seed)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="validate-atlas-") as scratch:
        sweep = atlas_sweep(scene, designs, args.workers, Path(scratch))
        counts = summary(sweep["rows"])["counts"]
        totals = sweep["atlas"]["totals"]
        split = time_split(sweep["atlas"])
        print(f"atlas sweep: {len(designs)} designs, {counts}, {totals['centres']} centres used, "
              f"{totals['built']} PROMs built "
              f"({totals['build_time_s']:.1f} s of builds; {totals.get('check_corner_builds', 0)} corner PROMs of the "
              f"atlas check, {totals.get('check_time_s', 0.0):.1f} s of checks), {sweep['wall_time']:.1f} s; worker time: builds "
              f"{split['build_wall_s']:.1f} s (CPU {split['build_cpu_s']:.1f} s; first per worker "
              f"{', '.join(f'{t:.2f}' for t in split['first_build_per_worker_s'])} s, others "
              f"{split['later_build_mean_s'] or 0.0:.3f} s each), solves {split['solve_wall_s']:.1f} s "
              f"(CPU {split['solve_cpu_s']:.1f} s, {1e3 * split['solve_cpu_per_design_s']:.2f} ms per design)", flush=True)
        load_after_sweep = os.getloadavg()
        common = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": machine(), "versions": software_versions(),
                  "scene": args.scene, "samples": args.samples, "seed": args.seed, "workers": args.workers,
                  "load_average_before": load_before, "load_average_after_sweep": load_after_sweep}
        sweep_record = {"wall_time_s": sweep["wall_time"], "counts": counts, "every_design_answered":
                        counts["completed"] == len(designs), "centres": totals["centres"], "built": totals["built"],
                        "check_corner_builds": totals.get("check_corner_builds", 0),
                        "build_time_s": totals["build_time_s"], "cells_in_box": sweep["atlas"]["cells_in_box"],
                        "seconds_per_design": sweep["wall_time"] / len(designs),
                        "atlas": cover_record(sweep["atlas"]), "where_the_time_goes": time_split(sweep["atlas"])}
        write_json_atomic(args.bench, common | {"sweep": sweep_record})
        if args.sweep_only:
            print(f"wrote {args.bench}")
            return 0
        checked = checked_designs(scene, sweep["rows"], args.random, args.farthest, args.check_seed)
        results = fom_check(scene, checked, args.workers, Path(scratch))
        corners = corner_check(scene, results, args.corners, args.workers, Path(scratch)) if args.corners else []
    errors = [abs(entry["relative_error"]) for entry in results if "relative_error" in entry]
    worst = max(results, key=lambda entry: abs(entry.get("relative_error", np.inf)))
    report = common | {"sweep": sweep_record, "atlas": {key: value for key, value in sweep["atlas"].items()},
                       "check": {"random": args.random, "farthest": args.farthest, "check_seed": args.check_seed,
                                 "designs": results, "checked": len(results), "fom_completed": len(errors),
                                 "largest_relative_error": worst.get("relative_error"),
                                 "largest_at": worst["design"], "limit": LIMIT,
                                 "within_limit": len(errors) == len(results) and max(errors) <= LIMIT}}
    if corners:
        largest = max(corners, key=lambda entry: abs(entry.get("relative_error", np.inf)))
        report["corners"] = {"cells": args.corners, "designs": corners, "largest_relative_error":
                             largest.get("relative_error"), "largest_at": largest["design"]}
        print(f"corners of {args.corners} cells: {len(corners)} designs, largest relative distance error "
              f"{100 * largest.get('relative_error', np.nan):+.2f} % at {largest['design']} ({largest['prom_center']})")
    write_json_atomic(args.out, report)
    print(f"FOM check: {len(errors)} of {len(results)} designs, largest relative distance error "
          f"{100 * worst.get('relative_error', np.nan):+.2f} % at {worst['design']} (limit {100 * LIMIT:g} %); "
          f"wrote {args.out}")
    return 0 if report["check"]["within_limit"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
