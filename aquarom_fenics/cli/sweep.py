"""``aquarom sweep``: one model run per design, on local worker processes or a Dask cluster."""
from __future__ import annotations

import os
import time
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.cli.inputs import check_plan, check_time_runs, load_scene, say
from aquarom_fenics.cli.outputs import claim_output, shown
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.run_record import check_run_record, write_run_record


DRY_RUN_CACHE_LOOKUPS = 1000
"""Designs a dry run looks up in the FOM cache (about 1 ms each): its estimate for more is an upper bound."""


def sweep_designs(args, scene) -> tuple[list[dict], str]:
    """The designs of --designs, --grid or --samples (exactly one of them) and a description."""
    from aquarom_fenics.studies import sweep_designs as sources

    given = [name for name, value in (("--designs", args.designs), ("--grid", args.grid),
                                      ("--samples", args.samples)) if value is not None]
    if len(given) != 1:
        raise InputError("give the designs with one of --designs FILE.csv, --grid NAME=LO:HI:N (repeatable) "
                         f"or --samples N{f' (got {chr(32).join(given)})' if given else ''}")
    if args.designs is not None:
        return sources.csv_designs(args.designs, scene), f"{args.designs}"
    if args.grid is not None:
        designs = sources.grid_designs(args.grid, scene)
        return designs, "grid " + " × ".join(spec.partition("=")[0] + "(" + spec.rsplit(":", 1)[-1] + ")"
                                             for spec in args.grid)
    return sources.latin_hypercube(scene, args.samples, args.seed), f"Latin hypercube, seed {args.seed}"


def earlier_rows(args, scene, designs, target: Path) -> dict:
    """The rows --resume keeps (none without it)."""
    from aquarom_fenics.studies.sweep import resumed_rows

    if not args.resume:
        return {}
    path = target / "sweep.csv"
    if not path.is_file():
        raise InputError(f"--resume: no sweep.csv in {target}; run without --resume")
    check_run_record(target, run_record(args, scene))
    return resumed_rows(path, scene, designs, args.model)


def run_record(args, scene) -> dict:
    """What makes a sweep's rows (compared by --resume): the scene's hash (its file, --set, --level,
    --degree) and the model; the designs are compared row by row."""
    return {"command": "sweep", "scene_hash": scene.hash, "model": args.model}


def sweep_inputs(args):
    """``sweep``: not under mpirun, --workers ≥ 1, the scene's time grid and the sizes of one run and of
    the plan (the designs are read next; a dry run needs them for its plan, see :func:`dry_run`)."""
    if MPI.COMM_WORLD.size > 1:
        raise InputError("aquarom sweep spreads its designs over workers itself; run it without mpirun "
                         "(--workers N, or --scheduler for a Dask cluster)")
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers {args.workers}: must be at least 1")
    scene = load_scene(args)
    check_time_runs(args, scene)
    check_plan(args, "sweep", scene)
    return scene


