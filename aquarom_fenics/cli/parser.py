"""The ``aquarom`` command line: sub-commands, their options and examples."""
from __future__ import annotations

import argparse
from pathlib import Path


EXAMPLES = {
    "mesh": "aquarom mesh scenes/nominal.toml",
    "shapes": "aquarom shapes so1 --xi y_thin=0.1 --xi z_tail=-0.3 --out results/shapes",
    "simulate": "aquarom simulate nominal --model fom --level 1 --out results/nominal-fom\n"
                "  mpirun -n 2 aquarom simulate so1 --xi y_thin=0.1 --out results/so1-thin\n"
                "  aquarom simulate so1 --model prom --prom results/so1-prom.npz --xi y_thin=0.02",
    "build": "aquarom build so1 --out results/so1-prom.npz",
    "compare": "aquarom compare so1 --xi y_thin=0.02 --level 1 --out results/so1-compare",
    "optimize": "aquarom optimize so1 --level 1 --out results/so1-opt\n  aquarom optimize so1 --out results/so1-opt --resume",
    "pareto": "aquarom pareto co --level 1 --out results/co-pareto\n"
              "  aquarom pareto co --budgets 0.05:0.4:8 --out results/co-budgets\n"
              "  aquarom pareto co --scheduler-file ~/dask-scheduler.json --out results/co-pareto\n"
              "  aquarom pareto co --level 1 --out results/co-pareto --resume",
    "animate": "aquarom animate results/nominal-fom --fps 20 --stride 2",
    "basis": "aquarom basis so1 --level 1 --out results/so1-basis",
    "check": "aquarom check so1 --level 1\n  aquarom check so1 --level 1 --degree 2\n"
             "  aquarom check so1 --prom results/so1-prom.npz\n  aquarom check my-scene.toml --shapes-module my_fields.py",
    "export": "aquarom export so1 --xi y_thin=0.1 --out results/so1-thin.stl\n"
              "  aquarom export nominal --regions --out results/nominal-parts\n"
              "  aquarom export nominal --units m --out results/nominal.msh",
    "calibrate": "aquarom calibrate nominal --level 1 --data swim.csv --fit material.young_modulus "
                 "--fit fluid.thrust_factor=0.5:2 --out results/nominal-calibrated",
    "cache": "aquarom cache list\n  aquarom cache clear --kind prom",
    "sweep": "aquarom sweep so1 --grid z_tail=-0.3:0.3:5 --grid y_thin=0:0.1:3 --level 1 --out results/so1-sweep\n"
             "  aquarom sweep so1 --samples 200 --seed 1 --scheduler tcp://head-node:8786 --out results/so1-lhs\n"
             "  aquarom sweep so1 --designs designs.csv --model prom --dry-run",
}


DEFAULT_WEIGHT = 0.5
"""w_1 of a co-optimisation when --weight is not given."""

VERBOSE_HELP = "log details (solver set-up, timings)"


