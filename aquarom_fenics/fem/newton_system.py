"""The FOM's Newton system (SPEC §6): the Newton matrix of a time step,

    S = ∂r_{n+1-α}/∂u_{n+1} = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t,

assembled from the model's tangent form, the thrust and drag entries and the constant k_a M + k_v C
(``NewtonMatrix``); the coupling that stays outside the sparse matrix (stations, head-averaged drag);
and the factorisation and solves of S (``NewtonSolver``, with the solvers of ``linear_solver``).
"""
from __future__ import annotations

import time as clock
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.linear_solver import (ExactNewtonOperator, describe_linear_solve, mumps_solver,
                                              upper_triangle_copy)
from aquarom_fenics.fem.time_scheme import TimeScheme


@dataclass
class SolveProfile:
    """Wall time [s] of this rank in the parts of the Newton iterations (``FullOrderModel.profile``)."""

    residuals: float = 0.0              # r(u, u̇, ü): forms, matrix products, thrust, drag
    newton_matrix_assembly: float = 0.0  # S: tangent form, thrust and drag entries, M and C, fixed dofs
    factorizations: float = 0.0         # MUMPS numerical factorisation (and the first analysis)
    solves: float = 0.0                 # forward and back substitutions (GMRES with "krylov")
    counts: dict = field(default_factory=lambda: {"residuals": 0, "factorizations": 0, "solves": 0})

    def as_dict(self) -> dict:
        return {"residuals": self.residuals, "newton_matrix_assembly": self.newton_matrix_assembly,
                "factorizations": self.factorizations, "solves": self.solves, "counts": dict(self.counts)}


@dataclass(frozen=True)
class TangentFactors:
    """Factors of S = k_u K_t + k_v C_t + k_a M_t that pick one tangent."""

    stiffness_factor: float
    velocity_factor: float
    acceleration_factor: float


STIFFNESS, DAMPING, MASS = TangentFactors(1.0, 0.0, 0.0), TangentFactors(0.0, 1.0, 0.0), TangentFactors(0.0, 0.0, 1.0)
"""The factors of K_t, C_t and M_t alone."""


