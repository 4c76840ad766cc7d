"""Accuracy of a PROM away from its building point (SPEC §8): the validity radius.

Along each shape direction of a scene (default SO1), at 1/8, 1/4 and 1/2 of its bound and both
signs, the PROM built at ξ = 0 (Taylor order 1 and 2) against the FOM on the moved mesh.
Writes results/validation/prom_validity.json and a Markdown table; the radius of a parameter is
the largest tested |ξ| at which both signs stay within 5% in distance.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))

from aquarom_fenics.errors import InputError  # noqa: E402
from aquarom_fenics.geometry.fish import load_fish  # noqa: E402
from aquarom_fenics.io.outputs import software_versions  # noqa: E402
from aquarom_fenics.io.persistence import write_json_atomic  # noqa: E402
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced  # noqa: E402
from aquarom_fenics.reduction.reductor import build_prom  # noqa: E402
from aquarom_fenics.io.scene import Scene  # noqa: E402
from aquarom_fenics.dynamics.simulate import simulate_fom  # noqa: E402

FRACTIONS = (0.125, 0.25, 0.5)
TOLERANCE = 0.05


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="so1")
    parser.add_argument("--level", type=int, default=3)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation")
    args = parser.parse_args()
    base = Scene.load(args.scene).replace("mesh", level=args.level)
    fish = load_fish(base)
    wide = base.replace("reduction", validity_fraction=10.0)
    proms = {order: build_prom(wide.replace("reduction", taylor_order=order), fish=fish) for order in (1, 2)}
    nominal = simulate_fom(base, fish=fish, progress=False)
    rows = []
    for index, shape in enumerate(base.shapes):
        for fraction in FRACTIONS:
            for sign in (-1, 1):
                bound = shape.upper if sign > 0 else shape.lower
                value = fraction * bound
                xi = np.zeros(len(base.shapes))
                xi[index] = value
                row = {"parameter": shape.name, "value": value, "fraction": fraction}
                try:
                    fom = simulate_fom(base, xi, fish=fish, moved_mesh=True, progress=False)
                except InputError as refused:
                    row["fom_error"] = str(refused)
                    rows.append(row)
                    continue
                row["fom_distance"] = fom.distance
                for order, prom in proms.items():
                    reduced = simulate_reduced(prom, wide, xi)
                    row[f"order{order}_distance"] = reduced.distance
                    row[f"order{order}_error"] = (reduced.distance - fom.distance) / fom.distance if (
                        fom.completed and reduced.completed) else None
                rows.append(row)
                print(row, flush=True)
    radius = {}
    for shape in base.shapes:
        passed = 0.0
        for fraction in FRACTIONS:
            pair = [r for r in rows if r["parameter"] == shape.name and r["fraction"] == fraction]
            errors = [r.get("order1_error") for r in pair]
            if any(e is None or abs(e) > TOLERANCE for e in errors):
                break
            passed = max(abs(r["value"]) for r in pair)
        radius[shape.name] = passed
    write_json_atomic(args.out / "prom_validity.json", {
        "scene": base.name, "level": args.level, "cells": nominal.n_cells, "nominal_fom_distance": nominal.distance,
        "rows": rows, "validity_radius_order1": radius, "tolerance": TOLERANCE, "versions": software_versions()})
    lines = [f"# PROM validity along the {base.name} directions ({nominal.n_cells} cells)", "",
             "| parameter | ξ | FOM distance [cm] | PROM order 1 | error | PROM order 2 | error |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        if "fom_error" in r:
            lines.append(f"| {r['parameter']} | {r['value']:+.4g} | refused: {r['fom_error']} | | | | |")
            continue
        lines.append(f"| {r['parameter']} | {r['value']:+.4g} | {100 * r['fom_distance']:.3f} | "
                     f"{100 * r['order1_distance']:.3f} | {100 * r['order1_error']:+.2f}% | "
                     f"{100 * r['order2_distance']:.3f} | {100 * r['order2_error']:+.2f}% |")
    lines += ["", "Validity radius (order 1, within 5% for both signs): "
              + ", ".join(f"{name} {value:g}" for name, value in radius.items())]
    (args.out / "prom_validity.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
