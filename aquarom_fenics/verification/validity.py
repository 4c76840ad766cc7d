"""Accuracy of a PROM away from its building point (SPEC §8): the validity radius along each shape.

Along each shape direction, at the fractions 1/8, 1/4 and 1/2 of its bound and both signs, the PROM
built at ξ = 0 (Taylor order 1 and 2) against the FOM on the moved mesh. The radius of a parameter
is the largest tested |ξ| up to which both signs of every smaller fraction stay within the
tolerance in distance (order 1).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.verification.compare import deviation

FRACTIONS = (0.125, 0.25, 0.5)
"""Tested |ξ| as fractions of the bound on each side."""

TOLERANCE = 0.05
"""Largest relative distance error of the order-1 PROM inside the radius."""

ORDERS = (1, 2)


def validity_study(base: Scene, fish=None, on_row: Callable[[dict], None] | None = None) -> dict:
    """FOM and PROM (orders 1 and 2, built at ξ = 0 with room for the largest fraction) along every shape.

    Rows: parameter, value, fraction, ``fom_distance`` [m] or ``fom_error`` (the FOM refused the
    moved mesh), and per order ``order<k>_distance`` [m] and ``order<k>_error`` (relative, None when
    either run stopped). ``on_row`` is called with each row as it is computed.
    """
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
    from aquarom_fenics.dynamics.simulate import simulate_fom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    fish = fish or load_fish(base)
    wide = base.replace("reduction", validity_fraction=10.0, validity_change=0.0)     # no radius: the study measures it
    proms = {order: build_prom(wide.replace("reduction", taylor_order=order), fish=fish) for order in ORDERS}
    nominal = simulate_fom(base, fish=fish, progress=False)
    rows = []
    for index, shape in enumerate(base.shapes):
        for fraction in FRACTIONS:
            for bound in (shape.lower, shape.upper):
                xi = np.zeros(len(base.shapes))
                xi[index] = fraction * bound
                row = {"parameter": shape.name, "value": float(xi[index]), "fraction": fraction}
                try:
                    fom = simulate_fom(base, xi, fish=fish, moved_mesh=True, progress=False)
                except InputError as refused:
                    row["fom_error"] = str(refused)
                else:
                    row["fom_distance"] = fom.distance
                    for order, prom in proms.items():
                        reduced = simulate_reduced(prom, wide, xi)
                        row[f"order{order}_distance"] = reduced.distance
                        row[f"order{order}_error"] = (deviation(reduced.distance, fom.distance)[1]
                                                      if fom.completed and reduced.completed else None)
                rows.append(row)
                if on_row:
                    on_row(row)
    return {"scene": base.name, "level": base.mesh.level, "cells": nominal.n_cells,
            "nominal_fom_distance": nominal.distance, "rows": rows,
            "validity_radius_order1": validity_radius(rows, base.shape_names), "tolerance": TOLERANCE}


def validity_radius(rows: list[dict], names: list[str], tolerance: float = TOLERANCE) -> dict[str, float]:
    """Per parameter, the largest tested |ξ| such that both signs of it and of every smaller fraction keep
    |order-1 error| ≤ tolerance (0 when the smallest fraction fails or the FOM refused it)."""
    radius = {}
    for name in names:
        passed = 0.0
        for fraction in FRACTIONS:
            pair = [row for row in rows if row["parameter"] == name and row["fraction"] == fraction]
            errors = [row.get("order1_error") for row in pair]
            if not pair or any(error is None or abs(error) > tolerance for error in errors):
                break
            passed = max(abs(row["value"]) for row in pair)
        radius[name] = passed
    return radius


def validity_table(study: dict) -> list[str]:
    """Markdown lines: one row per tested ξ (distances in cm, errors in %) and the radius per parameter."""
    lines = [f"# PROM validity along the {study['scene']} directions ({study['cells']} cells)", "",
             "| parameter | ξ | FOM distance [cm] | PROM order 1 | error | PROM order 2 | error |",
             "|---|---|---|---|---|---|---|"]
    for row in study["rows"]:
        if "fom_error" in row:
            lines.append(f"| {row['parameter']} | {row['value']:+.4g} | refused: {row['fom_error']} | | | | |")
            continue
        cells = [f"{100 * row['fom_distance']:.3f}"]
        for order in ORDERS:
            error = row[f"order{order}_error"]
            cells += [f"{100 * row[f'order{order}_distance']:.3f}", "—" if error is None else f"{100 * error:+.2f}%"]
        lines.append(f"| {row['parameter']} | {row['value']:+.4g} | " + " | ".join(cells) + " |")
    tolerance = 100 * study["tolerance"]
    return lines + ["", f"Validity radius (order 1, within {tolerance:g}% for both signs): "
                    + ", ".join(f"{name} {value:g}" for name, value in study["validity_radius_order1"].items())]
