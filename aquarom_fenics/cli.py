"""The ``aquarom`` command: scene files in, results, plots and pictures out.

Bad input ends in one line on stderr and exit code 2; a solver that stops early keeps what it
computed, says when it stopped and exits with code 3.
"""
from __future__ import annotations

import argparse
import logging
import os
import shutil
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from .errors import InputError, SolverError

EXAMPLES = {
    "mesh": "aquarom mesh scenes/nominal.toml",
    "shapes": "aquarom shapes so1 --xi y_thin=0.1 --xi z_tail=-0.3 --out results/shapes",
    "simulate": "aquarom simulate nominal --model fom --level 1 --out results/nominal-fom\n"
                "  mpirun -n 2 aquarom simulate so1 --xi y_thin=0.1 --out results/so1-thin\n"
                "  aquarom simulate so1 --model prom --prom results/so1-prom.npz --xi y_thin=0.05",
    "build": "aquarom build so1 --out results/so1-prom.npz",
    "compare": "aquarom compare so1 --xi y_thin=0.05 --level 1 --out results/so1-compare",
    "optimize": "aquarom optimize so1 --level 1 --out results/so1-opt\n  aquarom optimize so1 --out results/so1-opt --resume",
    "pareto": "aquarom pareto co --level 1 --out results/co-pareto",
    "animate": "aquarom animate results/nominal-fom --fps 20 --stride 2",
    "basis": "aquarom basis so1 --level 1 --out results/so1-basis",
    "check": "aquarom check so1 --level 1\n  aquarom check so1 --prom results/so1-prom.npz",
    "cache": "aquarom cache list\n  aquarom cache clear --kind prom",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="aquarom", description="Shape optimisation of soft swimmers with FEniCSx and parametric ROMs.",
        epilog="Scenes: a path to a TOML file, or the name of a shipped scene (nominal, so1 … so9, co).")
    parser.add_argument("--verbose", "-v", action="store_true", help="log details (solver set-up, timings)")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, help_text):
        sub = commands.add_parser(name, help=help_text, description=help_text,
                                  epilog=f"example:\n  {EXAMPLES[name]}", formatter_class=argparse.RawDescriptionHelpFormatter)
        sub.add_argument("scene", help="scene file (.toml) or shipped scene name")
        sub.add_argument("--level", type=int, choices=range(1, 6), metavar="{1..5}",
                         help="override the scene's mesh level (1 is the coarsest)")
        sub.add_argument("--dry-run", action="store_true",
                         help="print what would be built, reused and skipped, and a time estimate; write nothing")
        return sub

    command("mesh", "report the scene's mesh: cells, nodes, tags, cell quality")
    shapes = command("shapes", "write a design mesh (XDMF + PNG), or a sheet of every shape variation at ± its bound")
    shapes.add_argument("--xi", action="append", metavar="NAME=VALUE", help="shape parameter (repeatable)")
    shapes.add_argument("--out", type=Path, help="output directory (default results/shapes/SCENE)")
    shapes.add_argument("--force", action="store_true", help="replace existing outputs")
    simulate = command("simulate", "simulate the swimmer over the scene's horizon")
    simulate.add_argument("--model", choices=["fom", "rom", "prom"], default="fom",
                          help="full-order model, ROM of the design, or PROM of the scene (default fom)")
    simulate.add_argument("--xi", action="append", metavar="NAME=VALUE", help="shape parameter (repeatable)")
    simulate.add_argument("--prom", type=Path, help="PROM file from `aquarom build` (model prom; built if absent)")
    simulate.add_argument("--out", type=Path, help="output directory (default results/simulate/SCENE-MODEL)")
    simulate.add_argument("--force", action="store_true", help="replace existing outputs")
    simulate.add_argument("--no-progress", action="store_true", help="no progress bar")
    build = command("build", "build the scene's PROM (basis and reduced tensors) and save it to one file")
    build.add_argument("--xi", action="append", metavar="NAME=VALUE", help="building point (default: start values)")
    build.add_argument("--out", type=Path, help="PROM file (default results/build/SCENE-prom.npz)")
    build.add_argument("--force", action="store_true", help="replace existing outputs")
    compare = command("compare", "run the FOM and the reduced model at one design and report their errors")
    compare.add_argument("--model", choices=["rom", "prom"], default="prom", help="reduced model to check")
    compare.add_argument("--xi", action="append", metavar="NAME=VALUE", help="shape parameter (repeatable)")
    compare.add_argument("--prom", type=Path, help="PROM file from `aquarom build` (built if absent)")
    compare.add_argument("--out", type=Path, help="output directory (default results/compare/SCENE)")
    compare.add_argument("--force", action="store_true", help="replace existing outputs")
    compare.add_argument("--no-progress", action="store_true", help="no progress bar")
    optimize = command("optimize", "optimise the shape (and the amplitude, for co-optimisation scenes) with the PROM")
    optimize.add_argument("--out", type=Path, help="output directory (default results/optimize/SCENE)")
    optimize.add_argument("--force", action="store_true", help="replace existing outputs")
    optimize.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    optimize.add_argument("--method", choices=["paper", "trust-region"], help="override the scene's method")
    optimize.add_argument("--weight", type=float, default=0.5,
                          help="w_1 of L = w_1(-d) + (1-w_1) α A² for co-optimisation scenes (default 0.5)")
    pareto = command("pareto", "co-optimisation weight sweep: Pareto front of distance against actuation energy")
    pareto.add_argument("--out", type=Path, help="output directory (default results/pareto/SCENE)")
    pareto.add_argument("--force", action="store_true", help="replace existing outputs")
    from .animate import DEFAULT_FPS

    animate_help = "animate a simulation run (MP4 and GIF preview): the fish from above and from the side"
    animate = commands.add_parser("animate", help=animate_help, description=animate_help,
                                  epilog=f"example:\n  {EXAMPLES['animate']}",
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
    animate.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="output directory of `aquarom simulate`")
    animate.add_argument("--out", type=Path, help="MP4 file (default RUN_DIR/animation.mp4; the GIF goes next to it)")
    animate.add_argument("--fps", type=int, default=DEFAULT_FPS, help=f"frames per second (default {DEFAULT_FPS})")
    animate.add_argument("--stride", type=int, default=1, help="one frame every K stored samples (default 1)")
    basis = command("basis", "build the scene's PROM and draw every basis vector on the fish (basis.png)")
    basis.add_argument("--out", type=Path, help="output directory (default results/basis/SCENE)")
    basis.add_argument("--force", action="store_true", help="replace existing outputs")
    check = command("check", "Taylor tests of the scene's PROM against its FOM forms and finite differences "
                             "(exit 1 on a FAIL)")
    check.add_argument("--prom", type=Path, help="PROM file from `aquarom build` to check (default: build one)")
    cache_help = "list or clear the caches of meshes, PROMs and FOM checks (content-addressed, checksummed)"
    cache = commands.add_parser("cache", help=cache_help, description=cache_help,
                                epilog=f"example:\n  {EXAMPLES['cache']}", formatter_class=argparse.RawDescriptionHelpFormatter)
    cache.add_argument("action", choices=["list", "clear"])
    cache.add_argument("--kind", action="append", choices=["prom", "fom", "mesh"],
                       help="cache to clear (repeatable; default prom and fom)")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    rank = MPI.COMM_WORLD.rank
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    logging.getLogger("aquarom").setLevel(logging.INFO if rank == 0 else logging.ERROR)
    started = time.perf_counter()
    try:
        if getattr(args, "dry_run", False):
            return run_dry(args)
        code = COMMANDS[args.command](args)
        if code == 0 and getattr(args, "output_dir", None) is not None and rank == 0:
            write_manifest(args, time.perf_counter() - started)
        return code
    except InputError as error:
        if rank == 0:
            print(f"aquarom {args.command}: error: {error}", file=sys.stderr)
        return InputError.exit_code
    except SolverError as error:
        if rank == 0:
            print(f"aquarom {args.command}: solver stopped: {error}", file=sys.stderr)
        return SolverError.exit_code


