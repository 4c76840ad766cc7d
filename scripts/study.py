"""`make study`: SO1–SO3 and the CO Pareto sweep (on each scene's mesh), collected in one table.

Writes every run under results/studies/ and results/studies/summary.md (case, mesh, parameters,
cells, PROM dofs, builds, wall times, time per build, optimum, bounds active there, how the
optimiser stopped, FOM distance start/optimal, ratio). SO2 runs from 3 starts (its source
reports two local optima); its row is the best FOM-verified one. Each case keeps its rows in
<case>/study_rows.md, and summary.md gathers the rows of every case in the output folder, so
cases run one invocation at a time (`--cases so7 so8`) land in the same table.

Each case runs with both optimisers by default (`--methods paper trust-region`): the paper
method's runs in <case>/, the trust region's in <case>-trust-region/, one table row each.

The cases run one after the other; within a case the Pareto weights and the starts of a
multi-start run on --workers local processes or on a Dask cluster (--scheduler ADDRESS,
--scheduler-file FILE; results/studies must then be on a file system the workers share).
Wall times in the table are then those of the parallel run.
"""
import argparse
import json
import sys
import time
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
from aquarom_fenics.parallel import choose_cluster, open_pool

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.outputs import holds_file
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_text_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.studies.study import (checkpoint_pattern, completed_summary, pareto_sweep, run_optimization,
                                              weight_folder)

REPOSITORY = Path(__file__).resolve().parents[1]

