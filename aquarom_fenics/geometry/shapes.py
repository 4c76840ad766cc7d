"""Shape variations: the catalog of nodal displacement fields of SPEC §4.

A design is ``x_ξ = x_0 + U ξ`` (SPEC §1), ``U = [U_1 … U_p]`` with one column per shape
variation. Every field is a pure function of the *relative* coordinates of the nominal shape,

    x ∈ [-L, 0]  (head face at 0, tail face at -L),   y, z measured from the body axis,

and of the box dimensions L (``box.length``), W (``box.width``), H (``box.height``). It takes the
three coordinate arrays separately and returns ``(dx, dy, dz)`` of the same shape, so the same
function serves a numpy point array and a dolfinx interpolation (which passes a (3, N) array).
Every field vanishes outside its region. "Collapse" fields bring their coordinate to 0 at the
extreme for ξ = 1; negative ξ enlarges.

Nodal arrays are (n_nodes, 3); ``U`` is (3 n_nodes, p) in node-major order (x0, y0, z0, x1, …).
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence

import numpy as np

from aquarom_fenics.errors import InputError


class BoxDimensions(Protocol):
    """Anything with the nominal block's length L (x), width W (y) and height H (z) [m]."""

    length: float
    width: float
    height: float


ShapeField = Callable[
    [np.ndarray, np.ndarray, np.ndarray, BoxDimensions], tuple[np.ndarray, np.ndarray, np.ndarray]
]
"""(x, y, z) relative coordinates, box -> (dx, dy, dz) nodal displacement [m]."""

def _zero(x: np.ndarray) -> np.ndarray:
    return np.zeros(np.shape(x))


def _inside(region: np.ndarray, value: np.ndarray) -> np.ndarray:
    """``value`` in the region, 0 outside."""
    return np.where(region, value, 0.0)


def _rounding(s: np.ndarray) -> np.ndarray:
    """√(1 - s²) - 1, with 1 - s² clipped at 0 so |s| = 1 + rounding error gives -1, not NaN."""
    return np.sqrt(np.clip(1.0 - s**2, 0.0, None)) - 1.0