class NewtonMatrix:
    """S of one model and its tangents K_t, C_t, M_t, all in one storage: the pattern of the model's
    tangent form with the thrust and drag Jacobians' entries reserved (they lie outside it).

    Owns the storage, the block k_a M + k_v C of the current time step and the copies of the
    constant matrices on the storage's pattern (released by :meth:`destroy`).
    """

    def __init__(self, model):
        self.model = model
        self.scheme: TimeScheme | None = None
        self._storage: PETSc.Mat | None = None
        self._inertia_damping: PETSc.Mat | None = None
        self._on_newton_pattern: dict[str, PETSc.Mat] = {}

    @property
    def storage(self) -> PETSc.Mat:
        """The matrix S and the tangents are assembled into. Made at first use: a PROM build never
        needs it."""
        if self._storage is None:
            model = self.model
            entries = [np.zeros((2, 0), dtype=np.int64)] + [np.stack(term.newton_entries())
                                                            for term in (model.thrust, model.drag) if term is not None]
            rows, columns = np.concatenate(entries, axis=1)
            self._storage = fx.create_matrix_with_entries(model.tangent_form, rows, columns)
            self._storage.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        return self._storage

    def set_time_step(self, scheme: TimeScheme) -> None:
        """The scheme's factors enter S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t;
        the block k_a M + k_v C of the previous step is released (petsc4py does not free it)."""
        self.scheme = scheme
        for previous in (self._inertia_damping, self._on_newton_pattern.pop("inertia_damping", None)):
            if previous is not None:
                previous.destroy()
        self._inertia_damping = self.model.inertia.newton_block(scheme.acceleration_factor, scheme.velocity_factor)

    def assemble(self, time, u, v, a) -> PETSc.Mat:
        """S = ∂r_{n+1-α}/∂u_{n+1} = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t at the
        evaluation point (t, u, u̇, ü), with the exact thrust and drag Jacobians."""
        return self._combine(self.scheme, ("inertia_damping", self._inertia_damping), time, u, v, a)

    def tangents(self, time, u, v, a) -> Iterator[PETSc.Mat]:
        """K_t = ∂r/∂u, C_t = ∂r/∂u̇ and M_t = ∂r/∂ü at (t, u, u̇, ü), in that order, each in the
        storage and valid until the next one is made (fixed dofs: unit rows). For use between runs:
        S of the scheme is made anew at its next assembly, and a solver still holding factors of the
        old one would refactorise what the storage holds."""
        model = self.model
        yield self._combine(STIFFNESS, None, time, u, v, a)
        yield self._combine(DAMPING, ("damping", model.damping_matrix), time, u, v, a)
        yield self._combine(MASS, ("mass", model.mass_matrix), time, u, v, a)

    def _combine(self, factors, constant: tuple[str, PETSc.Mat] | None, time, u, v, a) -> PETSc.Mat:
        """k_u K_t + k_v C_t + k_a M_t from the factors' k and ``constant`` = (name, k_a M + k_v C)."""
        model = self.model
        model.set_state(time, u)
        matrix = self.storage
        if factors.stiffness_factor == 0.0:
            matrix.zeroEntries()
        else:
            fx.assemble_matrix_into(matrix, model.tangent_form)
            if factors.stiffness_factor != 1.0:
                matrix.scale(factors.stiffness_factor)
        if model.thrust is not None:
            model.thrust.add_newton_matrix(matrix, factors, u, v, a)
        if model.drag is not None:
            model.drag.add_newton_matrix(matrix, factors.velocity_factor, v)
        matrix.assemble()
        if constant is not None:
            matrix.axpy(1.0, self._stored_on_newton_pattern(*constant),
                        structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        matrix.zeroRowsColumns(model.global_dofs(model.fixed_dofs), diag=1.0)
        return matrix

    def _stored_on_newton_pattern(self, name: str, constant: PETSc.Mat) -> PETSc.Mat:
        """A copy of ``constant`` (kept under ``name``) on the storage's pattern (tangent, thrust and
        drag entries), so that adding it is one pass over the values."""
        if name not in self._on_newton_pattern:
            padded = self.storage.duplicate(copy=False)
            padded.axpy(1.0, constant, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._on_newton_pattern[name] = padded
        return self._on_newton_pattern[name]

    def correction(self, time, u, v, a):
        """x ↦ (S_exact - S) x at the evaluation point, S the assembled matrix: the stations' coupling
        Bᵀ J B and the head-averaged drag, which stay out of the sparse matrix (None for the nodal
        model, whose matrix is exact)."""
        model = self.model
        parts = []
        if model.station_averages is not None and model.thrust is not None:
            parts.append(model.thrust.newton_correction(self.scheme, u, v, a))
        if model.drag is not None:
            parts.append(model.drag.newton_correction(self.scheme.velocity_factor, v))
        parts = [part for part in parts if part is not None]
        if not parts:
            return None
        return lambda x: sum(part(x) for part in parts)

    def coupling_blocks(self, time, u, v, a, dofs: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """The parts of (K_t, C_t, M_t)[dofs, dofs] that :meth:`tangents` leaves out of the matrices
        (the stations' coupling less the lumped added mass, the head-averaged drag), dense, for a small
        region of owned dofs; None for the nodal model."""
        model = self.model
        if model.station_averages is None:
            return None
        blocks = []
        for factors in (STIFFNESS, DAMPING, MASS):
            block = np.zeros((dofs.size, dofs.size))
            if model.thrust is not None:
                block += model.thrust.coupling_block(factors, u, v, a, dofs)
            if model.drag is not None and factors.velocity_factor:
                block += model.drag.coupling_block(factors.velocity_factor, v, dofs)
            fixed = np.isin(dofs, model.fixed_dofs)
            block[fixed, :] = 0.0
            block[:, fixed] = 0.0
            blocks.append(block)
        return tuple(blocks)

    def exact_product(self, time, u, v, a, x: np.ndarray) -> np.ndarray:
        """S_exact x = ∂r_{n+1-α}/∂u_{n+1} x, owned dofs (fixed dofs: identity)."""
        model = self.model
        product = model.matvec(self.assemble(time, u, v, a), x)
        correction = self.correction(time, u, v, a)
        if correction is not None:
            free = x.copy()
            free[model.fixed_dofs] = 0.0
            extra = correction(free)
            extra[model.fixed_dofs] = 0.0
            product = product + extra
        return product

    @property
    def is_symmetric(self) -> bool:
        """With stations the assembled S is symmetric: K_t and M, C are, the lumped added mass
        Σ_i b_ij m̃ ℓ₀ n nᵀ is, and the unsymmetric thrust and drag couplings stay outside it. The nodal
        model puts the thrust's and the drag's Jacobians (unsymmetric) into S."""
        return self.model.station_averages is not None

    def destroy(self) -> None:
        """Release the storage, the step's block k_a M + k_v C and the padded constants."""
        for matrix in (self._storage, self._inertia_damping, *self._on_newton_pattern.values()):
            if matrix is not None:
                matrix.destroy()
        self._storage, self._inertia_damping, self._on_newton_pattern = None, None, {}


class NewtonSolver:
    """The factorisation of S and the solves with it, timed in ``profile``.

    S is factorised by LDLᵀ of its upper triangle when it is symmetric (stations), by LU otherwise.
    With ``[solver] newton_coupling = "krylov"`` and a coupling outside the matrix (stations), the
    solves are GMRES on S_exact of the factorised point, preconditioned by the factors of S; with
    "lumped" they use the factors alone (modified Newton). Owns the KSP, the upper-triangle copy and
    the exact operator (released by :meth:`destroy`).
    """

    def __init__(self, model, matrix: NewtonMatrix):
        self.model, self.matrix = model, matrix
        self.profile = SolveProfile()
        self.ksp: PETSc.KSP | None = None
        self._krylov = False
        self._upper_triangle: PETSc.Mat | None = None
        self._exact_operator: PETSc.Mat | None = None

    def factorize(self, time, u, v, a) -> None:
        """Assemble S at the evaluation point and factorise it."""
        model = self.model
        started = clock.perf_counter()
        matrix = self.matrix.assemble(time, u, v, a)
        correction = (self.matrix.correction(time, u, v, a) if model.scene.solver.newton_coupling == "krylov"
                      else None)
        symmetric = self.matrix.is_symmetric
        if self.ksp is None or (correction is not None) != self._krylov:
            if self.ksp is not None:
                self.ksp.destroy()
            self.ksp = mumps_solver(model.comm, symmetric, krylov=correction is not None)
            self._krylov = correction is not None
        factored = matrix
        if symmetric:
            factored = self._upper_triangle = upper_triangle_copy(matrix, self._upper_triangle)
        if correction is None:
            self.ksp.setOperators(factored)
        else:
            if self._exact_operator is None:
                self._exact_operator = PETSc.Mat().createPython(matrix.getSizes(), ExactNewtonOperator(),
                                                                comm=model.comm)
                self._exact_operator.setUp()
            self._exact_operator.getPythonContext().set(matrix, correction, model.fixed_dofs)
            self.ksp.setOperators(self._exact_operator, factored)
        assembled = clock.perf_counter()
        self.profile.newton_matrix_assembly += assembled - started
        try:
            self.ksp.setUp()
        except PETSc.Error as error:
            raise SolverError(f"linear solve failed in the factorisation (PETSc {error}; "
                              f"{describe_linear_solve(self.ksp)})") from None
        self.profile.factorizations += clock.perf_counter() - assembled
        self.profile.counts["factorizations"] += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """S⁻¹ rhs with the current factors (owned dofs)."""
        started = clock.perf_counter()
        solution = self.model.solve_with(self.ksp, rhs)
        self.profile.solves += clock.perf_counter() - started
        self.profile.counts["solves"] += 1
        return solution

    def status(self) -> str:
        """KSP reason and MUMPS status of the last solve ("" before the first factorisation)."""
        return describe_linear_solve(self.ksp) if self.ksp is not None else ""

    def destroy(self) -> None:
        """Release the KSP (and its factors), the upper-triangle copy and the exact operator."""
        for petsc_object in (self.ksp, self._upper_triangle, self._exact_operator):
            if petsc_object is not None:
                petsc_object.destroy()
        self.ksp = self._upper_triangle = self._exact_operator = None
