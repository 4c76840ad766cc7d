"""Taylor test of a shape field's gradient against its value (SPEC §4: the forms use ∇U_k, the
design moves the nodes by U_k, so the two must agree).

At every quadrature point X_i of the forms (nominal, relative to the box) and a fixed random unit
direction d_i, the first-order remainder

    r_i(h) = ‖U(X_i + h d_i) - U(X_i) - h ∇U(X_i) d_i‖

falls like h² where U is smooth and ∇U is its gradient, like h where ∇U is wrong. Steps
h = h_0, h_0/2, h_0/4, h_0/8 with h_0 = STEP_FRACTION × L; the local order at a point is
log2(r_i(h_0/4) / r_i(h_0/8)). Points where r_i(h_0), or r_i(h_0/8), is at round-off (U linear
there, or past a kink h_0 away) count as exact. The field passes when at least PASS_FRACTION of the other points have an order ≥
MIN_ORDER: the catalogue's fields are piecewise smooth, and a point closer than h to a kink (a
region's edge) or to the body's faces sees a first-order remainder until h is below that distance.
"""
from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from aquarom_fenics.geometry.shapes import shape_displacement, shape_gradients
from aquarom_fenics.verification.check import CheckResult

STEP_FRACTION = 1e-4             # h_0 / L
HALVINGS = 3                     # h_0 … h_0 / 2³
MIN_ORDER = 1.5
PASS_FRACTION = 0.99
EXACT = 1e-8                     # r_i(h_0) below this × the largest first-order term h_0 ‖∇U d‖: exact


def taylor_remainders(name: str, points: np.ndarray, box, steps: np.ndarray, seed: int = 5) -> tuple[np.ndarray, float]:
    """(len(steps), n) remainders r_i(h) of the field ``name`` at (n, 3) relative points, and the
    largest first-order term ‖∇U d‖ per unit step."""
    directions = np.random.default_rng(seed).standard_normal(points.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    value = shape_displacement(name, points, box)
    slope = np.einsum("nij,nj->ni", shape_gradients([name], points, box)[0], directions)
    return np.stack([np.linalg.norm(shape_displacement(name, points + h * directions, box) - value - h * slope, axis=1)
                     for h in steps]), float(np.max(np.linalg.norm(slope, axis=1), initial=0.0))


def check_shape_gradient(name: str, points: np.ndarray, box) -> CheckResult:
    """The Taylor test of the field ``name`` at (n, 3) relative points of the body in ``box``."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    steps = STEP_FRACTION * box.length * 0.5 ** np.arange(HALVINGS + 1)
    remainders, slope = taylor_remainders(name, points, box, steps)
    label = f"0 ∇U {name}"
    tolerance = f"≥ {100 * PASS_FRACTION:g} % ≥ {MIN_ORDER:g}"
    steps_note = f"h = {steps[0]:.2g}…{steps[-1]:.2g} m"
    smooth = remainders[0] > EXACT * steps[0] * slope
    if not smooth.any():
        return CheckResult(label, f"exact at {len(points)}", tolerance, True,
                           note=f"{steps_note}; remainder at round-off everywhere (linear field)")
    settled = remainders[-1, smooth] <= EXACT * steps[-1] * slope      # at round-off by the last step: exact
    with np.errstate(divide="ignore", invalid="ignore"):
        orders = np.where(settled, np.inf, np.log2(remainders[-2, smooth] / remainders[-1, smooth]))
    share = (orders >= MIN_ORDER).mean()
    measured = f"{100 * share:.2f} % of {smooth.sum()}"
    order = f"{np.median(orders[np.isfinite(orders)]):.2f}" if np.isfinite(orders).any() else "exact"
    if share >= PASS_FRACTION:
        return CheckResult(label, measured, tolerance, True, order=order,
                           note=f"{steps_note}; local order of the remainder, median {order}")
    worst = points[smooth][int(np.argmin(np.where(np.isfinite(orders), orders, -np.inf)))]
    return CheckResult(label, measured, tolerance, False, order=order,
                       note=f"{steps_note}; the remainder falls like h^{order} (median), not h²: the gradient is not "
                            f"that of the value, e.g. at X = ({worst[0]:.4g}, {worst[1]:.4g}, {worst[2]:.4g}) m")


def check_shape_gradients(fish, names: Sequence[str] | None = None) -> Iterator[CheckResult]:
    """The Taylor test of each of ``names`` (default: the fish's shapes) at the quadrature points of
    the fish's forms."""
    points = fish.tags.box.relative(fish.integration_points().reshape(-1, 3))
    for name in fish.shape_names if names is None else names:
        yield check_shape_gradient(name, points, fish.tags.box)
