"""Taylor test of a shape field's gradient against its value (SPEC §4: the forms use ∇U_k, the
design moves the nodes by U_k, so the two must agree).

At every quadrature point X_i of the forms (nominal, relative to the box: the points of every cell,
where F_1 = I + ξ ∇U is evaluated) and a random unit direction d_i, the first-order remainders

    r_i^±(h) = ‖U(X_i ± h d_i) - U(X_i) ∓ h ∇U(X_i) d_i‖

fall like h² where U is smooth and ∇U is its gradient (Taylor: r = ½ h² |d·∇²U d| + O(h³)), like h
where ∇U is wrong (r = h ‖(∇U_true - ∇U) d‖ + O(h²)). Steps h = h_0, h_0/2, …, h_0/2^HALVINGS with
h_0 = STEP_FRACTION × L; the local order of a direction is log2(r(h_K-1) / r(h_K)) at the last two
steps. A direction is exact where its remainder r(h_K) is at round-off (EXACT × the first-order
term h_K max‖∇U d‖: U linear there). A point passes when one of its two directions is exact or has
an order ≥ MIN_ORDER, midway between the 2 of a right gradient and the 1 of a wrong one; the field
passes when every point passes: a gradient wrong on one cell fails the test, however small that
cell's share of the body. Two directions, because a point closer than h to a kink of a piecewise
field (a region's edge) sees a first-order remainder on the side of the kink, and a second-order
one away from it, where its one-sided gradient holds.
"""
from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from aquarom_fenics.geometry.shapes import shape_displacement, shape_gradients
from aquarom_fenics.verification.check import CheckResult

STEP_FRACTION = 1e-4             # h_0 / L
HALVINGS = 3                     # h_0 … h_0 / 2³
MIN_ORDER = 1.5                  # between the orders 2 (right gradient) and 1 (wrong gradient)
EXACT = 1e-8                     # r(h_K) below this × the largest first-order term h_K ‖∇U d‖: exact


def taylor_remainders(name: str, points: np.ndarray, box, steps: np.ndarray,
                      seed: int = 5) -> tuple[np.ndarray, float]:
    """(2, len(steps), n) remainders r_i^±(h) of the field ``name`` at (n, 3) relative points (the
    directions +d_i, then -d_i), and the largest first-order term ‖∇U d‖ per unit step."""
    directions = np.random.default_rng(seed).standard_normal(points.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    value = shape_displacement(name, points, box)
    slope = np.einsum("nij,nj->ni", shape_gradients([name], points, box)[0], directions)
    remainders = np.stack([np.stack([np.linalg.norm(shape_displacement(name, points + sign * h * directions, box)
                                                    - value - sign * h * slope, axis=1) for h in steps])
                           for sign in (1.0, -1.0)])
    return remainders, float(np.max(np.linalg.norm(slope, axis=1), initial=0.0))


def local_orders(remainders: np.ndarray, steps: np.ndarray, slope: float) -> np.ndarray:
    """(n,) order of each point: the larger of its two directions' log2(r(h_K-1) / r(h_K)), +inf
    where a direction is exact (module docstring)."""
    exact = remainders[:, -1] <= EXACT * steps[-1] * slope
    with np.errstate(divide="ignore", invalid="ignore"):
        orders = np.log2(remainders[:, -2] / remainders[:, -1])
    return np.where(exact, np.inf, np.nan_to_num(orders, nan=-np.inf)).max(axis=0)


def check_shape_gradient(name: str, points: np.ndarray, box) -> CheckResult:
    """The Taylor test of the field ``name`` at (n, 3) relative points of the body in ``box``."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    steps = STEP_FRACTION * box.length * 0.5 ** np.arange(HALVINGS + 1)
    remainders, slope = taylor_remainders(name, points, box, steps)
    orders = local_orders(remainders, steps, slope)
    label = f"0 ∇U {name}"
    tolerance = f"min ≥ {MIN_ORDER:g}"
    steps_note = f"h = {steps[0]:.2g}…{steps[-1]:.2g} m, {len(points)} quadrature points"
    finite = orders[np.isfinite(orders)]
    if not finite.size:
        return CheckResult(label, f"exact at {len(points)}", tolerance, True,
                           note=f"{steps_note}; remainder at round-off everywhere (linear field)")
    failed = orders < MIN_ORDER
    if not failed.any():
        order = f"{np.median(finite):.2f}"
        return CheckResult(label, f"min {finite.min():.2f}", tolerance, True, order=order,
                           note=f"{steps_note}; local order of the remainder, median {order}")
    order = f"{np.median(orders[failed]):.2f}"
    worst = points[int(np.argmin(orders))]
    return CheckResult(label, f"{int(failed.sum())} of {len(points)} < {MIN_ORDER:g}", tolerance, False, order=order,
                       note=f"{steps_note}; at {int(failed.sum())} points the remainder falls like h^{order} (median), "
                            f"not h²: the gradient is not that of the value, e.g. at X = ({worst[0]:.4g}, "
                            f"{worst[1]:.4g}, {worst[2]:.4g}) m")


def check_shape_gradients(fish, names: Sequence[str] | None = None) -> Iterator[CheckResult]:
    """The Taylor test of each of ``names`` (default: the fish's shapes) at the quadrature points of
    every cell of the fish's forms."""
    points = fish.tags.box.relative(fish.integration_points().reshape(-1, 3))
    for name in fish.shape_names if names is None else names:
        yield check_shape_gradient(name, points, fish.tags.box)
