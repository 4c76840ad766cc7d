"""The atlas's check of its own cells: ``[reduction] atlas_check`` = τ > 0.

A cell of the atlas (a node of :mod:`~aquarom_fenics.reduction.atlas_refine`, centre c, half-width h) answers
every design in it with the PROM built at c. Whether that holds within 3 % of the FOM depends on the scene
(s = 0.7 holds on SO1's box, not on SO2's, SO3's or SO7-SO9's: +21 to +47 % at a cell's corner). The check
compares the centre's PROM with the PROMs built at two of the cell's corners, where the error is likely largest:
along the sign pattern σ of the centre PROM's distance gradient g = ∂d_c/∂ξ (c),

    σ_k = sign(g_k) (+1 where g_k = 0),      v± = c ± σ ∘ h,

the corners where the centre PROM's distance moves most to first order. A PROM at its own centre is the best
reduced answer there, so the gap

    γ± = |d_c(v±) - d_v±(v±)| / |d_v±(v±)|

(d_c the centre PROM's distance, d_v the corner PROM's at its own centre) stands in for the error against the
FOM. A cell with max γ± > τ is halved once in every shape that has a width (``atlas_refine.Refiner``; at most
``MAX_DEPTH`` halvings per shape), and the half holding the design is checked the same way. A corner is a vertex
of the finest grid, placed by integers (:func:`vertex`), so cells that meet there share its PROM in the PROM cache;
a half's corners along its parent's signs are its parent's centre and corner, whose PROMs are built already.
A corner whose PROM cannot be built is left out of the check (its gap NaN); a reduced solve that stops counts as
an infinite gap (the cell is halved). Everything is a function of the node and its PROMs: deterministic, the same
under any worker pool.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aquarom_fenics.errors import InputError

CORNERS = 2
"""Corners checked per cell: v+ and v- along the centre PROM's distance gradient signs."""


@dataclass
class CellCheck:
    """What the check of one cell found: its corners (2, p), the relative gaps γ (2,) (NaN: the corner's PROM
    could not be built; ∞: a solve stopped), the corner PROMs built (not read from the cache) and the outcome."""

    corners: np.ndarray
    gaps: np.ndarray
    built: int
    tolerance: float
    refused: list = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """Whether every corner that could be compared is within τ: max γ ≤ τ over the finite-or-∞ gaps."""
        known = self.gaps[~np.isnan(self.gaps)]
        return bool(np.all(known <= self.tolerance))

    @property
    def largest(self) -> float:
        known = self.gaps[~np.isnan(self.gaps)]
        return float(np.max(known)) if known.size else float("nan")

    def record(self, names) -> dict:
        """The check as atlas.json gives it: corners by shape, gaps, builds, passed."""
        return {"tolerance": self.tolerance, "corners": [dict(zip(names, corner.tolist())) for corner in self.corners],
                "gaps": [None if np.isnan(gap) else float(gap) for gap in self.gaps], "corner_builds": self.built,
                "passed": self.passed, **({"refused": self.refused} if self.refused else {})}


def gradient_signs(gradient: np.ndarray) -> np.ndarray:
    """σ_k = sign(g_k), +1 where g_k = 0 or is not a number."""
    gradient = np.nan_to_num(np.asarray(gradient, dtype=float))
    return np.where(gradient < 0, -1, 1).astype(int)


def vertex(lower: np.ndarray, half_width: np.ndarray, index, levels, signs, depth: int) -> np.ndarray:
    """The corner c + σ ∘ h of the node ``index`` at ``levels`` halvings (h the base cell's half-width ``half_width``)
    as a point of the grid of ``depth`` halvings, n_k = (2 j_k + 1 + σ_k) 2^{depth - L_k}, placed as the centre of
    the node it is the centre of: with n_k = 2^{t_k} (2 i_k + 1), t_k ≤ depth,

        ξ_k = lower_k + (2 i_k + 1) h_k / 2^{depth - t_k}     (``Node.center``'s floats),

    else (a vertex of the base cells, t_k > depth) ξ_k = lower_k + (n_k / 2^depth) h_k. So every node that has the
    point as a corner, and the node centred there, name the same floats, and share its PROM in the PROM cache."""
    levels = np.asarray(levels, dtype=int)
    count = (2 * np.asarray(index, dtype=np.int64) + 1 + np.asarray(signs, dtype=np.int64)) * 2 ** (depth - levels)
    point = np.array(lower, dtype=float)
    for k, n in enumerate(int(c) for c in count):
        if n == 0:
            continue
        twos = (n & -n).bit_length() - 1                            # t: the power of 2 in n
        if twos <= depth:
            point[k] = lower[k] + (n >> twos) * (half_width[k] / 2.0 ** (depth - twos))
        else:
            point[k] = lower[k] + (n >> depth) * half_width[k]
    return point


def relative_gaps(center_distances: np.ndarray, corner_distances: np.ndarray) -> np.ndarray:
    """γ = |d_c(v) - d_v(v)| / |d_v(v)| per corner; ∞ where a distance is not a number (a stopped solve)."""
    center_distances = np.asarray(center_distances, dtype=float)
    corner_distances = np.asarray(corner_distances, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        gaps = np.abs(center_distances - corner_distances) / np.abs(corner_distances)
    return np.where(np.isfinite(gaps), gaps, np.inf)


def check_cell(center_prom, scene, center: np.ndarray, corners_of, corner_prom, tolerance: float,
               distances) -> CellCheck:
    """The check of a cell: the centre PROM's gradient at c gives σ, ``corners_of(σ)`` → the corners (2, p)
    v± = c ± σ ∘ h, ``corner_prom(v)`` → (PROM at v, built) or InputError, ``distances(prom, scene, xis,
    gradient)`` → (d, ∂d/∂ξ) (:func:`~aquarom_fenics.dynamics.batched.reduced_distances`: the reduced dynamics
    sit above this layer, so the caller passes them)."""
    _, gradient = distances(center_prom, scene, np.asarray(center, dtype=float)[None, :], True)
    corners = np.asarray(corners_of(gradient_signs(gradient[0])), dtype=float)
    from_center, _ = distances(center_prom, scene, corners, False)
    own, built, refused = np.full(len(corners), np.nan), 0, []
    for k, corner in enumerate(corners):
        try:
            prom, fresh = corner_prom(corner)
        except InputError as error:
            refused.append(str(error))
            continue
        built += bool(fresh)
        own[k] = distances(prom, scene, corner[None, :], False)[0][0]
    gaps = np.where(np.isnan(own), np.nan, relative_gaps(from_center, own))
    return CellCheck(corners, gaps, built, float(tolerance), refused)
