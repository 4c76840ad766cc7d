"""The commands of ``aquarom`` (those that run models at one design are in ``runs.py``)."""
from __future__ import annotations

import textwrap
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.cli.inputs import (check_design_space, check_plan, check_time_runs, checked, design_values,
                                       load_scene, say)
from aquarom_fenics.cli.export import run_export
from aquarom_fenics.cli.calibrate import run_calibrate
from aquarom_fenics.cli.outputs import claim_output, claim_output_file, shown
from aquarom_fenics.cli.runs import run_build, run_compare, run_simulate
from aquarom_fenics.cli.sweep import run_sweep
from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.parallel import shutting_down


def mesh_inputs(args):
    """``mesh``: the scene alone (its mesh checked against its level by :func:`load_scene`)."""
    return load_scene(args), {}


@checked(mesh_inputs)
def run_mesh(args, scene, xi) -> int:
    from aquarom_fenics.geometry.fish import body_summary, load_fish
    from aquarom_fenics.geometry.mesh import cell_quality

    fish = load_fish(scene)
    mesh, tags = fish.mesh, fish.tags
    quality = cell_quality(mesh.points, mesh.cells)
    box, nodes = tags.box, fish.nodes.points.shape[0]
    say(textwrap.dedent(f"""\
        scene {scene.name}: {mesh.source}
          box          L = {box.length:.4g} m, W = {box.width:.4g} m, H = {box.height:.4g} m
          cells        {mesh.cells.shape[0]}
          nodes        {nodes} of degree {fish.degree} ({mesh.points.shape[0]} vertices, {3 * nodes} dofs)
          head         {tags.head_cells.size} cells, {tags.head_nodes.size} nodes
          muscles      left {tags.left_muscle_cells.size} cells, right {tags.right_muscle_cells.size} cells
          skin         {tags.skin_facets.shape[0]} facets, {tags.skin_nodes.size} nodes"""))
    for label, text in thrust_points(scene, fish):
        say(f"  {label:<12} {text}")
    say(f"  quality      min {quality.min():.3f}, mean {quality.mean():.3f} (1 = regular tetrahedron)")
    for line in body_summary(scene, mesh, tags):
        label, _, text = line.partition(": ")
        say(f"  {label:<12} {text}")
    return 0


def thrust_points(scene, fish) -> list[tuple[str, str]]:
    """(label, text) rows of where the thrust acts: the stations (N_s + 1, their spacing, the tail
    station, the body's depth d from its skin) and, where the mesh has nodes on its axis, the spine
    (``stations = "nodes"`` acts on it and needs it)."""
    import numpy as np

    from aquarom_fenics.physics.stations import station_positions
    from aquarom_fenics.physics.thrust_full_order import station_sections

    tags, fluid = fish.tags, scene.fluid
    rows = []
    if fluid.stations != "nodes":
        box, count = tags.box, fluid.stations
        sections = station_sections(fish, station_positions(box.length, box.x_tail, count))
        depth = sections.top[:, 2] - sections.bottom[:, 2]
        on_tail = np.abs(box.relative(fish.mesh.points)[:, 0] + box.length) <= tags.tolerance
        face = int(on_tail[tags.skin_facets].all(axis=1).sum())
        tail = (f"the end face x = {box.x_tail:.4g} m ({face} facets)" if fluid.tail_station == "face" and face
                else "the last slab's half-hat" + ("" if fluid.tail_station == "slab" else " (no end face)"))
        rows.append(("stations", f"{count + 1}, every {box.length / count:.4g} m from x = {box.x_tail:.4g} to "
                                 f"{box.x_head:.4g} m; tail station: {tail}; depth d from the skin "
                                 f"{depth.min():.4g} to {depth.max():.4g} m (tail {depth[0]:.4g} m)"))
    if tags.has_spine:
        rows.append(("spine", f"{tags.spine_nodes.size} nodes, {tags.spine_segments.shape[0]} segments, tail node "
                              f"{tags.tail_node}, {tags.dorsal_nodes.size} dorsal nodes"))
    else:
        rows.append(("spine", "none: no nodes on the body axis (the stations need none; stations = \"nodes\" would)"))
    return rows


def shapes_inputs(args):
    """``shapes``: the scene with shapes or an --xi design (a warning where a parameter left out takes 0
    outside its bounds)."""
    scene = load_scene(args)
    xi = design_values(args, scene)
    if not xi and not scene.shapes:
        raise InputError(f"scene {scene.source} has no [shapes]: nothing to show (add shape variations or use --xi)")
    if xi:
        warn_about_unnamed_parameters(scene, xi)
    return scene, xi


