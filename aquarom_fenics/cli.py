"""The ``aquarom`` command: scene files in, results, plots and pictures out.

Bad input ends in one line on stderr and exit code 2; a solver that stops early keeps what it
computed, says when it stopped and exits with code 3.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import textwrap
import time
import traceback
import zipfile
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError, Interrupted, SolverError

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
    "check": "aquarom check so1 --level 1\n  aquarom check so1 --level 1 --degree 2\n"
             "  aquarom check so1 --prom results/so1-prom.npz",
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
        sub.add_argument("--degree", type=int, choices=(1, 2),
                         help="override the scene's element degree (1: linear, 2: quadratic tetrahedra)")
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
    optimize.add_argument("--max-time", type=float, metavar="SECONDS",
                          help="stop the optimiser after this wall time (default 86400 s, one day)")
    pareto = command("pareto", "co-optimisation weight sweep: Pareto front of distance against actuation energy")
    pareto.add_argument("--out", type=Path, help="output directory (default results/pareto/SCENE)")
    pareto.add_argument("--force", action="store_true", help="replace existing outputs")
    from aquarom_fenics.viz.animate import DEFAULT_FPS

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


AGREEMENT_SECONDS = 10.0    # how long a failing rank waits for the others to fail too before aborting all


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    comm = MPI.COMM_WORLD
    agreement = comm.Dup() if comm.size > 1 else None
    console = logging.StreamHandler()          # details (INFO) only with --verbose
    console.setFormatter(logging.Formatter("%(message)s"))
    console.setLevel(logging.INFO if args.verbose else logging.WARNING)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, handlers=[console])
    logging.getLogger("aquarom").setLevel(logging.INFO if comm.rank == 0 else logging.ERROR)
    started = time.perf_counter()
    line = None
    try:
        code = run_dry(args) if getattr(args, "dry_run", False) else COMMANDS[args.command](args)
    except (Exception, KeyboardInterrupt) as error:
        code, line = describe_failure(args, error)
    try:
        settle_output(args, code, time.perf_counter() - started)
    except (OSError, InputError) as problem:
        text = os_error_text(problem) if isinstance(problem, OSError) else str(problem)
        code, line = InputError.exit_code, f"{line + '; ' if line else ''}error: the outputs could not be finished ({text})"
    if line is None:
        return code
    return end_in_agreement(agreement, code, f"aquarom {args.command}: {line}")


def describe_failure(args, error: BaseException) -> tuple[int, str]:
    """Exit code and the one line for the user: 2 bad input or OS error, 3 solver stop, 130 Ctrl-C.

    Anything else is a bug: its traceback is printed and the exit code is 1.
    """
    if isinstance(error, KeyboardInterrupt):
        location = getattr(args, "output", None)
        written = location is not None and location.working.is_dir() and any(location.working.iterdir())
        where = f"; partial results in {location.working}/" if written else "; nothing written"
        return Interrupted.exit_code, f"{str(error) or 'interrupted'}{where}"
    if isinstance(error, InputError):
        return InputError.exit_code, f"error: {error}"
    if isinstance(error, SolverError):
        return SolverError.exit_code, f"solver stopped: {error}"
    if isinstance(error, OSError):
        location = getattr(args, "output", None)
        unnamed = f"writing in {location.working}/" if location is not None else "a file"
        return InputError.exit_code, f"error: {os_error_text(error, unnamed)}"
    if MPI.COMM_WORLD.size == 1:
        raise error
    traceback.print_exc()
    return 1, f"internal error on rank {MPI.COMM_WORLD.rank}: {type(error).__name__}: {error}"


def os_error_text(error: OSError, unnamed: str = "a file") -> str:
    """'PATH: what went wrong' for an operating-system error (permission, missing folder, full disk)."""
    where = error.filename if error.filename is not None else unnamed
    return f"{where}: {error.strerror or error}"


def end_in_agreement(agreement, code: int, line: str) -> int:
    """Print the one line and return the exit code, on every rank alike.

    Under MPI the failing ranks wait (on their own communicator) for the others: when every rank
    failed, rank 0 prints its line and all return its code; when some rank is still busy (a
    failure on one rank only), this rank prints its line and aborts every rank with its code.
    """
    if agreement is None:
        print(line, file=sys.stderr, flush=True)
        return code
    request = agreement.Ibarrier()
    deadline = time.monotonic() + AGREEMENT_SECONDS
    while not request.Test():
        if time.monotonic() > deadline:
            print(line, file=sys.stderr, flush=True)
            MPI.COMM_WORLD.Abort(code)
        time.sleep(0.01)
    code, line = agreement.bcast((code, line))
    if agreement.rank == 0:
        print(line, file=sys.stderr, flush=True)
    return code


def run_dry(args) -> int:
    from aquarom_fenics.optimization.plan import plan

    scene, _ = check_inputs(args, load_scene(args))
    say(f"plan for `aquarom {args.command}` (dry run, nothing is written):")
    for line in plan(args.command, scene, getattr(args, "model", None)):
        say(f"  {line}")
    return 0


def check_inputs(args, scene):
    """The checks a command makes before its work (arguments against the scene, time grid, design
    space), so a dry run refuses what the run would refuse; returns the scene the command uses and
    the --xi values."""
    from aquarom_fenics.optimization.cost import design_space, require_interior
    from aquarom_fenics.io.scene import parse_xi_assignments
    from aquarom_fenics.dynamics.simulate import check_time_grid

    xi = parse_xi_assignments(getattr(args, "xi", None), scene)
    if getattr(args, "prom", None) is not None and getattr(args, "model", "prom") != "prom":
        raise InputError(f"--prom {args.prom} is used by --model prom only (this run: --model {args.model})")
    if args.command in ("simulate", "compare", "optimize", "pareto"):
        check_time_grid(scene)
    if args.command == "optimize":
        if args.method:
            scene = scene.replace("optimizer", method=args.method)
        if not scene.shapes:
            raise InputError(f"scene {scene.source} has no [shapes] to optimise")
        if scene.cooptimization.enabled and not 0.0 <= args.weight <= 1.0:
            raise InputError(f"--weight {args.weight}: must be in [0, 1]")
        if args.max_time is not None and not args.max_time > 0:
            raise InputError(f"--max-time {args.max_time}: must be a positive number of seconds")
    if args.command == "pareto" and not scene.cooptimization.enabled:
        raise InputError(f"scene {scene.source}: [cooptimization] enabled = true is needed for a Pareto sweep")
    if args.command in ("optimize", "pareto"):
        space = design_space(scene)
        if scene.optimizer.method == "paper":
            require_interior(space, scene)
    return scene, xi


def claim_output(args, path: Path, resume: bool = False) -> Path:
    """The folder this run writes to (see :func:`outputs.claim_folder`): the output folder itself,
    or a folder beside it when --force replaces an earlier run's results."""
    from aquarom_fenics.io.outputs import claim_folder

    location = on_rank_zero(lambda: claim_folder(path, getattr(args, "force", False), resume))
    args.output = location
    args.output_dir = location.working
    return location.working


