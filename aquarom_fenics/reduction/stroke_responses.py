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


def stroke_response(fom: FullOrderModel, amplitude: float, steps: int = 4) -> np.ndarray:
    """u_s(a), the static response to the activations a P_1 (the first activation pattern; the pair's
    (1, -1)): Newton from rest or, when that fails, by continuation in ``steps`` equal steps of a, each
    Newton from the previous solution."""
    activations = amplitude * fom.muscle.law.patterns()[0]
    try:
        return fom.static_response(*activations)
    except SolverError:
        log.info("basis: the static response at a = %g needs continuation (%d steps)", amplitude, steps)
    u = None
    for step in range(1, steps + 1):
        u = fom.static_response(*(step / steps * activations), start=u)
    return u
