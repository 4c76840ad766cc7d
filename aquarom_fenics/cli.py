"""The ``aquarom`` command: scene files in, results, plots and pictures out.

Bad input ends in one line on stderr and exit code 2; a solver that stops early keeps what it
computed, says when it stopped and exits with code 3.
"""
from __future__ import annotations

import argparse
import logging
import sys
import textwrap
from pathlib import Path

from mpi4py import MPI

from .errors import InputError, SolverError

EXAMPLES = {
    "mesh": "aquarom mesh scenes/nominal.toml",
    "shapes": "aquarom shapes so1 --xi y_thin=0.1 --xi z_tail=-0.3 --out results/shapes",
    "simulate": "aquarom simulate nominal --model fom --level 1 --out results/nominal-fom\n"
                "  mpirun -n 2 aquarom simulate so1 --xi y_thin=0.1 --out results/so1-thin",
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
        return sub

    command("mesh", "report the scene's mesh: cells, nodes, tags, cell quality")
    shapes = command("shapes", "write a design mesh (XDMF + PNG), or a sheet of every shape variation at ± its bound")
    shapes.add_argument("--xi", action="append", metavar="NAME=VALUE", help="shape parameter (repeatable)")
    shapes.add_argument("--out", type=Path, help="output directory (default results/shapes/SCENE)")
    simulate = command("simulate", "simulate the swimmer over the scene's horizon")
    simulate.add_argument("--model", choices=["fom"], default="fom", help="model to integrate")
    simulate.add_argument("--xi", action="append", metavar="NAME=VALUE", help="shape parameter (repeatable)")
    simulate.add_argument("--out", type=Path, help="output directory (default results/simulate/SCENE-MODEL)")
    simulate.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    rank = MPI.COMM_WORLD.rank
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    for noisy in ("ffcx", "UFL", "FFCX", "root"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    try:
        return COMMANDS[args.command](args)
    except InputError as error:
        if rank == 0:
            print(f"aquarom {args.command}: error: {error}", file=sys.stderr)
        return InputError.exit_code
    except SolverError as error:
        if rank == 0:
            print(f"aquarom {args.command}: solver stopped: {error}", file=sys.stderr)
        return SolverError.exit_code


def load_scene(args):
    """The scene named on the command line, with the --level override applied."""
    from .scene import Scene

    scene = Scene.load(args.scene)
    if args.level is not None:
        scene = scene.replace("mesh", level=args.level)
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
    out = args.out or Path("results") / "shapes" / scene.name
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
    out = args.out or Path("results") / "simulate" / f"{scene.name}-{args.model}"
    result = simulate_fom(scene, xi=xi, out_dir=out, progress=not args.no_progress)
    if not result.completed:
        raise SolverError(f"{result.error}; partial trajectory in {out / 'trajectory.csv'}")
    say(f"{scene.name} ({args.model}): distance {100 * result.distance:.3f} cm, tail amplitude "
        f"{100 * result.tail_amplitude:.3f} cm, {result.n_cells} cells, {result.n_dofs} dofs, "
        f"{result.wall_time:.1f} s on {MPI.COMM_WORLD.size} rank(s)")
    say(f"outputs in {out}/ (trajectory.csv, summary.json, trajectory.png)")
    return 0


COMMANDS = {"mesh": run_mesh, "shapes": run_shapes, "simulate": run_simulate}

if __name__ == "__main__":
    sys.exit(main())