def verbose_option(parser: argparse.ArgumentParser) -> None:
    """-v/--verbose on a sub-command too (``aquarom simulate so1 -v``); given nowhere, it stays False."""
    parser.add_argument("--verbose", "-v", action="store_true", default=argparse.SUPPRESS, help=VERBOSE_HELP)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="aquarom", description="Shape optimisation of soft swimmers with FEniCSx and parametric ROMs.",
        epilog="Scenes: a path to a TOML file, or the name of a shipped scene (nominal, so1 … so9, co).")
    parser.add_argument("--verbose", "-v", action="store_true", help=VERBOSE_HELP)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    shape_parameter = "shape parameter (repeatable)"

    def command(name, help_text, out: str | None = None, xi: str | None = None, prom: str | None = None,
                progress: bool = False):
        """A sub-command on a scene; ``out``, ``xi`` and ``prom`` are the help texts of the options
        --out (with --force), --xi and --prom where the command has them."""
        sub = commands.add_parser(name, help=help_text, description=help_text,
                                  epilog=f"example:\n  {EXAMPLES[name]}", formatter_class=argparse.RawDescriptionHelpFormatter)
        sub.add_argument("scene", help="scene file (.toml) or shipped scene name")
        sub.add_argument("--level", type=int, choices=range(1, 6), metavar="{1..5}",
                         help="override the scene's mesh level (1 is the coarsest)")
        sub.add_argument("--degree", type=int, choices=(1, 2),
                         help="override the scene's element degree (1: linear, 2: quadratic tetrahedra)")
        sub.add_argument("--dry-run", action="store_true",
                         help="print what would be built, reused and skipped, and a time estimate; write nothing")
        sub.add_argument("--allow-large", action="store_true",
                         help="run a plan beyond the size limits (mesh far outside its level, steps × dofs, reduced "
                              "tensors, an estimate over 1 h)")
        sub.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE", dest="settings",
                         help="override one scene value, validated like the file (repeatable), "
                              "e.g. --set solver.duration=0.5 or --set shapes.z_tail.start=0.1")
        sub.add_argument("--shapes-module", metavar="MODULE_OR_FILE.py",
                         help="Python module (a file, or a module name on the Python path) that registers the "
                              "scene's own shape fields with register_shape_field; imported before the scene is read")
        verbose_option(sub)
        if xi:
            sub.add_argument("--xi", action="append", metavar="NAME=VALUE", help=xi)
        if prom:
            sub.add_argument("--prom", type=Path, help=prom)
        if out:
            sub.add_argument("--out", type=Path, help=out)
            sub.add_argument("--force", action="store_true", help="replace existing outputs")
        if progress:
            sub.add_argument("--no-progress", action="store_true",
                             help="no progress bars of FOM runs (they show on a terminal only)"
                                  + ("; no line per finished design" if name == "sweep" else ""))
        return sub

    command("mesh", "report the scene's mesh: cells, nodes, tags, cell quality")
    command("shapes", "write a design mesh (XDMF + PNG), or a sheet of every shape variation at ± its bound",
            out="output directory (default results/shapes/SCENE)", xi=shape_parameter)
    simulate = command("simulate", "simulate the swimmer over the scene's horizon",
                       out="output directory (default results/simulate/SCENE-MODEL)", xi=shape_parameter,
                       prom="PROM file from `aquarom build` (model prom; built if absent)", progress=True)
    simulate.add_argument("--model", choices=["fom", "rom", "prom"], default="fom",
                          help="full-order model, ROM of the design, or PROM of the scene (default fom)")
    command("build", "build the scene's PROM (basis and reduced tensors) and save it to one file",
            out="PROM file (default results/build/SCENE-prom.npz)", xi="building point (default: start values)",
            progress=True)
    compare = command("compare", "run the FOM and the reduced model at one design and report their errors",
                      out="output directory (default results/compare/SCENE)", xi=shape_parameter,
                      prom="PROM file from `aquarom build` (built if absent)", progress=True)
    compare.add_argument("--model", choices=["rom", "prom"], default="prom", help="reduced model to check")
    optimize = command("optimize", "optimise the shape (and the amplitude, for co-optimisation scenes) with the PROM",
                       out="output directory (default results/optimize/SCENE)", progress=True)
    optimize.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    optimize.add_argument("--method", choices=["paper", "trust-region"], help="override the scene's method")
    optimize.add_argument("--weight", type=float,
                          help=f"w_1 of L = w_1(-d) + (1-w_1) α A², co-optimisation scenes only (default {DEFAULT_WEIGHT})")
    optimize.add_argument("--max-time", type=float, metavar="SECONDS",
                          help="stop the optimiser after this wall time (default 86400 s, one day)")
    add_cluster_options(optimize, "the starts of a multi-start ([optimizer] starts > 1)",
                        "local worker processes, one start each (default 1: one after the other here)")
    pareto = command("pareto", "co-optimisation weight sweep: Pareto front of distance against actuation energy",
                     out="output directory (default results/pareto/SCENE)", progress=True)
    add_cluster_options(pareto, "the weights", "local worker processes, one weight each "
                                               "(default 1: the weights one after the other in this process)")
    pareto.add_argument("--resume", action="store_true",
                        help="continue the sweep in --out: keep the weights that completed, continue the others "
                             "from their checkpoints (with --budgets: keep the budgets done, continue from the last)")
    pareto.add_argument("--budgets", metavar="LOW:HIGH:COUNT",
                        help="trace the front by effort budgets instead of the weights: maximise the distance "
                             "subject to A ≤ A_k for COUNT budgets from LOW to HIGH (or a comma list A1,A2,...), "
                             "each from the previous optimum, each FOM-checked")
    add_sweep(command("sweep", "run a model at every design of a CSV file, a grid or a Latin hypercube (sweep.csv, "
                            "sweep.png); on local worker processes or a Dask cluster",
                      out="output directory (default results/sweep/SCENE-MODEL)", progress=True))
    from aquarom_fenics.viz.animate import DEFAULT_FPS

    animate_help = "animate a simulation run (MP4 and GIF preview): the fish from above and from the side"
    animate = commands.add_parser("animate", help=animate_help, description=animate_help,
                                  epilog=f"example:\n  {EXAMPLES['animate']}",
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
    verbose_option(animate)
    animate.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="output directory of `aquarom simulate`")
    animate.add_argument("--out", type=Path, help="MP4 file (default RUN_DIR/animation.mp4, with the GIF preview "
                         "RUN_DIR/animation.gif)")
    animate.add_argument("--gif", type=Path, help="GIF preview file (default: none when --out is given)")
    animate.add_argument("--force", action="store_true", help="replace an animation the toolkit wrote earlier")
    animate.add_argument("--fps", type=int, default=DEFAULT_FPS, help=f"frames per second (default {DEFAULT_FPS})")
    animate.add_argument("--stride", type=int, default=1, help="one frame every K stored samples (default 1)")
    command("basis", "build the scene's PROM and draw every basis vector on the fish (basis.png)",
            out="output directory (default results/basis/SCENE)")
    command("check", "Taylor tests of the scene's shape-field gradients against their values and of its PROM "
                     "against its FOM forms and finite differences (exit 1 on a FAIL)",
            prom="PROM file from `aquarom build` to check (default: build one)")
    export = command("export", "write the design's body: a closed STL surface (binary, outward normals), one per region "
                               "with --regions, or the tagged volume mesh (.msh, .vtu); checked before writing",
                     out="output file (.stl, .msh or .vtu; a folder with --regions)", xi=shape_parameter)
    export.add_argument("--units", choices=["mm", "m"], default="mm", help="length unit of the file (default mm)")
    export.add_argument("--regions", action="store_true",
                        help="one closed STL surface per region (head, each muscle, the passive body) in the "
                             "folder --out; interfaces belong to both neighbours")
    calibrate = command("calibrate", "fit scene parameters (E, head factor, damping, k·A, frequency, fluid factors, a time "
                                     "offset) to a measured swim by "
                                     "least squares on the PROM, checked with the FOM (calibration.json, fit.png, "
                                     "calibrated.toml)",
                        out="output directory (default results/calibrate/SCENE)", progress=True)
    calibrate.add_argument("--data", type=Path, metavar="SWIM.csv",
                           help="the measured swim: time_s and any of head_x_m, tail_y_m, com_x_m, tail_x_m, "
                                "com_y_m (displacements from rest [m])")
    calibrate.add_argument("--fit", action="append", metavar="KEY[=LO:HI]",
                           help="a scene key to fit, e.g. material.young_modulus or fluid.drag_factor=0.5:2 "
                                "(repeatable; default bounds: a tenth to ten times the scene's value)")
    calibrate.add_argument("--max-iterations", type=int, default=30, metavar="N",
                           help="Levenberg–Marquardt iterations on the PROM before the fit counts as not converged "
                                "(exit 3, its best point written; default 30)")
    cache_help = "list or clear the caches of meshes, PROMs and FOM checks (content-addressed, checksummed)"
    cache = commands.add_parser("cache", help=cache_help, description=cache_help,
                                epilog=f"example:\n  {EXAMPLES['cache']}", formatter_class=argparse.RawDescriptionHelpFormatter)
    verbose_option(cache)
    cache.add_argument("action", choices=["list", "clear"])
    cache.add_argument("--kind", action="append", choices=["prom", "fom", "mesh"],
                       help="cache to clear (repeatable; default prom and fom)")
    return parser