def _tail_rounding(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """√(1 - s²) - 1 for x ≤ -0.7L, s = (x + 0.7L)/(0.3L) ∈ [-1, 0]; 0 elsewhere."""
    length = box.length
    s = (x + 0.7 * length) / (0.3 * length)
    return _inside(x <= -0.7 * length, _rounding(s))


def _head_rounding(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """√(1 - s²) - 1 for x ≥ -0.3L, s = (x + 0.3L)/(0.3L) ∈ [0, 1]; 0 elsewhere."""
    length = box.length
    s = (x + 0.3 * length) / (0.3 * length)
    return _inside(x >= -0.3 * length, _rounding(s))


def _long_tail_ramp(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """(-x - 0.3L)/(0.7L) for x ≤ -0.3L (0 at -0.3L, 1 at -L); 0 elsewhere."""
    length = box.length
    return _inside(x <= -0.3 * length, (-x - 0.3 * length) / (0.7 * length))


def _notch(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """f(x) for -0.9L ≤ x ≤ -0.3L, piecewise linear: 0 at -0.3L, 1 at -0.7L, 0 at -0.9L."""
    length = box.length
    f = np.interp(x, [-0.9 * length, -0.7 * length, -0.3 * length], [0.0, 1.0, 0.0])
    return _inside((x >= -0.9 * length) & (x <= -0.3 * length), f)


def z_tail(x, y, z, box):
    # Δz = z(√(1-s²) - 1), s = (x + 0.7L)/(0.3L), x ≤ -0.7L
    return _zero(x), _zero(x), z * _tail_rounding(x, box)


def z_head(x, y, z, box):
    # Δz = z(√(1-s²) - 1), s = (x + 0.3L)/(0.3L), x ≥ -0.3L
    return _zero(x), _zero(x), z * _head_rounding(x, box)


def y_thin(x, y, z, box):
    # Δy = -y, everywhere
    return _zero(x), -y, _zero(x)


def y_lin_long_tail(x, y, z, box):
    # Δy = -y(-x - 0.3L)/(0.7L), x ≤ -0.3L
    return _zero(x), -y * _long_tail_ramp(x, box), _zero(x)


def y_head(x, y, z, box):
    # Δy = y(√(1-s²) - 1), s = (x + 0.3L)/(0.3L), x ≥ -0.3L
    return _zero(x), y * _head_rounding(x, box), _zero(x)


def y_ellipse(x, y, z, box):
    # Δy = y(√(1 - (2z/H)²) - 1), everywhere
    return _zero(x), y * _rounding(2.0 * z / box.height), _zero(x)


def z_small(x, y, z, box):
    # Δz = -z, everywhere
    return _zero(x), _zero(x), -z


def z_notch(x, y, z, box):
    # Δz = -z f(x), -0.9L ≤ x ≤ -0.3L; f piecewise linear: 0 at -0.3L, 1 at -0.7L, 0 at -0.9L
    return _zero(x), _zero(x), -z * _notch(x, box)


def xz_concave_tail(x, y, z, box):
    # Δx = -|z| b(x), Δz = 0.4 z b(x), b = (-0.9L - x)/(0.1L), x ≤ -0.9L
    length = box.length
    b = _inside(x <= -0.9 * length, (-0.9 * length - x) / (0.1 * length))
    return -np.abs(z) * b, _zero(x), 0.4 * z * b


def y_fin(x, y, z, box):
    # Δy = y h(x), -0.9L ≤ x ≤ -0.7L; h a hat: 0 at -0.9L, 1 at -0.8L, 0 at -0.7L
    length = box.length
    h = np.interp(x, [-0.9 * length, -0.8 * length, -0.7 * length], [0.0, 1.0, 0.0])
    region = (x >= -0.9 * length) & (x <= -0.7 * length)
    return _zero(x), y * _inside(region, h), _zero(x)


def y_notch(x, y, z, box):
    # Δy = -y f(x), f and region as z_notch
    return _zero(x), -y * _notch(x, box), _zero(x)


def z_tail_step(x, y, z, box):
    # Δz = -z g(x), x ≤ -0.45L; g = 1 for x ≤ -0.55L, linear to 0 at -0.45L
    length = box.length
    g = np.interp(x, [-0.55 * length, -0.45 * length], [1.0, 0.0])
    return _zero(x), _zero(x), -z * _inside(x <= -0.45 * length, g)


def z_tail_lin(x, y, z, box):
    # Δz = -z(-x - 0.3L)/(0.7L), x ≤ -0.3L
    return _zero(x), _zero(x), -z * _long_tail_ramp(x, box)


def y_tail(x, y, z, box):
    # Δy = y(√(1-s²) - 1), s = (x + 0.7L)/(0.3L), x ≤ -0.7L (z_tail with y and z swapped)
    return _zero(x), y * _tail_rounding(x, box), _zero(x)


CATALOG: dict[str, ShapeField] = {
    "z_tail": z_tail,
    "z_head": z_head,
    "y_thin": y_thin,
    "y_lin_long_tail": y_lin_long_tail,
    "y_head": y_head,
    "y_ellipse": y_ellipse,
    "z_small": z_small,
    "z_notch": z_notch,
    "xz_concave_tail": xz_concave_tail,
    "y_fin": y_fin,
    "y_notch": y_notch,
    "z_tail_step": z_tail_step,
    "z_tail_lin": z_tail_lin,
    "y_tail": y_tail,
}
"""Every shape variation by the name scenes use, in the order of SPEC §4 (paper numbers 1-13)."""


# ---------------------------------------------------------------------------------------------
# Exact gradients ∇U_k of the fields (SPEC §4: F_1 = I + ∇u_ξ where the forms are integrated)

ShapeGradient = Callable[[np.ndarray, np.ndarray, np.ndarray, BoxDimensions], np.ndarray]
"""(x, y, z) relative coordinates, box -> (n, 3, 3) gradient G_ij = ∂Δx_i/∂x_j (dimensionless)."""


def _rounding_slope(s: np.ndarray) -> np.ndarray:
    """d/ds (√(1 - s²) - 1) = -s/√(1 - s²); infinite at |s| = 1 (only on the body's faces)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s**2 < 1.0, -s / np.sqrt(np.clip(1.0 - s**2, 0.0, None)), -np.sign(s) * np.inf)


def _tail_rounding_slope(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """d/dx of `_tail_rounding`: (1/(0.3L)) d/ds (√(1-s²) - 1) for x ≤ -0.7L."""
    length = box.length
    s = (x + 0.7 * length) / (0.3 * length)
    return _inside(x <= -0.7 * length, _rounding_slope(s) / (0.3 * length))


def _head_rounding_slope(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """d/dx of `_head_rounding`: (1/(0.3L)) d/ds (√(1-s²) - 1) for x ≥ -0.3L."""
    length = box.length
    s = (x + 0.3 * length) / (0.3 * length)
    return _inside(x >= -0.3 * length, _rounding_slope(s) / (0.3 * length))


def _piecewise_linear_slope(x: np.ndarray, knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Slope of the piecewise-linear interpolant of (knots, values) at x; 0 outside the knots."""
    slopes = np.diff(values) / np.diff(knots)
    segment = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, len(slopes) - 1)
    return np.where((x >= knots[0]) & (x <= knots[-1]), slopes[segment], 0.0)


def _long_tail_ramp_slope(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """d/dx of `_long_tail_ramp`: -1/(0.7L) for x ≤ -0.3L."""
    return _inside(x <= -0.3 * box.length, np.full(np.shape(x), -1.0 / (0.7 * box.length)))


def _notch_slope(x: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """d/dx of `_notch`."""
    knots = np.array([-0.9, -0.7, -0.3]) * box.length
    return _piecewise_linear_slope(x, knots, np.array([0.0, 1.0, 0.0]))


def _gradient(n: int, entries) -> np.ndarray:
    """(n, 3, 3) gradient with the given {(i, j): ∂Δx_i/∂x_j} entries, zero elsewhere."""
    gradient = np.zeros((n, 3, 3))
    for (i, j), value in entries.items():
        gradient[:, i, j] = value
    return gradient


def _product_gradient(n: int, component: int, factor, factor_slope, factor_axis: int,
                      profile, profile_slope, profile_axis: int) -> np.ndarray:
    """∇ of Δx_c = a(x_k) p(x_l): ∂/∂x_k = a' p, ∂/∂x_l = a p' (k ≠ l)."""
    return _gradient(n, {(component, factor_axis): factor_slope * profile,
                         (component, profile_axis): factor * profile_slope})


def _grad_z_times_x_profile(sign, profile, slope):
    """∇ of Δz = sign · z p(x)."""
    def gradient(x, y, z, box):
        return _product_gradient(np.size(x), 2, sign * z, sign, 2, profile(x, box), slope(x, box), 0)
    return gradient


def _grad_y_times_x_profile(sign, profile, slope):
    """∇ of Δy = sign · y p(x)."""
    def gradient(x, y, z, box):
        return _product_gradient(np.size(x), 1, sign * y, sign, 1, profile(x, box), slope(x, box), 0)
    return gradient


def _fin_hat(x, box):
    length = box.length
    region = (x >= -0.9 * length) & (x <= -0.7 * length)
    return _inside(region, np.interp(x, [-0.9 * length, -0.8 * length, -0.7 * length], [0.0, 1.0, 0.0]))


def _fin_hat_slope(x, box):
    return _piecewise_linear_slope(x, np.array([-0.9, -0.8, -0.7]) * box.length, np.array([0.0, 1.0, 0.0]))


def _tail_step(x, box):
    length = box.length
    return _inside(x <= -0.45 * length, np.interp(x, [-0.55 * length, -0.45 * length], [1.0, 0.0]))


def _tail_step_slope(x, box):
    return _piecewise_linear_slope(x, np.array([-0.55, -0.45]) * box.length, np.array([1.0, 0.0]))


def _grad_y_ellipse(x, y, z, box):
    # Δy = y ρ(2z/H), ρ(s) = √(1 - s²) - 1: ∂/∂y = ρ, ∂/∂z = y ρ'(2z/H) 2/H
    s = 2.0 * z / box.height
    return _product_gradient(np.size(x), 1, y, 1.0, 1, _rounding(s), 2.0 / box.height * _rounding_slope(s), 2)


def _grad_xz_concave_tail(x, y, z, box):
    # Δx = -|z| b(x), Δz = 0.4 z b(x), b = (-0.9L - x)/(0.1L) for x ≤ -0.9L
    length = box.length
    b = _inside(x <= -0.9 * length, (-0.9 * length - x) / (0.1 * length))
    b_slope = _inside(x <= -0.9 * length, np.full(np.shape(x), -1.0 / (0.1 * length)))
    return _gradient(np.size(x), {(0, 0): -np.abs(z) * b_slope, (0, 2): -np.sign(z) * b,
                                  (2, 0): 0.4 * z * b_slope, (2, 2): 0.4 * b})


def _constant_gradient(i: int, value: float):
    def gradient(x, y, z, box):
        return _gradient(np.size(x), {(i, i): value})
    return gradient


GRADIENTS: dict[str, ShapeGradient] = {
    "z_tail": _grad_z_times_x_profile(1.0, _tail_rounding, _tail_rounding_slope),
    "z_head": _grad_z_times_x_profile(1.0, _head_rounding, _head_rounding_slope),
    "y_thin": _constant_gradient(1, -1.0),
    "y_lin_long_tail": _grad_y_times_x_profile(-1.0, _long_tail_ramp, _long_tail_ramp_slope),
    "y_head": _grad_y_times_x_profile(1.0, _head_rounding, _head_rounding_slope),
    "y_ellipse": _grad_y_ellipse,
    "z_small": _constant_gradient(2, -1.0),
    "z_notch": _grad_z_times_x_profile(-1.0, _notch, _notch_slope),
    "xz_concave_tail": _grad_xz_concave_tail,
    "y_fin": _grad_y_times_x_profile(1.0, _fin_hat, _fin_hat_slope),
    "y_notch": _grad_y_times_x_profile(-1.0, _notch, _notch_slope),
    "z_tail_step": _grad_z_times_x_profile(-1.0, _tail_step, _tail_step_slope),
    "z_tail_lin": _grad_z_times_x_profile(-1.0, _long_tail_ramp, _long_tail_ramp_slope),
    "y_tail": _grad_y_times_x_profile(1.0, _tail_rounding, _tail_rounding_slope),
}
"""∇U_k of every catalog field, exact (piecewise-analytic; one-sided at the kinks)."""


REGISTERED: dict[str, tuple[ShapeField, ShapeGradient]] = {}
"""Fields registered in this process (``shape_registry.register_shape_field``): name -> (field,
gradient) with the catalogue's signatures. They follow the catalogue in ``shape_names``."""


def shape_gradient_function(name: str) -> ShapeGradient:
    """∇U of the catalogue's or a registered field ``name``."""
    if name in GRADIENTS:
        return GRADIENTS[name]
    shape_field(name)                       # InputError for an unknown name
    return REGISTERED[name][1]


def shape_gradients(names: Sequence[str], relative_points: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """(p, n, 3, 3): ∇U_k at (n, 3) relative coordinates, for every name."""
    points = np.asarray(relative_points, dtype=float).reshape(-1, 3)
    return np.stack([shape_gradient_function(name)(points[:, 0], points[:, 1], points[:, 2], box)
                     for name in names]) if len(names) else np.zeros((0, points.shape[0], 3, 3))


def shape_names() -> list[str]:
    """The catalogue's names, then those registered in this process."""
    return list(CATALOG) + list(REGISTERED)


def shape_field(name: str) -> ShapeField:
    if name in CATALOG:
        return CATALOG[name]
    if name in REGISTERED:
        return REGISTERED[name][0]
    raise InputError(f"unknown shape variation '{name}'; valid names: {', '.join(shape_names())}")


def shape_displacement(name: str, relative_points: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """The field ``name`` at (n, 3) relative coordinates: (n, 3) displacements [m]."""
    points = np.asarray(relative_points, dtype=float)
    field = shape_field(name)
    return np.stack(field(points[:, 0], points[:, 1], points[:, 2], box), axis=1)


def shape_matrix(names: Sequence[str], relative_points: np.ndarray, box: BoxDimensions) -> np.ndarray:
    """U (3 n_nodes, p): column k is field ``names[k]``, node i component c at row 3 i + c."""
    n_nodes = len(relative_points)
    matrix = np.empty((3 * n_nodes, len(names)))
    for k, name in enumerate(names):
        matrix[:, k] = shape_displacement(name, relative_points, box).ravel()
    return matrix


def design_points(points: np.ndarray, U: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """x_ξ = x_0 + U ξ as (n_nodes, 3)."""
    points = np.asarray(points, dtype=float)
    return points + (U @ np.asarray(xi, dtype=float)).reshape(points.shape)


def reference_to_cells(points: np.ndarray, cells: np.ndarray, reference_points: np.ndarray) -> np.ndarray:
    """(n_cells, n_q, 3) physical positions x = x_0 + Σ_a X_a (x_a - x_0) of reference points X."""
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    edges = vertices[:, 1:, :] - vertices[:, :1, :]
    return vertices[:, None, 0, :] + np.einsum("qa,cai->cqi", reference_points, edges)