def run_dry(args) -> int:
    from .plan import plan

    scene = load_scene(args)
    say(f"plan for `aquarom {args.command}` (dry run, nothing is written):")
    for line in plan(args.command, scene, getattr(args, "model", None)):
        say(f"  {line}")
    return 0


def claim_output(args, path: Path, resume: bool = False) -> Path:
    """An output location that may be written: refuses to overwrite existing outputs without --force."""
    path = Path(path)
    occupied = path.is_file() or (path.is_dir() and any(path.iterdir()))
    if occupied and not resume:
        if not getattr(args, "force", False):
            raise InputError(f"output {path} exists; pass --force to replace it or choose another --out")
        if MPI.COMM_WORLD.rank == 0:
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        MPI.COMM_WORLD.barrier()
    if path.suffix == "":
        args.output_dir = path
    return path


def write_manifest(args, wall_time: float) -> None:
    """manifest.json: scene, versions, git commit, command, host cores, timings per phase."""
    from .outputs import git_commit, software_versions, write_json_atomic
    from .scene import REPOSITORY

    scene = getattr(args, "scene_used", None)
    write_json_atomic(args.output_dir / "manifest.json", {
        "command": "aquarom " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("aquarom") else args.command,
        "arguments": {k: str(v) for k, v in vars(args).items() if k not in ("scene_used", "timings", "output_dir")},
        "scene": None if scene is None else {"name": scene.name, "source": scene.source, "hash": scene.hash,
                                             "values": scene.to_dict()},
        "versions": software_versions(), "git_commit": git_commit(REPOSITORY),
        "host_cores": os.cpu_count(), "mpi_ranks": MPI.COMM_WORLD.size,
        "timings": {"total": wall_time} | getattr(args, "timings", {}),
        "date": time.strftime("%Y-%m-%d %H:%M:%S")})


