"""Richardson reference and the choice of the default mesh (mesh-convergence study)."""
import numpy as np
import pytest

from aquarom_fenics.verification.convergence import MeshCase, mesh_convergence, richardson

CELLS = [1232, 4176, 7944]


def test_richardson_recovers_limit_and_order_of_an_exact_power_law():
    h = np.asarray(CELLS, dtype=float) ** (-1 / 3)
    values = 0.045 - 0.8 * h ** 2.0
    result = richardson(CELLS, values, formal_order=3.0)
    assert result["value"] == pytest.approx(0.045, rel=1e-10)
    assert result["observed_order"] == pytest.approx(2.0, rel=1e-8)
    assert result["order_used"] == pytest.approx(2.0, rel=1e-8)
    assert result["estimated_error"] == pytest.approx(1.25 * 0.8 * h[-1] ** 2, rel=1e-8)


def test_an_observed_order_above_the_formal_one_is_not_trusted():
    """A series that looks sixth order on an element of formal order 3: the extrapolation uses
    order 3, which moves the reference less far and widens the error bar."""
    h = np.asarray(CELLS, dtype=float) ** (-1 / 3)
    values = 0.045 - 0.8 * h ** 6.0
    result = richardson(CELLS, values, formal_order=3.0)
    assert result["observed_order"] == pytest.approx(6.0, rel=1e-6)
    assert result["order_used"] == 3.0 and result["safety_factor"] == 1.25
    correction = (values[2] - values[1]) / ((h[1] / h[2]) ** 3 - 1.0)
    assert result["value"] == pytest.approx(values[2] + correction, rel=1e-12)
    assert result["estimated_error"] == pytest.approx(1.25 * abs(correction), rel=1e-12)
    assert abs(result["value"] - 0.045) < result["estimated_error"]


def test_richardson_uses_the_three_finest_cases_and_falls_back_on_oscillation():
    h = np.asarray([800] + CELLS, dtype=float) ** (-1 / 3)
    values = 2.0 + 5.0 * h ** 1.5
    values[0] += 1.0       # the coarsest case is off the power law: it must not matter
    assert richardson([800] + CELLS, values, formal_order=2.0)["value"] == pytest.approx(2.0, rel=1e-10)
    oscillating = richardson(CELLS, [1.0, 1.2, 1.1], formal_order=2.0)
    h = np.asarray(CELLS, dtype=float) ** (-1 / 3)
    correction = -0.1 / ((h[1] / h[2]) ** 2 - 1.0)
    assert oscillating["observed_order"] is None and oscillating["order_used"] == 2.0
    assert oscillating["value"] == pytest.approx(1.1 + correction, rel=1e-12)
    assert oscillating["estimated_error"] == pytest.approx(3.0 * abs(correction), rel=1e-12)


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