STARTS = {"so2": 3}      # [optimizer] starts per case (1 when not listed)
METHODS = ("paper", "trust-region")
ROWS = "study_rows.md"   # a case's table rows, inside its output folder
HEADER = ["| case | mesh | parameters | cells | PROM dofs | builds (reused from the cache) | optimisation [s] | "
          "FOM check [s] | case wall time [s] | time per build [s] | optimum | active | stop (iterations) | starts | "
          "FOM start [cm] | FOM optimal [cm] | ratio |", "|---" * 17 + "|"]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--level", type=int, help="mesh level for every case (default: each scene's own)")
    parser.add_argument("--degree", type=int, choices=(1, 2), help="element degree for every case (default: each scene's own)")
    parser.add_argument("--cases", nargs="+", default=["so1", "so2", "so3", "co"])
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                        help="optimisers to run each case with (default both; the paper method's runs in <case>/, "
                             "the trust region's in <case>-trust-region/)")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "studies")
    parser.add_argument("--workers", type=int, default=1,
                        help="local worker processes for a case's weights or starts (default 1: one after the other)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="run weights and starts on this Dask scheduler")
    parser.add_argument("--scheduler-file", type=Path, metavar="FILE", help="as --scheduler, from a scheduler file")
    parser.add_argument("--resume", action="store_true",
                        help="continue a study in --out: keep the runs that completed, continue the others from "
                             "their checkpoints (the case wall time is then that of this invocation)")
    args = parser.parse_args()
    try:
        cluster = choose_cluster(args.scheduler, args.scheduler_file)
        pool = open_pool(args.workers, cluster, SWIMMER_WORKERS) if cluster.distributed or args.workers > 1 else None
    except InputError as error:
        print(f"study: error: {error}", file=sys.stderr)
        return InputError.exit_code
    try:
        run_cases(args, pool)
    except InputError as error:
        print(f"study: error: {error}", file=sys.stderr)
        return InputError.exit_code
    finally:
        if pool is not None:
            pool.shutdown()
    return 0


def case_folder(case: str, method: str) -> str:
    """A case's output folder for one optimiser: <case> (the paper method), <case>-trust-region."""
    return case if method == "paper" else f"{case}-{method}"


def run_cases(args, pool) -> None:
    for case in args.cases:
        for method in args.methods:
            run_case(args, pool, case, method)
    print((args.out / "summary.md").read_text(), end="")


def run_case(args, pool, case: str, method: str) -> None:
    """One case with one optimiser: its runs, its rows (<folder>/study_rows.md) and summary.md."""
    scene = Scene.load(case)
    mesh = {name: value for name, value in (("level", args.level), ("degree", args.degree)) if value is not None}
    scene = scene.replace("mesh", **mesh).replace("optimizer", starts=STARTS.get(case, 1), method=method)
    folder = args.out / case_folder(case, method)
    label = case if method == "paper" else f"{case} ({method})"
    started = time.perf_counter()
    fish = load_fish(scene)
    if scene.cooptimization.enabled:
        points = pareto_sweep(scene, folder, fish=fish, pool=pool, resume=args.resume)
        summaries = [(f"{label} w1={point['w1']:g}", folder / weight_folder(point['w1']) / "summary.json")
                     for point in points]
    else:
        if not (args.resume and completed_summary(folder, scene)):
            run_optimization(scene, folder, fish=fish, pool=pool,
                             resume=args.resume and holds_file(folder, checkpoint_pattern(scene)))
        summaries = [(label, folder / "summary.json")]
    case_time = time.perf_counter() - started
    rows = [_row(name, scene, fish, json.loads(path.read_text()), case_time if k == 0 else None)
            for k, (name, path) in enumerate(summaries)]
    write_text_atomic(folder / ROWS, "\n".join(rows) + "\n")
    write_text_atomic(args.out / "summary.md", "\n".join(summary_lines(args.out)) + "\n")


def summary_lines(out: Path) -> list[str]:
    """summary.md: the header and the rows of every case folder in ``out`` (SO cases, then CO)."""
    folders = sorted((path.parent for path in out.glob(f"*/{ROWS}")), key=lambda path: (path.name.startswith("co"), path.name))
    lines = ["# Optimisation studies", "", *HEADER]
    lines += [row for folder in folders for row in (folder / ROWS).read_text().splitlines()]
    lines += ["", "Optimisation and FOM check (start and optimal design) are those of the reported run (of the "
              "best start of a multi-start case); the case wall time is the whole case (mesh, every start or "
              "weight). PROMs and FOM distances taken from the cache count as reused; `make bench` times every "
              "build from scratch."]
    if any("stopped" in line for line in lines):
        lines += ["", "FOM runs marked 'stopped' did not converge: see each case's summary.json (fom_check.error)."]
    versions = software_versions()
    return lines + ["", f"aquarom_fenics {versions['aquarom_fenics']}, dolfinx {versions['dolfinx']}."]


def _centimetres(value):
    return "stopped" if value is None else f"{100 * value:.3f}"


def _row(case, scene, fish, summary, case_time: float | None) -> str:
    """One table row of a case's summary.json; ``case_time`` [s] on the first row of a case only."""
    check = summary["fom_check"]
    optimum = ", ".join(f"{n} {v:+.3f}" for n, v in summary["optimum"].items())
    ratio = "n/a" if check["ratio"] is None else f"{check['ratio']:.2f}"
    timings = summary["timings"]
    return (f"| {case} | P{scene.mesh.degree} level {scene.mesh.level} | {len(summary['optimum'])} | "
            f"{fish.mesh.cells.shape[0]} | {summary['prom_size']} | "
            f"{summary['prom_builds']} ({summary.get('prom_builds_reused_from_cache', 0)}) | "
            f"{timings['total']:.1f} | {timings['fom_check']:.1f} | "
            f"{'' if case_time is None else f'{case_time:.1f}'} | {summary['time_per_build']:.2f} | {optimum} | "
            f"{', '.join(summary['bounds_active']) or 'none'} | "
            f"{'optimal' if summary['converged'] else summary['stop_reason']} ({summary['iterations']}) | "
            f"{_starts(summary)} | {_centimetres(check['start_distance'])} | {_centimetres(check['optimal_distance'])} | {ratio} |")


def _starts(summary) -> str:
    """'1', or 'N (best k; m distinct optima)' of a multi-start run."""
    multistart = summary.get("multistart")
    if multistart is None:
        return "1"
    return (f"{multistart['starts']} (best {multistart['best_start']}; "
            f"{len(multistart['distinct_optima'])} distinct optima)")


if __name__ == "__main__":
    sys.exit(main())