def load_scene(args):
    """The scene named on the command line, with the --level override applied."""
    from .scene import Scene

    scene = Scene.load(args.scene)
    if args.level is not None:
        scene = scene.replace("mesh", level=args.level)
    args.scene_used = scene
    return scene


def say(text: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(text, flush=True)


def run_mesh(args) -> int:
    from .fish import load_fish
    from .mesh import cell_quality

    scene = load_scene(args)
    fish = load_fish(scene)
    mesh, tags = fish.mesh, fish.tags
    quality = cell_quality(mesh.points, mesh.cells)
    box = tags.box
    say(textwrap.dedent(f"""\
        scene {scene.name}: {mesh.source}
          box          L = {box.length:.4g} m, W = {box.width:.4g} m, H = {box.height:.4g} m
          cells        {mesh.cells.shape[0]}
          nodes        {mesh.points.shape[0]}  ({3 * mesh.points.shape[0]} dofs)
          head         {tags.head_cells.size} cells, {tags.head_nodes.size} nodes
          muscles      left {tags.left_muscle_cells.size} cells, right {tags.right_muscle_cells.size} cells
          skin         {tags.skin_facets.shape[0]} facets, {tags.skin_nodes.size} nodes
          spine        {tags.spine_nodes.size} nodes, {tags.spine_segments.shape[0]} segments, tail node {tags.tail_node}
          dorsal nodes {tags.dorsal_nodes.size}
          quality      min {quality.min():.3f}, mean {quality.mean():.3f} (1 = regular tetrahedron)"""))
    return 0


def run_shapes(args) -> int:
    from .render import render_design, render_shape_sheet
    from .fish import load_fish
    from .scene import parse_xi_assignments

    scene = load_scene(args)
    xi = parse_xi_assignments(args.xi, scene)
    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "shapes" / scene.name)
    if xi:
        design = fish.design(xi)
        files = render_design(fish, design, xi, out)
    else:
        if not scene.shapes:
            raise InputError(f"scene {scene.source} has no [shapes]: nothing to show (add shape variations or use --xi)")
        files = render_shape_sheet(fish, scene, out)
    for path in files:
        say(f"wrote {path}")
    return 0


def run_simulate(args) -> int:
    from .scene import parse_xi_assignments
    from .simulate import simulate_fom

    scene = load_scene(args)
    xi = parse_xi_assignments(args.xi, scene)
    out = claim_output(args, args.out or Path("results") / "simulate" / f"{scene.name}-{args.model}")
    if args.model == "fom":
        result = simulate_fom(scene, xi=xi, out_dir=out, progress=not args.no_progress)
    else:
        result = run_reduced_model(scene, xi, args.model, args.prom, out)
    if not result.completed:
        raise SolverError(f"{result.error}; partial trajectory in {out / 'trajectory.csv'}")
    say(f"{scene.name} ({args.model}): distance {100 * result.distance:.3f} cm, tail amplitude "
        f"{100 * result.tail_amplitude:.3f} cm, {result.wall_time:.2f} s on {MPI.COMM_WORLD.size} rank(s)")
    say(f"outputs in {out}/ (trajectory.csv, summary.json, trajectory.png)")
    return 0


