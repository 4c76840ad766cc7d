"""How many vibration modes the basis takes: ``[reduction] vibration_modes``, a number or "auto".

"auto" follows the gait. A gait whose muscles all move in one rhythm (the antagonist pair: every
driven muscle at one frequency with phases 0° or 180°, one muscle group) keeps SPEC §7's single
mode. A gait of G > 1 muscle groups (muscles whose activations differ by more than a sign: another
frequency, or a phase other than 0° or 180° apart; the travelling wave over three pairs has G = 3)
bends the body in up to G independent shapes in the swimming plane, so the basis takes the lowest
modes of the clamped body until G of them lie in that plane:

    n_vm = min { n : #{i ≤ n : μ_y(φ_i) > ½} ≥ G },   μ_y(φ) = φ_yᵀ M_yy φ_y / φᵀ M φ,

μ_y the share of a mode's kinetic energy in the lateral direction y (the muscles' left–right
direction); the modes below the G-th lateral one (vertical bending, torsion) stay in the basis. The
shipped block and fish (clamped head, level 1) have their modes 1, 3, 4 lateral and mode 2 vertical:
n_vm = 4 for their three-pair waves (docs/devlog.md, "2026-12-06: reduced models that follow waves").
"auto" takes at most MAX_AUTO_MODES = 8 modes (io/scene_muscles.py).
"""
from __future__ import annotations

import logging

import numpy as np

from aquarom_fenics.io.scene_muscles import MAX_AUTO_MODES, muscle_groups

log = logging.getLogger("aquarom")

LATERAL_SHARE = 0.5
"""A mode lies in the swimming plane when more than this share of φᵀ M φ is in its y components."""


def lateral_shares(modes: np.ndarray, mass_products: np.ndarray, comm=None) -> np.ndarray:
    """μ_y of each column φ of ``modes`` (owned dofs, interleaved x, y, z), given M φ in
    ``mass_products``: Σ φ_y (Mφ)_y / Σ φ (Mφ), summed over the ranks of ``comm`` (M acts on each
    direction alike, so (Mφ)_y = M_s φ_y and the split of φᵀ M φ by direction is exact)."""
    parts = np.array([np.einsum("ij,ij->j", modes[1::3], mass_products[1::3]),
                      np.einsum("ij,ij->j", modes, mass_products)])
    if comm is not None:
        from mpi4py import MPI

        parts = comm.allreduce(parts, op=MPI.SUM)
    return parts[0] / parts[1]


def modes_for_groups(shares: np.ndarray, groups: int) -> int | None:
    """The smallest n such that G = ``groups`` of the first n modes have μ_y > :data:`LATERAL_SHARE`;
    None when the given modes hold fewer than G lateral ones."""
    lateral = np.cumsum(np.asarray(shares) > LATERAL_SHARE)
    reached = np.flatnonzero(lateral >= max(groups, 1))
    return int(reached[0]) + 1 if reached.size else None


def candidate_count(groups: int) -> int:
    """How many modes to compute for "auto" with G muscle groups: 2 G + 2 (room for an out-of-plane
    mode between each two lateral ones), at most MAX_AUTO_MODES (io/scene_muscles.py)."""
    return min(2 * groups + 2, MAX_AUTO_MODES)


def choose_modes(scene, modes: np.ndarray, frequencies: np.ndarray, shares: np.ndarray) -> int:
    """n_vm for "auto" from the computed candidate ``modes`` (their ``frequencies`` [Hz] and μ_y), with
    one log line that says what was chosen and why; all the candidates (at most MAX_AUTO_MODES), with a
    warning, when they hold fewer than G lateral modes."""
    groups = muscle_groups(scene)
    count = modes_for_groups(shares, groups)
    lateral = [f"{frequency:.2f}" for frequency, share in zip(frequencies, shares) if share > LATERAL_SHARE]
    if count is None:
        log.warning("basis: [reduction] vibration_modes = \"auto\": the %d lowest modes hold %d in the swimming "
                    "plane (y), fewer than the gait's %d muscle groups; the basis takes all %d (set "
                    "vibration_modes to a number to choose)", modes.shape[1], len(lateral), groups, modes.shape[1])
        return modes.shape[1]
    log.info("basis: [reduction] vibration_modes = \"auto\": %d modes, the lowest that hold %d in the swimming "
             "plane (%s Hz) for the gait's %d muscle groups", count, groups, ", ".join(lateral[:groups]), groups)
    return count