def warn_about_unnamed_parameters(scene, xi: dict) -> None:
    """``shapes --xi`` draws the design of the given values, the other parameters at 0 (a run takes
    their start values, see :func:`run_design`); say so when 0 is outside the scene's bounds."""
    import logging

    for shape in scene.shapes:
        if shape.name not in xi and not shape.lower <= 0.0 <= shape.upper:
            logging.getLogger("aquarom").warning(
                "%s is not given with --xi: the design takes %s = 0, outside the scene's bounds [%g, %g]",
                shape.name, shape.name, shape.lower, shape.upper)


@checked(shapes_inputs)
def run_shapes(args, scene, xi) -> int:
    from aquarom_fenics.viz.render import render_design, render_shape_sheet
    from aquarom_fenics.geometry.fish import load_fish

    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "shapes" / scene.name)
    if xi:
        files = render_design(fish, fish.design(xi), xi, out)
    else:
        files = render_shape_sheet(fish, scene, out)
    for path in files:
        say(f"wrote {shown(args, path)}")
    return 0


def optimize_inputs(args):
    """``optimize``: the scene with --method, its shapes and time grid, --weight and --max-time, its
    design space and the size of the plan."""
    scene = load_scene(args)
    check_time_runs(args, scene)
    if args.method:
        scene = scene.replace("optimizer", method=args.method)
    if not scene.shapes and not scene.gait:
        raise InputError(f"scene {scene.source} has no [shapes] or [gait] variables to optimise")
    if args.weight is not None and not scene.cooptimization.enabled:
        raise InputError(f"--weight {args.weight}: scene {scene.source} does not co-optimise the amplitude "
                         "([cooptimization] enabled = false), so its cost is -d alone; leave --weight out")
    if args.weight is not None and not 0.0 <= args.weight <= 1.0:
        raise InputError(f"--weight {args.weight}: must be in [0, 1]")
    if args.max_time is not None and not args.max_time > 0:
        raise InputError(f"--max-time {args.max_time}: must be a positive number of seconds")
    check_design_space(scene)
    check_plan(args, "optimize", scene)
    return scene, {}


@checked(optimize_inputs)
def run_optimize(args, scene, xi) -> int:
    from aquarom_fenics.cli.parser import DEFAULT_WEIGHT
    from aquarom_fenics.optimization.cost import CostWeights
    from aquarom_fenics.optimization.optimize import DEFAULT_MAX_TIME
    from aquarom_fenics.studies.study import checkpoint_pattern, run_optimization

    weights = CostWeights()
    if scene.cooptimization.enabled:
        weight = DEFAULT_WEIGHT if args.weight is None else args.weight
        weights = CostWeights(weight, 1.0 - weight, scene.cooptimization.energy_weight)
    with shutting_down(open_work_pool(args, scene, max(scene.optimizer.starts, scene.optimizer.screen),
                                       default_workers=1)) as pool:
        out = claim_output(args, args.out or Path("results") / "optimize" / scene.name, resume=args.resume,
                           resume_file=checkpoint_pattern(scene))
        result, check = run_optimization(scene, out, resume=args.resume, weights=weights, pool=pool,
                                         max_time=DEFAULT_MAX_TIME if args.max_time is None else args.max_time)
    args.timings = result.timings | {"fom_check": check.time}
    space = result.space
    say(f"{scene.name} ({scene.optimizer.method}): optimum "
        + ", ".join(f"{n} = {v:.4g}" for n, v in zip(space.names, result.optimum))
        + f"; {result.prom_builds} PROM builds, {result.timings['total']:.1f} s ({result.stop_reason})")
    if check.error:
        raise SolverError(f"FOM check: {check.error}; the optimisation outputs are in {out}/")
    say(f"FOM check: start {100 * check.start_distance:.3f} cm, optimal {100 * check.optimal_distance:.3f} cm "
        f"(PROM {100 * check.prom_optimal_distance:.3f} cm), ratio {check.ratio:.2f}; outputs in {shown(args, out)}/")
    return 0


