"""The scene a command runs on, and the checks commands share before their work.

Each command declares its own checks beside it (``@checked(inputs)``): ``inputs(args)`` reads the
scene and refuses what the run would refuse, so ``--dry-run`` makes the same checks before it
prints the plan.
"""
from __future__ import annotations

import functools
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
        from aquarom_fenics.studies.plan import check_mesh_bounds

        check_mesh_bounds(scene)
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


def checked(inputs):
    """Declare a command's input checks: the command runs as ``run(args, scene, xi)`` after
    ``inputs(args)`` returned the scene it uses and the --xi values; with --dry-run the same checks
    are made and the plan is printed instead of the work."""
    def declare(run):
        @functools.wraps(run)
        def command(args) -> int:
            scene, xi = inputs(args)
            if getattr(args, "dry_run", False):
                return print_plan(args, scene)
            return run(args, scene, xi)
        return command
    return declare


def print_plan(args, scene) -> int:
    """The dry run of a command whose input checks passed: what it would build, reuse and skip."""
    from aquarom_fenics.studies.plan import plan

    lines = plan(args.command, scene, getattr(args, "model", None))      # refuses a bad mesh before printing
    say(f"plan for `aquarom {args.command}` (dry run, nothing is written):")
    for line in lines:
        say(f"  {line}")
    return 0


def design_values(args, scene) -> dict[str, float]:
    """The --xi values (none where the command has no --xi), checked against the scene's shapes."""
    from aquarom_fenics.io.command_values import parse_xi_assignments

    return parse_xi_assignments(getattr(args, "xi", None), scene)


def check_prom_option(args) -> None:
    """--prom goes with --model prom only."""
    if getattr(args, "prom", None) is not None and getattr(args, "model", "prom") != "prom":
        raise InputError(f"--prom {args.prom} is used by --model prom only (this run: --model {args.model})")


def check_time_runs(args, scene) -> None:
    """A command that runs a model in time: the scene's time grid, and (without --allow-large) the
    size of one run (steps × dofs)."""
    from aquarom_fenics.dynamics.simulate import check_time_grid

    check_time_grid(scene)
    if not getattr(args, "allow_large", False):
        from aquarom_fenics.studies.plan import check_run_bounds

        check_run_bounds(scene)


def check_plan(args, command: str, scene) -> None:
    """Without --allow-large: the reduced tensors of ``command``'s basis fit in memory and its plan
    is estimated under the time limit (:func:`aquarom_fenics.studies.plan.check_plan_bounds`)."""
    if not getattr(args, "allow_large", False):
        from aquarom_fenics.studies.plan import check_plan_bounds

        check_plan_bounds(command, scene, getattr(args, "model", None))


def check_design_space(scene) -> None:
    """An optimisation's design space, with a start inside its bounds for the paper's method."""
    from aquarom_fenics.optimization.cost import design_space, require_interior

    space = design_space(scene)
    if scene.optimizer.method == "paper" and scene.gait:
        raise InputError(f"scene {scene.source}: [optimizer] method = \"paper\" with [gait] variables: its steps and "
                         "rebuild threshold are in the shapes' units (a step of 0.05 in degrees or hertz); use "
                         "method = \"trust-region\", whose box scales each variable by its range")
    if scene.optimizer.method == "paper" and scene.cooptimization.enabled and scene.cooptimization.effort == "power":
        raise InputError(f"scene {scene.source}: [optimizer] method = \"paper\" with [cooptimization] effort = "
                         "\"power\": its linearised cost between builds counts A² alone; use method = \"trust-region\"")
    if scene.optimizer.method == "paper":
        require_interior(space, scene)


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
