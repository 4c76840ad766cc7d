"""The scene a command runs on and the checks it makes before its work."""
from __future__ import annotations

import os
import sys

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
    if not getattr(args, "allow_large", False):
        from aquarom_fenics.optimization.plan import check_mesh_bounds

        check_mesh_bounds(scene)
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
    if args.command in ("simulate", "compare", "shapes") and (xi or args.command != "shapes"):
        warn_about_unnamed_parameters(args, scene, xi)
    if getattr(args, "prom", None) is not None and getattr(args, "model", "prom") != "prom":
        raise InputError(f"--prom {args.prom} is used by --model prom only (this run: --model {args.model})")
    if args.command in ("simulate", "compare", "optimize", "pareto"):
        check_time_grid(scene)
        if not getattr(args, "allow_large", False):
            from aquarom_fenics.optimization.plan import check_run_bounds

            check_run_bounds(scene)
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
    """Print a line on rank 0; a closed stdout (``aquarom … | head``) ends the printing, not the run."""
    if MPI.COMM_WORLD.rank != 0:
        return
    try:
        print(text, flush=True)
    except BrokenPipeError:
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):
            pass


def warn_about_unnamed_parameters(args, scene, xi: dict) -> None:
    """A shape parameter not given with --xi takes 0 in the full-order design; say so when 0 is
    outside the scene's bounds (as a value given with --xi outside them is)."""
    import logging

    if args.command == "simulate" and args.model != "fom":
        return
    for shape in scene.shapes:
        if shape.name not in xi and not shape.lower <= 0.0 <= shape.upper:
            logging.getLogger("aquarom").warning(
                "%s is not given with --xi: the design takes %s = 0, outside the scene's bounds [%g, %g]",
                shape.name, shape.name, shape.lower, shape.upper)
