"""`make study`: SO1–SO3 and the CO Pareto sweep (on each scene's mesh level), collected in one table.

Writes every run under results/studies/ and results/studies/summary.md (case, parameters,
cells, PROM dofs, builds, wall time, time per build, optimum, bounds active there, how the
optimiser stopped, FOM distance nominal/optimal, ratio). SO2 runs from 3 starts (its source
reports two local optima); its row is the best FOM-verified one.
"""
import argparse
import json
from pathlib import Path

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.outputs import software_versions
from aquarom_fenics.io.persistence import write_text_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.study import pareto_sweep, run_optimization

REPOSITORY = Path(__file__).resolve().parents[1]

STARTS = {"so2": 3}      # [optimizer] starts per case (1 when not listed)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--level", type=int, help="mesh level for every case (default: each scene's own)")
    parser.add_argument("--cases", nargs="+", default=["so1", "so2", "so3", "co"])
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "studies")
    args = parser.parse_args()
    lines = ["# Optimisation studies", "",
             "| case | parameters | cells | PROM dofs | builds (reused from the cache) | wall time [s] | time per build [s] | optimum | "
             "active | stop (iterations) | starts | FOM nominal [cm] | FOM optimal [cm] | ratio |", "|---" * 14 + "|"]
    for case in args.cases:
        scene = Scene.load(case)
        if args.level is not None:
            scene = scene.replace("mesh", level=args.level)
        scene = scene.replace("optimizer", starts=STARTS.get(case, 1))
        fish = load_fish(scene)
        if scene.cooptimization.enabled:
            points = pareto_sweep(scene, args.out / case, fish=fish)
            for point in points:
                summary = json.loads((args.out / case / f"w1_{point['w1']:g}" / "summary.json").read_text())
                lines.append(_row(f"{case} w1={point['w1']:g}", scene, fish, summary))
            continue
        run_optimization(scene, args.out / case, fish=fish)
        lines.append(_row(case, scene, fish, json.loads((args.out / case / "summary.json").read_text())))
    lines += ["", "Wall time and time per build include PROMs taken from the cache (a rerun reuses them); "
              "`make bench` times every build from scratch."]
    failures = [line for line in lines if "stopped" in line]
    if failures:
        lines += ["", "FOM runs marked 'stopped' did not converge: see each case's summary.json (fom_check.error)."]
    versions = software_versions()
    lines += ["", f"aquarom_fenics {versions['aquarom_fenics']}, dolfinx {versions['dolfinx']}."]
    write_text_atomic(args.out / "summary.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


def _centimetres(value):
    return "stopped" if value is None else f"{100 * value:.3f}"


def _row(case, scene, fish, summary):
    check = summary["fom_check"]
    optimum = ", ".join(f"{n} {v:+.3f}" for n, v in summary["optimum"].items())
    ratio = "n/a" if check["ratio"] is None else f"{check['ratio']:.2f}"
    return (f"| {case} | {len(summary['optimum'])} | {fish.mesh.cells.shape[0]} | {summary['prom_size']} | "
            f"{summary['prom_builds']} ({summary.get('prom_builds_reused_from_cache', 0)}) | "
            f"{summary['timings']['total']:.1f} | {summary['time_per_build']:.2f} | {optimum} | "
            f"{', '.join(summary['bounds_active']) or 'none'} | "
            f"{'optimal' if summary['converged'] else summary['stop_reason']} ({summary['iterations']}) | "
            f"{_starts(summary)} | {_centimetres(check['nominal_distance'])} | {_centimetres(check['optimal_distance'])} | {ratio} |")


def _starts(summary) -> str:
    """'1', or 'N (best k; m distinct optima)' of a multi-start run."""
    multistart = summary.get("multistart")
    if multistart is None:
        return "1"
    return (f"{multistart['starts']} (best {multistart['best_start']}; "
            f"{len(multistart['distinct_optima'])} distinct optima)")


if __name__ == "__main__":
    main()