def run_sweep(args) -> int:
    from aquarom_fenics.cli.shapes_module import require_in_process
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.geometry.shape_registry import uses_registered
    from aquarom_fenics.parallel import choose_cluster, open_pool, shutting_down
    from aquarom_fenics.studies import sweep

    scene = sweep_inputs(args)
    designs, source = sweep_designs(args, scene)
    cluster = choose_cluster(args.scheduler, args.scheduler_file, scene.cluster, args.connect_timeout)
    target = args.out or Path("results") / "sweep" / f"{scene.name}-{args.model}"
    kept = earlier_rows(args, scene, designs, target)
    missing = len(designs) - len(kept)
    in_process = uses_registered(scene.shape_names)        # fields of --shapes-module: not in new workers
    workers = min(args.workers or (1 if in_process else os.cpu_count() or 1), max(missing, 1))
    require_in_process(args, scene, workers, cluster.distributed)
    if args.dry_run:
        return dry_run(args, scene, designs, source, kept, cluster, workers)
    started = time.perf_counter()
    # an unreachable scheduler is refused before any output; Ctrl-C or a refused output stops the workers at once
    with shutting_down(open_pool(workers, cluster, SWIMMER_WORKERS)) as pool:
        out = claim_output(args, target, resume=args.resume, resume_file="sweep.csv")
        write_run_record(out, run_record(args, scene))
        backend = describe_backend(pool, cluster)
        say(f"sweep of {scene.name}: {len(designs)} designs ({source}), model {args.model}, {missing} to run "
            f"{backend}" + (f", {len(kept)} kept from sweep.csv" if kept else ""))
        rows = sweep.run_sweep(scene, designs, args.model, out, pool, resume=args.resume,
                               on_row=None if args.no_progress else progress_line(len(designs), len(kept),
                                                                                  sweep.variable_names(scene)))
    result = sweep.summary(rows)
    args.timings = {"sweep": time.perf_counter() - started}
    args.manifest_extra = {"sweep": {"designs": len(designs), "source": source, "model": args.model,
                                     "backend": backend, "kept_from_resume": len(kept), "counts": result["counts"],
                                     "answered_from_cache": result["cached"]}}
    counts = ", ".join(f"{n} {status}" for status, n in result["counts"].items() if n)
    atlas = atlas_line(out) if args.model == "prom" else None
    if atlas:
        args.manifest_extra["sweep"]["atlas"] = atlas[1]
        say(atlas[0])
    say(f"{len(rows)} designs: {counts}; outputs in {shown(args, out)}/ (sweep.csv, manifest.json"
        + (", atlas.json" if atlas else "") + (", sweep.png)" if scene.output.plots else ")"))
    if result["best"] is not None:
        best = result["best"]
        say("farthest: " + ", ".join(f"{n} = {best[n]:.4g}" for n in sweep.variable_names(scene))
            + f" ({100 * best['distance_m']:.3f} cm)")
    return 0


def atlas_line(out: Path) -> tuple[str, dict] | None:
    """The PROM atlas of a sweep, one line, and its totals (atlas.json's)."""
    import json

    from aquarom_fenics.studies.atlas import ATLAS_FILE

    path = out / ATLAS_FILE
    if not path.is_file():
        return None
    report = json.loads(path.read_text())
    totals, refined = report["totals"], report.get("refinement", {})
    split, limit = len(refined.get("split_centres", [])), refined.get("at_depth_limit", [])
    failed = refined.get("check_failed_at_depth_limit", [])
    checked = "check_corner_builds" in totals and any("check" in record for record in report["centres"])
    return (f"PROM atlas: {totals['centres']} centre(s) used, {totals['built']} built "
            f"({totals['build_time_s']:.1f} s of builds), {totals['from_the_cache']} from the PROM cache"
            + (f"; {split} cell(s) bisected for their capped radius" + (" or their check" if checked else "")
               if split else "")
            + (f"; atlas check: {totals['check_corner_builds']} corner PROM(s) built "
               f"({totals['check_time_s']:.1f} s of checks)" if checked else "")
            + (f"; {len(failed)} cell(s) failed their check at the depth limit (their PROMs answer, unchecked): "
               f"{', '.join(failed[:5])}{' …' if len(failed) > 5 else ''}" if failed else "")
            + (f"; {len(limit)} cell(s) at the depth limit ({refined['max_depth']} bisections), whose PROMs "
               f"answer only within their radius: {', '.join(limit[:5])}{' …' if len(limit) > 5 else ''}"
               if limit else "")), \
        totals | ({"bisected": split, "at_depth_limit": len(limit)} if split or limit else {})


def describe_backend(pool, cluster) -> str:
    from aquarom_fenics.parallel import DaskCluster, InProcess

    if isinstance(pool, DaskCluster):
        return f"on {pool.workers} Dask worker(s) of the {cluster.describe().removeprefix('Dask ')}"
    if isinstance(pool, InProcess):
        return "in this process"
    return f"on {pool.workers} local worker processes"


def progress_line(total: int, done: int, names: list[str]):
    width = len(str(total))
    count = [done]

    def show(row: dict) -> None:
        count[0] += 1
        design = ", ".join(f"{n}={row[n]:.4g}" for n in names)
        outcome = (f"distance {100 * row['distance_m']:.3f} cm" + (" (cached)" if row.get("cached") else "")
                   if row["status"] == "completed" else f"{row['status']}: {row['reason']}")
        took = f", {row['wall_time_s']:.1f} s on {row['worker']}" if row.get("wall_time_s") is not None else ""
        say(f"[{count[0]:>{width}}/{total}] design {row['design']} ({design}): {outcome}{took}")

    return show


