"""The scene a command runs on and the checks it makes before its work."""
from __future__ import annotations

from mpi4py import MPI

from aquarom_fenics.errors import InputError


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
    if args.command in ("simulate", "compare", "optimize", "pareto", "sweep"):
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


def say(text: str) -> None:
    if MPI.COMM_WORLD.rank == 0:
        print(text, flush=True)
