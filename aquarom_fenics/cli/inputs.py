"""The scene a command runs on and the checks it makes before its work."""
from __future__ import annotations

import os
import sys

from mpi4py import MPI

from aquarom_fenics.errors import InputError


def load_scene(args):
    """The scene named on the command line, with the --set, --level and --degree overrides applied;
    the module of ``--shapes-module`` is imported first (the shape fields it registers)."""
    from aquarom_fenics.io.scene import Scene

    given = getattr(args, "shapes_module", None)
    if given:
        from aquarom_fenics.cli.shapes_module import import_shapes_module, require_used

        registered = import_shapes_module(given)        # before the scene names its fields
    scene = Scene.load(args.scene)
    for setting in getattr(args, "settings", None) or []:
        scene = with_setting(scene, setting)
    if given:
        require_used(given, registered, scene)
    if args.level is not None:
        if scene.mesh.file:
            raise InputError(f"--level {args.level}: scene {scene.source} reads its mesh from the file "
                             f"{scene.mesh.file} ([mesh] file), and levels are those of the built-in block; "
                             "refine the file's mesh instead, or drop --level")
        scene = scene.replace("mesh", level=args.level)
    if args.degree is not None:
        scene = scene.replace("mesh", degree=args.degree)
    if not getattr(args, "allow_large", False):
        from aquarom_fenics.studies.plan import check_mesh_bounds, check_plan_bounds

        check_mesh_bounds(scene)
        if args.command in ("basis", "check"):
            check_plan_bounds(args.command, scene)
    args.scene_used = scene
    return scene


def with_setting(scene, setting: str):
    """The scene with one ``section.key=value`` (or ``shapes.NAME.key=value``) changed; the value is
    TOML (a bare word is a string) and the whole scene is validated again as a file would be."""
    import tomllib

    from aquarom_fenics.io.scene import scene_from_dict

    path, sep, text = setting.partition("=")
    keys = [key.strip() for key in path.split(".")]
    if not sep or len(keys) < 2 or not all(keys):
        raise InputError(f"--set {setting}: expected section.key=value, e.g. --set solver.duration=0.5")
    try:
        value = tomllib.loads(f"value = {text.strip()}")["value"]
    except tomllib.TOMLDecodeError:
        value = text.strip()
    data = tomllib.loads(scene.to_toml())
    table = data
    for key in keys[:-1]:
        table = table.setdefault(key, {})
        if not isinstance(table, dict):
            raise InputError(f"--set {setting}: {'.'.join(keys[:-1])} is a value, not a table")
    table[keys[-1]] = value
    try:
        return scene_from_dict(data, source=scene.source, base_dir=scene.base_dir)
    except InputError as error:
        raise InputError(f"--set {setting}: {error}") from None


def check_inputs(args, scene):
    """The checks a command makes before its work (arguments against the scene, time grid, design
    space), so a dry run refuses what the run would refuse; returns the scene the command uses and
    the --xi values."""
    from aquarom_fenics.optimization.cost import design_space, require_interior
    from aquarom_fenics.io.scene import parse_xi_assignments
    from aquarom_fenics.dynamics.simulate import check_time_grid

    xi = parse_xi_assignments(getattr(args, "xi", None), scene)
    if args.command == "shapes" and xi:
        warn_about_unnamed_parameters(scene, xi)
    if getattr(args, "prom", None) is not None and getattr(args, "model", "prom") != "prom":
        raise InputError(f"--prom {args.prom} is used by --model prom only (this run: --model {args.model})")
    if args.command in ("simulate", "compare", "optimize", "pareto", "sweep"):
        check_time_grid(scene)
        if not getattr(args, "allow_large", False):
            from aquarom_fenics.studies.plan import check_run_bounds

            check_run_bounds(scene)
    if args.command == "optimize":
        if args.method:
            scene = scene.replace("optimizer", method=args.method)
        if not scene.shapes:
            raise InputError(f"scene {scene.source} has no [shapes] to optimise")
        if args.weight is not None and not scene.cooptimization.enabled:
            raise InputError(f"--weight {args.weight}: scene {scene.source} does not co-optimise the amplitude "
                             "([cooptimization] enabled = false), so its cost is -d alone; leave --weight out")
        if args.weight is not None and not 0.0 <= args.weight <= 1.0:
            raise InputError(f"--weight {args.weight}: must be in [0, 1]")
        if args.max_time is not None and not args.max_time > 0:
            raise InputError(f"--max-time {args.max_time}: must be a positive number of seconds")
    if args.command == "pareto" and not scene.cooptimization.enabled:
        raise InputError(f"scene {scene.source}: [cooptimization] enabled = true is needed for a Pareto sweep")
    if args.command == "pareto" and getattr(args, "budgets", None) is not None:
        from aquarom_fenics.studies.budget_front import parse_budgets

        parse_budgets(args.budgets, scene.cooptimization.amplitude_bounds)
    if args.command == "pareto":
        from aquarom_fenics.studies.study import require_distinct_weights

        require_distinct_weights(scene.cooptimization.weights, f"scene {scene.source}")
    if args.command in ("optimize", "pareto"):
        space = design_space(scene)
        if scene.optimizer.method == "paper":
            require_interior(space, scene)
    if args.command in ("simulate", "compare", "optimize", "pareto", "build", "sweep") \
            and not getattr(args, "allow_large", False):
        from aquarom_fenics.studies.plan import check_plan_bounds

        check_plan_bounds(args.command, scene, getattr(args, "model", None))
    return scene, xi


def run_design(scene, xi: dict[str, float]) -> dict[str, float]:
    """The design a command runs: the scene's start values of every shape, overridden by --xi.

    Every model of a command (FOM, ROM, PROM) runs this same design, so a comparison compares
    one design and ``simulate`` without --xi runs what ``build`` and ``optimize`` start from.
    """
    return {shape.name: shape.start for shape in scene.shapes} | xi


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


def warn_about_unnamed_parameters(scene, xi: dict) -> None:
    """``shapes --xi`` draws the design of the given values, the other parameters at 0 (a run takes
    their start values, see :func:`run_design`); say so when 0 is outside the scene's bounds."""
    import logging

    for shape in scene.shapes:
        if shape.name not in xi and not shape.lower <= 0.0 <= shape.upper:
            logging.getLogger("aquarom").warning(
                "%s is not given with --xi: the design takes %s = 0, outside the scene's bounds [%g, %g]",
                shape.name, shape.name, shape.lower, shape.upper)
