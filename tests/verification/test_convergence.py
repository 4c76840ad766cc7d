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
    assert result["series_cells"] == CELLS and result["checked_against_cells"] == []


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


def test_richardson_uses_the_three_finest_cases_and_has_no_reference_without_an_order():
    h = np.asarray([800] + CELLS, dtype=float) ** (-1 / 3)
    values = 2.0 + 5.0 * h ** 1.5
    values[0] += 1.0       # the coarsest case is off the power law: it must not matter
    assert richardson([800] + CELLS, values, formal_order=2.0)["value"] == pytest.approx(2.0, rel=1e-10)
    oscillating = richardson(CELLS, [1.0, 1.2, 1.1], formal_order=2.0)
    assert oscillating["value"] is None and oscillating["estimated_error"] is None
    assert oscillating["observed_order"] is None and "no three consecutive cases show an order" in oscillating["reason"]


FIVE = [1300, 4300, 8100, 16000, 25000]


def test_a_finest_triple_without_an_order_falls_back_to_one_its_finer_case_confirms():
    """Levels 2-4 converge at third order; level 5 adds a little noise, so the finest triple shows no
    order: the reference comes from levels 2-4, and level 5 must lie inside its error bar."""
    h = np.asarray(FIVE, dtype=float) ** (-1 / 3)
    values = 0.047 - 2.0 * h ** 3
    values[4] = values[3] + 0.8 * (values[3] - values[2])     # too large a last step for any order
    result = richardson(FIVE, values, formal_order=3.0)
    assert result["series_cells"] == FIVE[1:4] and result["checked_against_cells"] == [25000]
    assert result["observed_order"] == pytest.approx(3.0, rel=1e-6) and result["order_used"] == pytest.approx(3.0)
    assert result["value"] == pytest.approx(0.047, rel=1e-9)
    assert abs(values[4] - result["value"]) <= result["estimated_error"]
    values[4] = result["value"] + 2 * result["estimated_error"]          # a finer case outside the bar
    missed = richardson(FIVE, values, formal_order=3.0)
    assert missed["value"] is None and "misses the finer cases [25000]" in missed["reason"]


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
