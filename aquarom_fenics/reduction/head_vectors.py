"""Basis vectors that strain the head, for reduced models that calibrate its stiffness factor (issue 52).

The basis of SPEC §7 is built with the head clamped (``basis.py``): its vectors move the head as a rigid
x-translation at most, so the head cells carry no strain in the reduced model and the head's factor
h (``[material] head_stiffness_factor``) does not enter it. The FOM holds the head in y and z only
(SPEC §5): under the muscles the head deforms along x. Its static response to each activation pattern
P_k with the head held as it swims,

    ψ_head,k = K_s⁻¹ f_act(P_k),   K_s = K_0 with the head's y, z dofs and one head node's x fixed,

(the muscle force is self-equilibrated: the pinned x only removes the free translation) carries that
strain; added to the basis, the head share of the elastic tensors is not zero and the reduced model's
derivative in h follows the FOM's.
"""
from __future__ import annotations

import numpy as np

from aquarom_fenics.fem.linear_solver import mumps_solver


def head_responses(fom, vectors: np.ndarray, labels: list[str]) -> list[tuple[str, np.ndarray]]:
    """(label, ψ_head,k) per activation pattern of the muscles and (label, K_s⁻¹ M v) per vector v of the basis
    ``vectors`` but the rigid translation, the head held as it swims (module docstring)."""
    from aquarom_fenics.reduction.basis import pattern_suffixes, unit_actuation_force

    patterns = fom.muscle.law.patterns() if fom.muscle.on else []
    pinned = fom._head_dofs(fom.fish.tags.head_nodes[:1], (0,))
    held = np.union1d(fom.fixed_dofs, pinned)
    matrix = fom.rest_stiffness.copy()
    matrix.zeroRowsColumns(fom.global_dofs(held), diag=1.0)
    solver = mumps_solver(fom.comm)
    solver.setOperators(matrix)
    responses = []
    try:
        for suffix, pattern in zip(pattern_suffixes(len(patterns)), patterns):
            force = unit_actuation_force(fom, pattern)
            force[held] = 0.0
            responses.append((f"head_psi{suffix}", fom.solve_with(solver, force)))
        for label, vector in zip(labels, vectors.T):
            if label != "rigid_x":
                inertia = fom.matvec(fom.mass_matrix, vector)
                inertia[held] = 0.0
                responses.append((f"head_ritz_{label}", fom.solve_with(solver, inertia)))
    finally:
        solver.destroy()
        matrix.destroy()
    return responses


def with_head_responses(fom, basis):
    """``basis`` (a ReductionBasis) with :func:`head_responses` added, mass-orthonormalised after its vectors."""
    from aquarom_fenics.reduction.basis import ReductionBasis, mass_orthonormalise

    candidates = list(zip(basis.labels, basis.vectors.T)) + head_responses(fom, basis.vectors, basis.labels)
    vectors, labels, dropped = mass_orthonormalise(fom, candidates, fom.scene.reduction.drop_tolerance)
    return ReductionBasis(vectors, labels, list(basis.dropped) + dropped, basis.frequencies, basis.timings)