def reduced_model(scene, xi: dict, model: str, prom_file: Path | None):
    """A ROM built at the design, or the scene's PROM (loaded from ``prom_file`` or built at the start values)."""
    from .cache import cached_prom
    from .fish import load_fish
    from .prom import ReducedModel
    from .reductor import build_prom

    if prom_file is not None and model == "prom":
        return ReducedModel.load(prom_file, scene_hash=scene.hash)
    fish = load_fish(scene)
    center = {s.name: s.start for s in scene.shapes} | (xi if model == "rom" else {})
    vector = fish.parameter_vector(center)
    if model == "prom":
        # Refuse a design beyond the validity radius before spending time on the build.
        ReducedModel.refuse_outside_radius(scene.shape_names, fish.parameter_vector(center | xi), vector,
                                           np.array(scene.validity_radii()))
    return cached_prom(scene, vector, lambda: build_prom(scene, xi_center=vector, fish=fish,
                                                          parametric=model == "prom"), parametric=model == "prom")


def run_reduced_model(scene, xi: dict, model: str, prom_file: Path | None, out: Path):
    from .animate import DISPLACEMENT_FILE, write_displacement_series
    from .fish import load_fish
    from .outputs import write_trajectory_csv
    from .reduced_dynamics import simulate_reduced
    from .simulate import write_run_outputs

    reduced = reduced_model(scene, xi, model, prom_file)
    xi_vector = np.array([xi.get(name, reduced.design_point.get(name, 0.0)) for name in reduced.shape_names])
    result = simulate_reduced(reduced, scene, xi_vector)
    fish = load_fish(scene)
    if MPI.COMM_WORLD.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        write_trajectory_csv(out / "trajectory.csv", result.trajectory.arrays())
        design = reduced.design_point | xi
        write_displacement_series(out / DISPLACEMENT_FILE, fish.design(design), fish.mesh.cells,
                                  result.trajectory.arrays()["time"],
                                  np.einsum("ndm,sm->snd", reduced.basis, result.states))
        write_run_outputs(out, scene, result, model, list(design.values()), list(design), MPI.COMM_WORLD,
                          extra={"cells": reduced.cells, "dofs": reduced.dofs, "reduced_size": reduced.size,
                                 "basis": reduced.labels, "basis_dropped": reduced.dropped,
                                 "build_timings": reduced.timings})
    return result


def run_build(args) -> int:
    from .cache import cached_prom
    from .fish import load_fish
    from .reductor import build_prom
    from .scene import parse_xi_assignments

    scene = load_scene(args)
    xi = {s.name: s.start for s in scene.shapes} | parse_xi_assignments(args.xi, scene)
    out = claim_output(args, args.out or Path("results") / "build" / f"{scene.name}-prom.npz")
    fish = load_fish(scene)
    center = fish.parameter_vector(xi)
    prom = cached_prom(scene, center, lambda: build_prom(scene, xi_center=center, fish=fish))
    if MPI.COMM_WORLD.rank == 0:
        prom.save(out)
    say(f"PROM of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}), p = {prom.n_parameters}, "
        f"built in {prom.timings['total']:.2f} s; wrote {out}")
    return 0


def run_compare(args) -> int:
    from .compare import model_errors
    from .outputs import plot_comparison, write_json_atomic
    from .scene import parse_xi_assignments
    from .simulate import simulate_fom

    scene = load_scene(args)
    xi = parse_xi_assignments(args.xi, scene)
    out = claim_output(args, args.out or Path("results") / "compare" / scene.name)
    reduced = run_reduced_model(scene, xi, args.model, args.prom, out / args.model)
    full = simulate_fom(scene, xi=xi, out_dir=out / "fom", progress=not args.no_progress)
    for name, result in (("fom", full), (args.model, reduced)):
        if not result.completed:
            raise SolverError(f"{name}: {result.error}")
    errors = model_errors(full, reduced)
    if MPI.COMM_WORLD.rank == 0:
        write_json_atomic(out / "compare.json", {"xi": xi, "model": args.model, "errors": errors,
                                                 "fom": full.summary(), args.model: reduced.summary(),
                                                 "speedup": full.wall_time / reduced.wall_time})
        plot_comparison(out / "compare.png", {"FOM": full.trajectory.arrays(),
                                              args.model.upper(): reduced.trajectory.arrays()},
                        f"{scene.name}: FOM against {args.model.upper()}")
    say(f"{scene.name} at {xi or 'the start values'}: distance FOM {100 * full.distance:.3f} cm, "
        f"{args.model.upper()} {100 * reduced.distance:.3f} cm ({100 * errors['distance_relative']:+.2f} %); "
        f"tail amplitude {100 * errors['tail_amplitude_relative']:+.2f} %; outputs in {out}/")
    return 0