def add_sweep(sweep: argparse.ArgumentParser) -> None:
    """The options of ``aquarom sweep``: where the designs come from, the model, where it runs."""
    designs = sweep.add_argument_group("designs (give one source; the scene's shapes and [gait] variables; those not set keep their start values)")
    designs.add_argument("--designs", type=Path, metavar="FILE.csv",
                         help="CSV file with a header of variable names (shapes, [gait] variables) and one design per row")
    designs.add_argument("--grid", action="append", metavar="NAME=LO:HI:N",
                         help="N evenly spaced values of a shape or [gait] variable from LO to HI (repeatable: the grid is the product)")
    designs.add_argument("--samples", type=int, metavar="N",
                         help="N designs of a Latin hypercube over the scene's bounds")
    designs.add_argument("--seed", type=int, default=0, help="seed of --samples (default 0)")
    sweep.add_argument("--model", choices=["fom", "rom", "prom"], default="fom",
                       help="full-order model, a ROM per design, or the scene's PROM (default fom)")
    sweep.add_argument("--resume", action="store_true",
                       help="keep the rows of sweep.csv in --out and run only the designs it lacks")
    add_cluster_options(sweep, "the designs", "local worker processes (default: the number of cores; "
                                              "1 runs in this process)")


def add_cluster_options(command: argparse.ArgumentParser, what: str, workers_help: str) -> None:
    """--workers, --scheduler, --scheduler-file, --connect-timeout: where ``what`` runs."""
    where = command.add_argument_group(f"where {what} run (default: local; a scene's [cluster] table also names a "
                                       "Dask scheduler)")
    where.add_argument("--workers", type=int, metavar="N", help=workers_help)
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on the workers of this Dask scheduler, e.g. tcp://head-node:8786")
    where.add_argument("--scheduler-file", type=Path, metavar="FILE",
                       help="run on the Dask scheduler of this file (`dask scheduler --scheduler-file FILE`)")
    where.add_argument("--connect-timeout", type=float, metavar="SECONDS",
                       help="how long to wait for the scheduler before giving up (default 10, or [cluster])")