def claim_output_file(args, path: Path) -> Path:
    """An output file (a PROM): an existing one is replaced only with --force and only if it is a PROM file."""
    from aquarom_fenics.io.outputs import claim_file

    return on_rank_zero(lambda: claim_file(path, args.force, is_prom_file))


def is_prom_file(path: Path) -> bool:
    """A .npz archive with the header of a PROM file (see ``ReducedModel.save``)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return "header.npy" in archive.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def shown(args, path: Path) -> Path:
    """Where ``path`` (written in the working folder) is once a successful run is published."""
    location = getattr(args, "output", None)
    if location is None or not location.replacing:
        return Path(path)
    return location.target / Path(path).relative_to(location.working)


def on_rank_zero(action):
    """``action()`` on rank 0 (file-system work); its value, or its error as the same InputError on every rank."""
    comm = MPI.COMM_WORLD
    outcome = (None, None)
    if comm.rank == 0:
        try:
            outcome = (action(), None)
        except InputError as error:
            outcome = (None, str(error))
        except OSError as error:
            outcome = (None, os_error_text(error))
    value, problem = comm.bcast(outcome) if comm.size > 1 else outcome
    if problem:
        raise InputError(problem)
    return value


def settle_output(args, code: int, wall_time: float) -> None:
    """Finish the output folder on rank 0: a finished run gets its manifest and is swapped into
    place; a stopped or interrupted one keeps its partial results and a manifest (an earlier
    run being replaced stays untouched); a refused one removes the folder it created."""
    from aquarom_fenics.io.outputs import discard, list_outputs, publish

    location = vars(args).pop("output", None)     # settled once; not an argument for the manifest
    if location is None or MPI.COMM_WORLD.rank != 0:
        return
    if code in (0, SolverError.exit_code, Interrupted.exit_code):
        if location.working.is_dir():
            write_manifest(args, wall_time)
            list_outputs(location.working)
        if code == 0:
            publish(location)
    else:
        discard(location)


def write_manifest(args, wall_time: float) -> None:
    """manifest.json: scene, versions, git commit, command, host cores, timings per phase."""
    from aquarom_fenics.io.outputs import git_commit, software_versions
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.io.paths import PACKAGE

    scene = getattr(args, "scene_used", None)
    write_json_atomic(args.output_dir / "manifest.json", {
        "command": "aquarom " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("aquarom") else args.command,
        "arguments": {k: str(v) for k, v in vars(args).items() if k not in ("scene_used", "timings", "output_dir")},
        "scene": None if scene is None else {"name": scene.name, "source": scene.source, "hash": scene.hash,
                                             "values": scene.to_dict()},
        "versions": software_versions(), "git_commit": git_commit(PACKAGE.parent),
        "host_cores": os.cpu_count(), "mpi_ranks": MPI.COMM_WORLD.size,
        "timings": {"total": wall_time} | getattr(args, "timings", {}),
        "date": time.strftime("%Y-%m-%d %H:%M:%S")})


def load_scene(args):
    """The scene named on the command line, with the --level and --degree overrides applied."""
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load(args.scene)
    if args.level is not None:
        scene = scene.replace("mesh", level=args.level)
    if args.degree is not None:
        scene = scene.replace("mesh", degree=args.degree)
    args.scene_used = scene
    return scene


def say(text: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(text, flush=True)


def run_mesh(args) -> int:
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.geometry.mesh import cell_quality

    scene = load_scene(args)
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
          skin         {tags.skin_facets.shape[0]} facets, {tags.skin_nodes.size} nodes
          spine        {tags.spine_nodes.size} nodes, {tags.spine_segments.shape[0]} segments, tail node {tags.tail_node}
          dorsal nodes {tags.dorsal_nodes.size}
          quality      min {quality.min():.3f}, mean {quality.mean():.3f} (1 = regular tetrahedron)"""))
    return 0