def run_optimize(args) -> int:
    from .cost import CostWeights
    from .study import run_optimization

    scene = load_scene(args)
    if args.method:
        scene = scene.replace("optimizer", method=args.method)
    if not scene.shapes:
        raise InputError(f"scene {scene.source} has no [shapes] to optimise")
    weights = CostWeights()
    if scene.cooptimization.enabled:
        if not 0.0 <= args.weight <= 1.0:
            raise InputError(f"--weight {args.weight}: must be in [0, 1]")
        weights = CostWeights(args.weight, 1.0 - args.weight, scene.cooptimization.energy_weight)
    out = claim_output(args, args.out or Path("results") / "optimize" / scene.name, resume=args.resume)
    result, check = run_optimization(scene, out, resume=args.resume, weights=weights)
    args.timings = result.timings | {"fom_check": check.time}
    space = result.space
    say(f"{scene.name} ({scene.optimizer.method}): optimum "
        + ", ".join(f"{n} = {v:.4g}" for n, v in zip(space.names, result.optimum))
        + f"; {result.builds} PROM builds, {result.timings['total']:.1f} s ({result.stop_reason})")
    if check.error:
        raise SolverError(f"FOM check: {check.error}; the optimisation outputs are in {out}/")
    say(f"FOM check: nominal {100 * check.nominal_distance:.3f} cm, optimal {100 * check.optimal_distance:.3f} cm "
        f"(PROM {100 * check.prom_optimal_distance:.3f} cm), ratio {check.ratio:.2f}; outputs in {out}/")
    return 0


def run_pareto(args) -> int:
    from .study import pareto_sweep

    scene = load_scene(args)
    if not scene.cooptimization.enabled:
        raise InputError(f"scene {scene.source}: [cooptimization] enabled = true is needed for a Pareto sweep")
    out = claim_output(args, args.out or Path("results") / "pareto" / scene.name)
    points = pareto_sweep(scene, out)
    for point in points:
        say(f"w1 = {point['w1']:.2f}: amplitude {point['amplitude']:.3f}, energy {point['energy']:.4f}, "
            f"FOM distance {100 * point['distance']:.3f} cm")
    say(f"outputs in {out}/ (pareto.csv, pareto.png, one folder per weight)")
    return 0


def run_animate(args) -> int:
    from .animate import animate_run

    for path in animate_run(args.run_dir, out=args.out, fps=args.fps, stride=args.stride):
        say(f"wrote {path}")
    return 0


def run_basis(args) -> int:
    from .animate import render_basis_sheet
    from .fish import load_fish
    from .reductor import build_prom

    scene = load_scene(args)
    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "basis" / scene.name)
    prom = build_prom(scene, xi_center={s.name: s.start for s in scene.shapes}, fish=fish)
    files = render_basis_sheet(prom, fish, out)
    dropped = f"; dropped as dependent: {', '.join(prom.dropped)}" if prom.dropped else ""
    say(f"basis of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}){dropped}; wrote {files[0]}")
    return 0


def run_check(args) -> int:
    from .check import run_checks, table_header, table_row
    from .fish import load_fish
    from .prom import ReducedModel
    from .reductor import build_prom

    scene = load_scene(args)
    fish = load_fish(scene)
    if args.prom is not None:
        prom = ReducedModel.load(args.prom, scene_hash=scene.hash)
    else:
        prom = build_prom(scene, xi_center={s.name: s.start for s in scene.shapes}, fish=fish)
    say(f"PROM of {scene.name} ({args.prom or 'built'}): m = {prom.size}, p = {prom.n_parameters}, "
        f"{prom.cells} cells; mesh of the scene: {fish.mesh.cells.shape[0]} cells")
    say(table_header())
    failed = []
    for result in run_checks(scene, prom, fish):
        say(table_row(result))
        if result.passed is False:
            failed.append(result.check)
    say(f"{len(failed)} check(s) failed: {', '.join(failed)}" if failed else "all checks passed")
    return 1 if failed else 0


def run_cache(args) -> int:
    from .cache import clear, listing

    if args.action == "list":
        for kind, entries, size in listing():
            say(f"{kind:15s} {entries:5d} entries {size / 1e6:9.1f} MB")
        return 0
    for folder in clear(args.kind or ["prom", "fom"]):
        say(f"removed {folder}")
    return 0


COMMANDS = {"mesh": run_mesh, "shapes": run_shapes, "simulate": run_simulate, "build": run_build,
            "compare": run_compare, "optimize": run_optimize, "pareto": run_pareto, "cache": run_cache, "animate": run_animate,
            "basis": run_basis, "check": run_check}

if __name__ == "__main__":
    sys.exit(main())
