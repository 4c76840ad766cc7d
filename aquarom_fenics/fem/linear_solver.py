"""The FOM's linear solvers: MUMPS factorisations (LU, or LDLᵀ of the symmetric upper triangle),
GMRES around them for a Newton matrix with a coupling outside its pattern, and what a failed
solve reports."""
from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from aquarom_fenics.errors import SolverError


def mumps_solver(comm: MPI.Comm, symmetric: bool = False, krylov: bool = False) -> PETSc.KSP:
    """A MUMPS factorisation, kept until its matrix changes: LU, or with ``symmetric`` MUMPS's LDLᵀ
    (SYM = 2, pivoting: indefinite matrices too) of an SBAIJ matrix. It is the whole solve
    ("preonly"), or with ``krylov`` the preconditioner of GMRES (relative tolerance 1e-10, at most
    100 iterations) for an operator that is not the factored matrix."""
    solver = PETSc.KSP().create(comm)
    if krylov:
        solver.setType("gmres")
        solver.setTolerances(rtol=1e-10, atol=0.0, max_it=100)
    else:
        solver.setType("preonly")
    preconditioner = solver.getPC()
    preconditioner.setType("cholesky" if symmetric else "lu")
    preconditioner.setFactorSolverType("mumps")
    return solver


def upper_triangle_copy(matrix: PETSc.Mat, out: PETSc.Mat | None) -> PETSc.Mat:
    """``matrix`` (BAIJ, symmetric) as SBAIJ, the upper triangle of its blocks; ``out`` from an earlier
    call is refilled in place (same pattern, so MUMPS keeps its analysis)."""
    matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    if out is None:
        return matrix.convert("sbaij", PETSc.Mat())
    matrix.convert("sbaij", out)
    return out


MUMPS_ERRORS = {-6: "structurally singular matrix", -9: "work array too small",
                -10: "numerically singular matrix", -13: "out of memory"}
"""Meaning of the negative INFOG(1) codes of a failed MUMPS factorisation."""


def describe_linear_solve(solver: PETSc.KSP) -> str:
    """KSP converged reason of the last solve and, for MUMPS, INFOG(1) of its factorisation."""
    reasons = {value: name for name, value in vars(PETSc.KSP.ConvergedReason).items() if name.isupper()}
    reason = solver.getConvergedReason()
    text = f"KSP {reasons.get(reason, reason)}"
    if solver.getPC().getFactorSolverType() != "mumps":
        return text
    try:
        info = solver.getPC().getFactorMatrix().getMumpsInfog(1)
    except PETSc.Error:
        return text
    return f"{text}, MUMPS INFOG(1) = {info}" + (f": {MUMPS_ERRORS[info]}" if info in MUMPS_ERRORS else "")


class ExactNewtonOperator:
    """PETSc Python matrix y = S x + c(x): the assembled Newton matrix S plus the coupling c outside
    it (zero on the fixed dofs, whose rows and columns of S are the identity)."""

    def set(self, matrix: PETSc.Mat, correction, fixed_dofs: np.ndarray) -> None:
        self.matrix, self.correction, self.fixed_dofs = matrix, correction, fixed_dofs

    def mult(self, operator, x: PETSc.Vec, y: PETSc.Vec) -> None:
        self.matrix.mult(x, y)
        values = x.array_r.copy()
        values[self.fixed_dofs] = 0.0
        extra = self.correction(values)
        extra[self.fixed_dofs] = 0.0
        y.array[:] += extra


def solve_into(solver: PETSc.KSP, rhs: np.ndarray, work_in: PETSc.Vec, work_out: PETSc.Vec) -> np.ndarray:
    """solver⁻¹ rhs through the work vectors (owned entries); SolverError if PETSc fails or the
    solve diverges (a failed factorisation)."""
    work_in.array[:] = rhs
    try:
        solver.solve(work_in, work_out)
    except PETSc.Error as error:
        raise SolverError(f"linear solve failed (PETSc {error}; {describe_linear_solve(solver)})") from None
    if solver.getConvergedReason() < 0:
        raise SolverError(f"linear solve failed ({describe_linear_solve(solver)})")
    return work_out.array.copy()