def run_shapes(args) -> int:
    from aquarom_fenics.viz.render import render_design, render_shape_sheet
    from aquarom_fenics.geometry.fish import load_fish

    scene, xi = check_inputs(args, load_scene(args))
    if not xi and not scene.shapes:
        raise InputError(f"scene {scene.source} has no [shapes]: nothing to show (add shape variations or use --xi)")
    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "shapes" / scene.name)
    if xi:
        files = render_design(fish, fish.design(xi), xi, out)
    else:
        files = render_shape_sheet(fish, scene, out)
    for path in files:
        say(f"wrote {shown(args, path)}")
    return 0


def run_simulate(args) -> int:
    from aquarom_fenics.dynamics.simulate import simulate_fom

    scene, xi = check_inputs(args, load_scene(args))
    out = claim_output(args, args.out or Path("results") / "simulate" / f"{scene.name}-{args.model}")
    if args.model == "fom":
        result = simulate_fom(scene, xi=xi, out_dir=out, progress=not args.no_progress)
    else:
        result = run_reduced_model(scene, xi, args.model, args.prom, out)
    if not result.completed:
        raise SolverError(f"{result.error}; partial trajectory in {out / 'trajectory.csv'}")
    say(f"{scene.name} ({args.model}): distance {100 * result.distance:.3f} cm, tail amplitude "
        f"{100 * result.tail_amplitude:.3f} cm, {result.wall_time:.2f} s on {MPI.COMM_WORLD.size} rank(s)")
    say(f"outputs in {shown(args, out)}/ (trajectory.csv, summary.json, trajectory.png)")
    return 0


def reduced_model(scene, xi: dict, model: str, prom_file: Path | None):
    """A ROM built at the design, or the scene's PROM (loaded from ``prom_file`` or built at the start values)."""
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom

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
    """Simulate the ROM or PROM at the design and write its run outputs to ``out``."""
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.io.run_outputs import write_run_outputs

    reduced = reduced_model(scene, xi, model, prom_file)
    xi_vector = np.array([xi.get(name, reduced.design_point.get(name, 0.0)) for name in reduced.shape_names])
    result = simulate_reduced(reduced, scene, xi_vector)
    fish = load_fish(scene)
    if MPI.COMM_WORLD.rank == 0:
        design = reduced.design_point | xi
        vertices = fish.nodes.n_vertices
        write_run_outputs(out, scene, result, model, design, fish.design(design)[:vertices], fish.mesh.cells,
                          np.einsum("ndm,sm->snd", reduced.basis[:vertices], result.states), MPI.COMM_WORLD,
                          extra={"cells": reduced.cells, "dofs": reduced.dofs, "reduced_size": reduced.size,
                                 "basis": reduced.labels, "basis_dropped": reduced.dropped,
                                 "build_timings": reduced.timings})
    return result