def pareto_inputs(args):
    """``pareto``: a co-optimisation scene with its time grid, --budgets or distinct weights, its
    design space and the size of the plan."""
    from aquarom_fenics.studies.budget_front import parse_budgets
    from aquarom_fenics.studies.study import require_distinct_weights

    scene = load_scene(args)
    check_time_runs(args, scene)
    if not scene.cooptimization.enabled:
        raise InputError(f"scene {scene.source}: [cooptimization] enabled = true is needed for a Pareto sweep")
    if scene.cooptimization.effort == "power":
        raise InputError(f"scene {scene.source}: [cooptimization] effort = \"power\": the Pareto front reports and "
                         "bounds the effort A²; run optimize --weight W per point, or effort = \"amplitude\"")
    if args.budgets is not None:
        if scene.gait:
            raise InputError(f"--budgets: scene {scene.source} has [gait] variables; the budget front bounds A "
                             "alone (its design vector is [shapes, A]); use the weights' front without --budgets")
        parse_budgets(args.budgets, scene.cooptimization.amplitude_bounds)
    require_distinct_weights(scene.cooptimization.weights, f"scene {scene.source}")
    check_design_space(scene)
    check_plan(args, "pareto", scene)
    return scene, {}


@checked(pareto_inputs)
def run_pareto(args, scene, xi) -> int:
    from aquarom_fenics.studies.study import checkpoint_pattern, pareto_sweep

    if args.budgets is not None:
        return run_budget_front(args, scene)
    with shutting_down(open_work_pool(args, scene, len(scene.cooptimization.weights), default_workers=1)) as pool:
        out = claim_output(args, args.out or Path("results") / "pareto" / scene.name, resume=args.resume,
                           resume_file=f"w1_*/{checkpoint_pattern(scene)}")
        points = pareto_sweep(scene, out, pool=pool, resume=args.resume)
    for point in points:
        say(f"w1 = {point['w1']:.2f}: amplitude {point['amplitude']:.3f}, energy {point['energy']:.4f}, "
            f"{fom_phrase(point)}")
    say(f"outputs in {shown(args, out)}/ (pareto.csv, pareto.png, one folder per weight)")
    return 0


def fom_phrase(point: dict) -> str:
    """A Pareto point's FOM check in words: its distance, or that it stopped (with the PROM's distance)."""
    if point["fom_check"] == "completed":
        return f"FOM distance {100 * point['distance_m']:.3f} cm"
    return f"FOM check stopped (infeasible), PROM distance {100 * point['prom_distance_m']:.3f} cm"


def run_budget_front(args, scene) -> int:
    """``aquarom pareto --budgets``: max d subject to A ≤ A_k for each budget, in this process."""
    from aquarom_fenics.studies.budget_front import CHECKPOINT, budget_front, parse_budgets

    budgets = parse_budgets(args.budgets, scene.cooptimization.amplitude_bounds)
    out = claim_output(args, args.out or Path("results") / "pareto" / f"{scene.name}-budgets", resume=args.resume,
                       resume_file=CHECKPOINT)
    for point in budget_front(scene, out, budgets, resume=args.resume):
        say(f"A ≤ {point['budget']:.3f}: amplitude {point['amplitude']:.3f}, {fom_phrase(point)}, PROM "
            f"{100 * point['prom_distance_m']:.3f} cm, {'converged' if point['converged'] else 'NOT converged'}")
    say(f"outputs in {shown(args, out)}/ (pareto.csv, pareto.png)")
    return 0


def open_work_pool(args, scene, tasks: int, default_workers: int):
    """The backend of --workers / --scheduler / --scheduler-file / [cluster] for ``tasks`` tasks, or
    None to run them one after the other here (also for a single task); an unreachable scheduler is
    refused (InputError)."""
    from mpi4py import MPI

    from aquarom_fenics.cli.shapes_module import require_in_process
    from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
    from aquarom_fenics.parallel import choose_cluster, open_pool

    if tasks <= 1:
        return None
    cluster = choose_cluster(args.scheduler, args.scheduler_file, scene.cluster, args.connect_timeout)
    workers = default_workers if args.workers is None else args.workers
    if workers < 1:
        raise InputError(f"--workers {workers}: must be at least 1")
    if not cluster.distributed and min(workers, tasks) <= 1:
        return None
    require_in_process(args, scene, min(workers, tasks), cluster.distributed)
    if MPI.COMM_WORLD.size > 1:
        raise InputError(f"aquarom {args.command} under mpirun runs its tasks one after the other; "
                         "drop --workers / --scheduler (or [cluster]) or run it without mpirun")
    return open_pool(min(workers, tasks), cluster, SWIMMER_WORKERS)


