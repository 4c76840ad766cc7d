"""Richardson reference and the choice of the default mesh (mesh-convergence study)."""
import numpy as np
import pytest

from aquarom_fenics.verification.convergence import MeshCase, mesh_convergence, richardson

CELLS = [1232, 4176, 7944]


def test_richardson_recovers_limit_and_order_of_an_exact_power_law():
    h = np.asarray(CELLS, dtype=float) ** (-1 / 3)
    values = 0.045 - 0.8 * h ** 2.0
    result = richardson(CELLS, values)
    assert result["value"] == pytest.approx(0.045, rel=1e-10)
    assert result["observed_order"] == pytest.approx(2.0, rel=1e-8)
    assert result["estimated_error"] == pytest.approx(0.8 * h[-1] ** 2, rel=1e-8)


def test_richardson_uses_the_three_finest_cases_and_falls_back_on_oscillation():
    h = np.asarray([800] + CELLS, dtype=float) ** (-1 / 3)
    values = 2.0 + 5.0 * h ** 1.5
    values[0] += 1.0       # the coarsest case is off the power law: it must not matter
    assert richardson([800] + CELLS, values)["value"] == pytest.approx(2.0, rel=1e-10)
    oscillating = richardson(CELLS, [1.0, 1.2, 1.1])
    assert oscillating["observed_order"] is None
    assert oscillating["value"] == 1.1 and oscillating["estimated_error"] == pytest.approx(0.1)


def case(degree, level, cells, distance, wall_time):
    return MeshCase(degree, level, cells, 3 * cells, distance, 0.02, 5.0, 0.025, 1e-3, wall_time)


def test_default_is_the_cheapest_case_within_three_percent_of_the_reference():
    h = np.asarray(CELLS, dtype=float) ** (-1 / 3)
    quadratic = 0.045 - 0.3 * h ** 3
    cases = [case(2, level, cells, d, t)
             for level, cells, d, t in zip((1, 2, 3), CELLS, quadratic, (10, 60, 200))]
    cases += [case(1, 3, 7944, 0.034, 9.0), case(1, 5, 25000, 0.0441, 40.0)]
    result = mesh_convergence(cases)
    assert result["reference"]["distance"]["value"] == pytest.approx(0.045, rel=1e-9)
    assert result["reference"]["distance"]["degree"] == 2
    errors = {(row["degree"], row["level"]): row["relative_error_distance"] for row in result["rows"]}
    assert errors[(1, 3)] == pytest.approx(0.034 / 0.045 - 1)
    within = [key for key, error in errors.items() if abs(error) <= 0.03]
    assert (1, 5) in within
    cheapest = min((row for row in result["rows"] if (row["degree"], row["level"]) in within),
                   key=lambda row: row["wall_time"])
    assert (result["default"]["degree"], result["default"]["level"]) == (cheapest["degree"], cheapest["level"])
