"""The stroke responses' continuation in the amplitude: increments halved where Newton fails, doubled where it
converges, at most MAX_INCREMENTS static solves (reduction/stroke_responses.py)."""
import pytest

from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.reduction.stroke_responses import MAX_INCREMENTS, continued_response, stroke_response


def reaching(largest_jump):
    """A solve that converges only from a start within ``largest_jump`` of the target fraction; it records its
    calls (target, start) and returns the fraction it solved for."""
    calls = []

    def solve(fraction, start):
        calls.append((fraction, start))
        if fraction - (start or 0.0) > largest_jump + 1e-15:
            raise SolverError("did not converge")
        return fraction

    return solve, calls


def test_a_failed_increment_is_halved_and_a_converged_one_doubled():
    solve, calls = reaching(0.1)
    assert continued_response(solve, 0.25, MAX_INCREMENTS) == 1.0
    accepted = [fraction for fraction, start in calls if fraction - (start or 0.0) <= 0.1 + 1e-15]
    assert accepted[:2] == [0.0625, 0.125] and accepted[-1] == 1.0
    assert all(later > earlier for earlier, later in zip(accepted, accepted[1:]))
    assert calls[:3] == [(0.25, None), (0.125, None), (0.0625, None)]
    assert len(calls) <= MAX_INCREMENTS


def test_a_continuation_that_cannot_reach_the_amplitude_stops_in_one_line():
    solve, calls = reaching(0.001)          # below the smallest increment 1/256
    with pytest.raises(SolverError, match="stopped at 0 of it"):
        continued_response(solve, 0.25, MAX_INCREMENTS)
    solve, calls = reaching(0.01)           # reachable, but in more solves than allowed
    with pytest.raises(SolverError, match=r"in 12 static solves"):
        continued_response(solve, 0.25, 12)
    assert len(calls) == 12


def test_the_stroke_response_through_refused_increments_is_the_static_response(quadratic_scene, quadratic_fish):
    """Newton allowed only small jumps in the activation (here: 0.06 of 0.4) reaches the response from rest."""
    fom = FullOrderModel(quadratic_scene, quadratic_fish)
    direct = fom.static_response(0.4, -0.4)
    static_response = fom.static_response
    jumps = []

    def short_jumps(left, right, start=None):
        reached = 0.0 if start is None else jumps[-1]
        if abs(left - reached) > 0.06 + 1e-12:
            raise SolverError("did not converge")
        jumps.append(left)
        return static_response(left, right, start=start)

    fom.static_response = short_jumps
    continued = stroke_response(fom, 0.4)
    assert fom.norm(continued - direct) < 1e-8 * fom.norm(direct)
    assert jumps[-1] == 0.4 and len(jumps) >= 7
