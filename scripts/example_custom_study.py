"""A scripted study with the Python API: optimise SO1 for three muscle stiffnesses, tabulate the optima.

    .venv/bin/python scripts/example_custom_study.py --level 1
"""
import argparse
from pathlib import Path

from aquarom_fenics.api import Scene, load_fish, optimize

STIFFNESSES = (3e4, 6e4, 9e4)     # Pa


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--level", type=int, default=1, help="mesh level (1: coarsest)")
    parser.add_argument("--out", type=Path, default=Path("results/example_custom_study"))
    args = parser.parse_args()
    base = Scene.load("so1").replace("mesh", level=args.level)
    fish = load_fish(base)
    rows = []
    for stiffness in STIFFNESSES:
        scene = base.replace("actuation", stiffness=stiffness)
        result, check = optimize(scene, args.out / f"k{stiffness:g}", fish=fish)
        rows.append((stiffness, result.optimum_dict, check, result.prom_builds))
    names = list(rows[0][1])
    print("| k [Pa] | " + " | ".join(names) + " | FOM start [cm] | FOM optimal [cm] | ratio | PROM builds |")
    print("|---" * (len(names) + 5) + "|")
    for stiffness, optimum, check, builds in rows:
        start, optimal = (f"{100 * d:.3f}" if d is not None else "stopped"
                            for d in (check.start_distance, check.optimal_distance))
        ratio = f"{check.ratio:.2f}" if check.ratio is not None else "n/a"
        print(f"| {stiffness:g} | " + " | ".join(f"{optimum[n]:+.3f}" for n in names)
              + f" | {start} | {optimal} | {ratio} | {builds} |")


if __name__ == "__main__":
    main()