def run_animate(args) -> int:
    from aquarom_fenics.io.output_lock import is_locked_by_another
    from aquarom_fenics.io.outputs import record_outputs
    from aquarom_fenics.viz.animate import ANIMATION_FILE, animate_run, check_animation_options, is_animation_file

    mp4 = args.out or args.run_dir / ANIMATION_FILE
    gif = args.gif or (mp4.with_suffix(".gif") if args.out is None else None)    # only files the user named
    check_animation_options(mp4, args.fps, args.stride, gif)
    writer = is_locked_by_another(args.run_dir)
    if writer:
        raise InputError(f"run directory {args.run_dir} is being written by another aquarom run ({writer}); "
                         "animate it when that run has ended")

    def claim(paths):
        for path in paths:
            claim_output_file(args, path, is_animation_file, path.with_name("animation" + path.suffix).name)

    files = animate_run(args.run_dir, out=mp4, fps=args.fps, stride=args.stride, gif=gif, before_writing=claim)
    if MPI.COMM_WORLD.rank == 0:          # the run folder's manifest lists the animation (what --force may replace)
        record_outputs(args.run_dir, [path for path in files if path.resolve().parent == args.run_dir.resolve()])
    for path in files:
        say(f"wrote {path}")
    return 0


def reduced_basis_inputs(command: str):
    """``basis`` and ``check``: the scene, and the size of the PROM they build."""
    def inputs(args):
        scene = load_scene(args)
        check_plan(args, command, scene)
        return scene, {}
    return inputs


@checked(reduced_basis_inputs("basis"))
def run_basis(args, scene, xi) -> int:
    from aquarom_fenics.viz.animate import render_basis_sheet
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "basis" / scene.name)
    prom = build_prom(scene, xi_center={s.name: s.start for s in scene.shapes}, fish=fish)
    files = render_basis_sheet(prom, fish, out)
    dropped = (f"; left out: {', '.join(prom.dropped)} (numerical combinations of the others, "
               "the basis spans the same motions)" if prom.dropped else "")
    say(f"basis of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}){dropped}; wrote {shown(args, files[0])}")
    return 0


@checked(reduced_basis_inputs("check"))
def run_check(args, scene, xi) -> int:
    from itertools import chain

    from aquarom_fenics.verification.check import run_checks, table_header, table_row
    from aquarom_fenics.verification.shape_fields import check_shape_gradients
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom

    fish = load_fish(scene)
    if args.prom is not None:
        prom = ReducedModel.load(args.prom, prom_hash=scene.prom_hash)
    else:
        prom = build_prom(scene, xi_center={s.name: s.start for s in scene.shapes}, fish=fish)
    say(f"PROM of {scene.name} ({args.prom or 'built'}): m = {prom.size}, p = {prom.n_parameters}, "
        f"{prom.cells} cells; mesh of the scene: {fish.mesh.cells.shape[0]} cells")
    say(table_header())
    failed = []
    for result in chain(check_shape_gradients(fish), run_checks(scene, prom, fish)):
        say(table_row(result))
        if result.passed is False:
            failed.append(result.check)
    say(f"{len(failed)} check(s) failed: {', '.join(failed)}" if failed else "all checks passed")
    return 1 if failed else 0


def run_cache(args) -> int:
    from aquarom_fenics.io.paths import cache_root, mesh_cache
    from aquarom_fenics.io.persistence import clear_entries
    from aquarom_fenics.reduction.cache import listing

    if args.action == "list":
        for kind, folder, entries, size in listing():
            say(f"{kind:15s} {entries:5d} entries {size / 1e6:9.1f} MB  {folder}")
        return 0
    for kind in dict.fromkeys(args.kind or ["prom", "fom"]):
        folder = mesh_cache() if kind == "mesh" else cache_root() / kind
        removed, left = clear_entries(folder)
        kept = (f"; left {len(left)} file(s) the cache did not write: {', '.join(left[:3])}{', …' if len(left) > 3 else ''}"
                if left else "")
        say(f"{kind} cache {folder}: removed {removed} entr{'y' if removed == 1 else 'ies'}{kept}")
    return 0


COMMANDS = {"mesh": run_mesh, "shapes": run_shapes, "simulate": run_simulate, "build": run_build,
            "compare": run_compare, "optimize": run_optimize, "pareto": run_pareto, "cache": run_cache, "animate": run_animate,
            "basis": run_basis, "check": run_check, "sweep": run_sweep,
            "export": run_export, "calibrate": run_calibrate}
