"""The FOM's static responses to a large stroke (the stroke vectors of :mod:`aquarom_fenics.reduction.basis`,
docs/theory/basis.md "Large strokes"): u_s(a), f_int(u) = f_act(u) at the activations a P_1, and its
forward difference in a shape parameter."""
from __future__ import annotations

import logging

import numpy as np

from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.io.scene_muscles import stroke_amplitude

log = logging.getLogger("aquarom")


SENSITIVITY_STEP = 0.01
"""Forward-difference step of the stroke sensitivities, as a fraction of the parameter's range."""


def stroke_sensitivity(fom: FullOrderModel, k: int, plus: np.ndarray, minus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """∂u_s(±A_s)/∂ξ_k ≈ (u_s(ξ + h e_k) - u_s(ξ)) / h, h = SENSITIVITY_STEP × the range of ξ_k, towards the
    middle of its bounds; each moved response by Newton from the response at ξ (same nominal mesh and dofs)."""
    shape = fom.scene.shapes[k]
    step = SENSITIVITY_STEP * (shape.upper - shape.lower) * (1.0 if fom.xi[k] <= 0.5 * (shape.lower + shape.upper) else -1.0)
    moved_xi = fom.xi.copy()
    moved_xi[k] += step
    moved = FullOrderModel(fom.scene, fom.fish, moved_xi, comm=fom.comm)
    activations = stroke_amplitude(fom.scene) * fom.muscle.law.patterns()[0]
    try:
        responses = [fom.owned_values(moved.nodal_displacement(moved.static_response(*(sign * activations), start=start)))
                     for sign, start in ((1.0, plus), (-1.0, minus))]
    except SolverError as error:
        raise SolverError(f"[reduction] stroke_sensitivities: the stroke response at {fom.fish.shape_names[k]} "
                          f"moved by {step:g}: {error}") from None
    finally:
        moved.destroy()
    return (responses[0] - plus) / step, (responses[1] - minus) / step


CONTINUATION_STEPS = 4
"""The first increment of the amplitude continuation: 1/4 of a."""
MAX_INCREMENTS = 32
"""Most static solves of one continuation (accepted and refused increments together)."""
SMALLEST_INCREMENT = 1.0 / 256
"""The smallest increment of the continuation, as a fraction of a."""


def stroke_response(fom: FullOrderModel, amplitude: float, steps: int = CONTINUATION_STEPS,
                    max_increments: int = MAX_INCREMENTS) -> np.ndarray:
    """u_s(a), the static response to the activations a P_1 (the first activation pattern; the pair's
    (1, -1)): Newton from rest or, when that fails, by continuation in the amplitude (:func:`continued_response`)."""
    activations = amplitude * fom.muscle.law.patterns()[0]
    try:
        return fom.static_response(*activations)
    except SolverError:
        log.info("basis: the static response at a = %g needs continuation", amplitude)
    return continued_response(lambda fraction, start: fom.static_response(*(fraction * activations), start=start),
                              1.0 / steps, max_increments)


def continued_response(solve, first: float, max_increments: int, smallest: float = SMALLEST_INCREMENT):
    """The solution at load fraction 1 by load stepping: ``solve(fraction, start)`` (Newton from ``start``, None:
    rest; SolverError when it fails) at fractions λ_0 = 0 < λ_1 < … < 1, each from the previous solution. The
    increment Δλ starts at ``first``; a failed solve halves it (down to ``smallest``), a solve that converged
    doubles it for the next (up to ``first``). SolverError after ``max_increments`` solves, or when Δλ would fall
    below ``smallest``, naming the fraction reached."""
    fraction, increment, solution = 0.0, first, None
    for _ in range(max_increments):
        target = min(1.0, fraction + increment)
        try:
            solution = solve(target, solution)
        except SolverError:
            increment *= 0.5
            if increment < smallest * (1 - 1e-12):
                raise SolverError(f"continuation in the amplitude stopped at {fraction:.4g} of it: an increment "
                                  f"of {2 * increment:.3g} did not converge") from None
            continue
        fraction = target
        if fraction >= 1.0:
            return solution
        increment = min(2.0 * increment, first)
    raise SolverError(f"continuation in the amplitude reached {fraction:.4g} of it in {max_increments} static "
                      "solves")
