"""The PROM validity radius from the rows of a validity study (no model run) and its Markdown table."""
from aquarom_fenics.verification.validity import FRACTIONS, TOLERANCE, validity_radius, validity_table


def rows_for(name, bound, errors):
    """Rows of one parameter: ``errors[fraction index]`` = (error at -bound side, error at +bound side)."""
    rows = []
    for fraction, pair in zip(FRACTIONS, errors):
        for sign, error in zip((-1, 1), pair):
            rows.append({"parameter": name, "value": sign * fraction * bound, "fraction": fraction,
                         "fom_distance": 0.01, "order1_distance": 0.01 * (1 + (error or 0)), "order1_error": error,
                         "order2_distance": 0.01, "order2_error": 0.0})
    return rows


def test_radius_is_the_largest_fraction_before_the_first_failure():
    inside, outside = 0.5 * TOLERANCE, 2 * TOLERANCE
    rows = (rows_for("y_thin", 0.2, [(inside, -inside), (inside, inside), (outside, inside)])
            + rows_for("z_tail", 0.4, [(inside, inside)] * 3)
            + rows_for("x_fin", 0.1, [(inside, None), (inside, inside), (inside, inside)]))
    radius = validity_radius(rows, ["y_thin", "z_tail", "x_fin"])
    assert radius == {"y_thin": FRACTIONS[1] * 0.2, "z_tail": FRACTIONS[2] * 0.4, "x_fin": 0.0}


def test_refused_designs_end_the_radius_and_appear_in_the_table():
    rows = rows_for("y_thin", 0.2, [(0.01, 0.01)])
    rows.append({"parameter": "y_thin", "value": -0.05, "fraction": FRACTIONS[1], "fom_error": "mesh inverted"})
    study = {"scene": "so1", "cells": 1232, "rows": rows, "tolerance": TOLERANCE,
             "validity_radius_order1": validity_radius(rows, ["y_thin"])}
    assert study["validity_radius_order1"] == {"y_thin": FRACTIONS[0] * 0.2}
    text = "\n".join(validity_table(study))
    assert "| y_thin | -0.05 | refused: mesh inverted | | | | |" in text
    assert "| y_thin | +0.025 | 1.000 | 1.010 | +1.00% | 1.000 | +0.00% |" in text
    assert text.endswith("within 5% for both signs): y_thin 0.025")