def run_build(args) -> int:
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    scene, xi = check_inputs(args, load_scene(args))
    xi = {s.name: s.start for s in scene.shapes} | xi
    out = claim_output_file(args, args.out or Path("results") / "build" / f"{scene.name}-prom.npz")
    fish = load_fish(scene)
    center = fish.parameter_vector(xi)
    prom = cached_prom(scene, center, lambda: build_prom(scene, xi_center=center, fish=fish))
    if MPI.COMM_WORLD.rank == 0:
        prom.save(out)
    say(f"PROM of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}), p = {prom.n_parameters}, "
        f"built in {prom.timings['total']:.2f} s; wrote {out}")
    return 0


def run_compare(args) -> int:
    from aquarom_fenics.verification.compare import model_errors
    from aquarom_fenics.io.outputs import plot_comparison
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.dynamics.simulate import simulate_fom

    scene, xi = check_inputs(args, load_scene(args))
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
        f"tail amplitude {100 * errors['tail_amplitude_relative']:+.2f} %; outputs in {shown(args, out)}/")
    return 0


def run_optimize(args) -> int:
    from aquarom_fenics.optimization.cost import CostWeights
    from aquarom_fenics.optimization.optimize import DEFAULT_MAX_TIME
    from aquarom_fenics.optimization.study import run_optimization

    scene, _ = check_inputs(args, load_scene(args))
    weights = CostWeights()
    if scene.cooptimization.enabled:
        weights = CostWeights(args.weight, 1.0 - args.weight, scene.cooptimization.energy_weight)
    out = claim_output(args, args.out or Path("results") / "optimize" / scene.name, resume=args.resume)
    result, check = run_optimization(scene, out, resume=args.resume, weights=weights,
                                     max_time=DEFAULT_MAX_TIME if args.max_time is None else args.max_time)
    args.timings = result.timings | {"fom_check": check.time}
    space = result.space
    say(f"{scene.name} ({scene.optimizer.method}): optimum "
        + ", ".join(f"{n} = {v:.4g}" for n, v in zip(space.names, result.optimum))
        + f"; {result.builds} PROM builds, {result.timings['total']:.1f} s ({result.stop_reason})")
    if check.error:
        raise SolverError(f"FOM check: {check.error}; the optimisation outputs are in {out}/")
    say(f"FOM check: nominal {100 * check.nominal_distance:.3f} cm, optimal {100 * check.optimal_distance:.3f} cm "
        f"(PROM {100 * check.prom_optimal_distance:.3f} cm), ratio {check.ratio:.2f}; outputs in {shown(args, out)}/")
    return 0


def run_pareto(args) -> int:
    from aquarom_fenics.optimization.study import pareto_sweep

    scene, _ = check_inputs(args, load_scene(args))
    out = claim_output(args, args.out or Path("results") / "pareto" / scene.name)
    points = pareto_sweep(scene, out)
    for point in points:
        say(f"w1 = {point['w1']:.2f}: amplitude {point['amplitude']:.3f}, energy {point['energy']:.4f}, "
            f"FOM distance {100 * point['distance']:.3f} cm")
    say(f"outputs in {shown(args, out)}/ (pareto.csv, pareto.png, one folder per weight)")
    return 0


def run_animate(args) -> int:
    from aquarom_fenics.viz.animate import animate_run

    for path in animate_run(args.run_dir, out=args.out, fps=args.fps, stride=args.stride):
        say(f"wrote {path}")
    return 0


def run_basis(args) -> int:
    from aquarom_fenics.viz.animate import render_basis_sheet
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    scene = load_scene(args)
    fish = load_fish(scene)
    out = claim_output(args, args.out or Path("results") / "basis" / scene.name)
    prom = build_prom(scene, xi_center={s.name: s.start for s in scene.shapes}, fish=fish)
    files = render_basis_sheet(prom, fish, out)
    dropped = f"; dropped as dependent: {', '.join(prom.dropped)}" if prom.dropped else ""
    say(f"basis of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}){dropped}; wrote {shown(args, files[0])}")
    return 0


def run_check(args) -> int:
    from aquarom_fenics.verification.check import run_checks, table_header, table_row
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom

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
    from aquarom_fenics.reduction.cache import clear, listing

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