def dry_run(args, scene, designs, source, kept, cluster, workers) -> int:
    from aquarom_fenics.studies.plan import plan
    from aquarom_fenics.studies.sweep import cached_designs, estimate

    todo = [design for k, design in enumerate(designs) if k not in kept]
    looked_up = todo[:DRY_RUN_CACHE_LOOKUPS]
    cached = cached_designs(scene, looked_up, args.model)
    missing = len(todo) - cached
    lines = plan("sweep", scene, args.model)[:5]      # scene, mesh, body (2 lines), forms; refuses a bad mesh
    say("plan for `aquarom sweep` (dry run, nothing is written):")
    for line in lines:
        say(f"  {line}")
    from aquarom_fenics.studies.sweep_designs import variable_names

    say(f"  designs: {len(designs)} ({source}) of {', '.join(variable_names(scene))}; model {args.model}")
    if kept:
        say(f"  resume: {len(kept)} rows kept from sweep.csv")
    if args.model == "fom":
        which = (f"the {len(todo)} designs answered already" if len(looked_up) == len(todo)
                 else f"the first {len(looked_up)} designs answered already (the other {len(todo) - len(looked_up)} "
                      "not looked up, counted as to compute)")
        say(f"  FOM cache: {cached} of {which}; {missing} to compute "
            f"({scene.n_steps} steps of {scene.solver.time_step:g} s each)")
    where = cluster.describe() if cluster.distributed else (f"{workers} local worker process(es)" if workers > 1
                                                            else "this process (one worker)")
    say(f"  runs on: {where}")
    centres, most = 0, None
    if args.model == "prom":
        from aquarom_fenics.reduction.atlas_refine import divides
        from aquarom_fenics.studies.atlas import assign, cover

        centres = len(assign(cover(scene), todo))
        say(f"  PROM atlas: {centres} centre(s) to build or take from the PROM cache "
            f"({cover(scene).box_cells()} cells in the box)")
        if divides(scene):
            centres, most = division_line(scene, todo)
    seconds = estimate(scene, missing, args.model, 1 if cluster.distributed else workers, centres)
    bound = (f" for the {centres} build(s) at least; at most ~"
             f"{estimate(scene, missing, args.model, 1 if cluster.distributed else workers, most):.0f} s"
             if most is not None else "")
    say(f"  estimate: ~{seconds:.0f} s" + bound + (" on one worker (divided by the number of the cluster's workers)"
                                                   if cluster.distributed else ""))
    return 0


def division_line(scene, designs: list[dict]) -> tuple[int, int]:
    """Say what the atlas's divisions (capped radii, the atlas check) will build for ``designs`` as far as the
    PROM cache tells (``studies.atlas_plan``: the ways down through its PROMs, read, none built); (builds at
    least, at most)."""
    from aquarom_fenics.reduction.atlas_refine import MAX_DEPTH, capped, check_tolerance
    from aquarom_fenics.studies.atlas_plan import division_plan

    plan = division_plan(scene, designs)
    tolerance = check_tolerance(scene)
    rule = ("[reduction] validity_change caps each PROM's radius at its centre: a cell whose capped radius is below "
            "it is divided at once into the halvings that radius asks for" if capped(scene) else "")
    if tolerance > 0:
        rule += ("; " if rule else "") + (
            f"[reduction] atlas_check = {tolerance:g}: each cell's PROM is compared with the PROMs at two of its "
            f"corners (up to 2 more builds a cell), and a cell whose relative distance gap exceeds {tolerance:g} is "
            "halved in every shape and its half checked again. The gaps are known only once those PROMs are built "
            "and solved, which a dry run does not do: it cannot tell which cells will be halved")
    say(f"  refinement: {rule}; up to {MAX_DEPTH} halvings per shape. Through the PROM cache ({plan.read} PROM(s) "
        f"read, none built): {plan.answered_from_cache} of {plan.designs} designs reach a cached leaf "
        f"({plan.leaves_in_cache} leaves)"
        + (f", {plan.unchecked} reach a cached cell whose check is not known" if tolerance > 0 else "")
        + f"; the others stop at {plan.to_build} cell(s) not in the cache: {plan.to_build} to {plan.at_most} PROM "
        "builds (each of those cells, and at most one per halving left below it for each of its designs"
        + (", three with the check's corners" if tolerance > 0 else "") + ")"
        + (f"; {plan.refused} design(s) meet a cell with no PROM" if plan.refused else ""))
    return plan.to_build, plan.at_most
