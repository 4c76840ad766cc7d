"""The one error function of a model against a reference (reduced runs, validation rows, validity radius)."""
import pytest

from aquarom_fenics.verification.compare import deviation


def test_deviation_is_signed_and_relative_to_the_reference_magnitude():
    assert deviation(1.1, 1.0) == (pytest.approx(0.1), pytest.approx(0.1))
    assert deviation(-0.9, -1.0) == (pytest.approx(0.1), pytest.approx(0.1))
    assert deviation(0.5, -1.0) == (pytest.approx(1.5), pytest.approx(1.5))


def test_deviation_from_zero_has_no_relative_error():
    assert deviation(0.25, 0.0) == (0.25, None)
