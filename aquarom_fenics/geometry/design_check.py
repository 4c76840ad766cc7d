"""The design check of SPEC §4: a design may invert or flatten no cell (det F_1 ≤ 0 where the forms
are integrated); one that shrinks cells below 10 % of their volume is valid and runs with a warning.

A refused or squeezed design is named with its worst cells (centroid in the nominal mesh [m],
region, volume ratio), so the message says where the shape variation breaks or squeezes the mesh.
"""

from __future__ import annotations

from typing import Mapping, Protocol

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.mesh import signed_cell_volumes


class RegionTags(Protocol):
    """Anything with the cell indices of the head and of the two muscles (e.g. ``FishTags``)."""

    head_cells: np.ndarray
    left_muscle_cells: np.ndarray
    right_muscle_cells: np.ndarray


MIN_VOLUME_RATIO = 0.1
"""A design that shrinks a cell below this fraction of its nominal volume is warned about: the
continuum is valid there, but the FOM's answer is less accurate (measured at the SO2 optimum of the
method's source: 12 head cells at 0.083–0.1)."""

CELLS_NAMED = 3
"""A refused design names at most this many of its worst cells."""


def cell_region(cell: int, regions: RegionTags) -> str:
    """'head', 'left muscle', 'right muscle' or 'passive' (the rest of the body)."""
    for name, region_cells in (("head", regions.head_cells), ("left muscle", regions.left_muscle_cells),
                               ("right muscle", regions.right_muscle_cells)):
        if cell in region_cells:
            return name
    return "passive"


def describe_cell(cell: int, points: np.ndarray, cells: np.ndarray, volume_ratio: float,
                  regions: RegionTags | None = None) -> str:
    """'cell 17 (left muscle) at x=…, y=…, z=… [m], volume ratio …' of a nominal-mesh cell."""
    centroid = np.asarray(points, dtype=float)[np.asarray(cells)[cell]].mean(axis=0)
    region = f" ({cell_region(cell, regions)})" if regions is not None else ""
    return (f"cell {cell}{region} at x={centroid[0]:.4g}, y={centroid[1]:.4g}, z={centroid[2]:.4g}, "
            f"volume ratio {volume_ratio:.3g}")


def check_design(points: np.ndarray, cells: np.ndarray, moved_points: np.ndarray,
                 xi_by_name: Mapping[str, float], label: str = "design",
                 regions: RegionTags | None = None) -> str | None:
    """Raise InputError if the moved mesh inverts or flattens a cell; the warning if it shrinks one below 10%.

    Volumes are compared with the nominal cell's signed volume, so the check holds for
    either orientation of the nominal cells. The message names the worst cells with their
    centroids in the nominal mesh [m] and, given ``regions``, the region of each.
    """
    if not np.all(np.isfinite(moved_points)):
        names = ", ".join(f"{name}={value:g}" for name, value in xi_by_name.items())
        raise InputError(f"{label} {names} has non-finite node coordinates; give finite parameters")
    nominal = signed_cell_volumes(points, cells)
    return check_volume_ratios(signed_cell_volumes(moved_points, cells) / nominal, points, cells, xi_by_name, label, regions)


def check_exact_design(points: np.ndarray, cells: np.ndarray, gradient_at, sample_points: np.ndarray,
                       xi_by_name: Mapping[str, float], label: str = "design",
                       regions: RegionTags | None = None) -> str | None:
    """Raise InputError unless det F_1 = det(I + ∇u_ξ) > 0 at every sample point (SPEC §4); the warning
    (or None) of cells where it falls below MIN_VOLUME_RATIO.

    ``sample_points`` (n_cells, n_q, 3) are where the forms are integrated; ``gradient_at`` maps
    (n, 3) positions to ∇u_ξ (n, 3, 3) of the exact shape field. The message names the cells with
    the smallest det F_1 (their "volume ratio").
    """
    if not all(np.isfinite(value) for value in xi_by_name.values()):
        names = ", ".join(f"{name}={value:g}" for name, value in xi_by_name.items())
        raise InputError(f"{label} {names} has non-finite node coordinates; give finite parameters")
    n_cells, n_points = sample_points.shape[:2]
    gradient = gradient_at(sample_points.reshape(-1, 3))
    with np.errstate(invalid="ignore"):
        determinant = determinant_3x3(np.eye(3) + gradient).reshape(n_cells, n_points)
    determinant = np.where(np.isfinite(determinant), determinant, -np.inf)
    return check_volume_ratios(determinant.min(axis=1), points, cells, xi_by_name, label, regions)


def determinant_3x3(a: np.ndarray) -> np.ndarray:
    """det a of (n, 3, 3) matrices by the cofactors of the first row (a few times faster than
    ``np.linalg.det``'s LU per matrix; equal to rounding)."""
    return (a[:, 0, 0] * (a[:, 1, 1] * a[:, 2, 2] - a[:, 1, 2] * a[:, 2, 1])
            - a[:, 0, 1] * (a[:, 1, 0] * a[:, 2, 2] - a[:, 1, 2] * a[:, 2, 0])
            + a[:, 0, 2] * (a[:, 1, 0] * a[:, 2, 1] - a[:, 1, 1] * a[:, 2, 0]))


def check_volume_ratios(volume_ratio: np.ndarray, points: np.ndarray, cells: np.ndarray,
                        xi_by_name: Mapping[str, float], label: str = "design",
                        regions: RegionTags | None = None) -> str | None:
    """Raise InputError if a cell's volume ratio is ≤ 0 (inverted or flat); return a one-line warning
    naming the worst cells if some are below MIN_VOLUME_RATIO (None otherwise)."""
    inverted = volume_ratio <= 0.0
    shrunk = ~inverted & (volume_ratio < MIN_VOLUME_RATIO)
    parameters = ", ".join(f"{name}={value:g}" for name, value in xi_by_name.items())
    if inverted.any():
        named = _worst_cells(volume_ratio, int(inverted.sum()), points, cells, regions)
        raise InputError(
            f"{label} {parameters} inverts or flattens {int(inverted.sum())} of {len(volume_ratio)} cells "
            f"(worst, in the nominal mesh: {named}); reduce the parameters")
    if not shrunk.any():
        return None
    named = _worst_cells(volume_ratio, int(shrunk.sum()), points, cells, regions)
    return (f"{label} {parameters} shrinks {int(shrunk.sum())} of {len(volume_ratio)} cells below "
            f"{MIN_VOLUME_RATIO:g} of their nominal volume (worst, in the nominal mesh: {named}); the design is "
            "valid, the FOM is less accurate there")


def _worst_cells(volume_ratio, count: int, points, cells, regions) -> str:
    worst = np.argsort(volume_ratio, kind="stable")[:min(CELLS_NAMED, count)]
    return "; ".join(describe_cell(int(cell), points, cells, volume_ratio[cell], regions) for cell in worst)
