"""Galerkin projection on a basis V (SPEC §8) and the Taylor polynomials in ξ of projected forms.

Every reduced vector is Vᵀ b and every reduced matrix Vᵀ A V, summed over the ranks; the ξ-terms
of a form are the projections of its UFL derivatives along the shape directions δξ = e_k
(``FullOrderModel.shape_derivative``) at the design the basis was built on.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.physics.taylor import Taylor, taylor_of


def project_vector(comm: MPI.Comm, vectors: np.ndarray, owned: np.ndarray) -> np.ndarray:
    """Vᵀ b over all ranks; ``owned`` is one owned dof array or its columns."""
    return comm.allreduce(vectors.T @ owned, op=MPI.SUM)


def project_matrix(comm: MPI.Comm, vectors: np.ndarray, apply: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """Vᵀ A V over all ranks; ``apply`` is x ↦ A x on owned dofs."""
    product = np.column_stack([apply(vectors[:, j]) for j in range(vectors.shape[1])])
    return project_vector(comm, vectors, product)


class Projector:
    """Projects the forms of one FOM on the basis V, with their Taylor coefficients in ξ at its design.

    ``order`` is the Taylor order (0 without ξ-terms), ``n_parameters`` the number p of ξ_k.
    """

    def __init__(self, fom, vectors: np.ndarray, n_parameters: int, order: int):
        self.fom, self.vectors = fom, vectors
        self.n_parameters, self.order = n_parameters, order
        self.directions = fom.keep("projection_directions", lambda: [fom.shape_direction(f"projection_direction_{i}")
                                                                     for i in range(2)])[: min(order, 2)]

    def vector(self, owned: np.ndarray) -> np.ndarray:
        return project_vector(self.fom.comm, self.vectors, owned)

    def matrix(self, matrix) -> np.ndarray:
        return project_matrix(self.fom.comm, self.vectors, lambda x: self.fom.matvec(matrix, x))

    def taylor(self, form, transform: Callable | None = None) -> Taylor:
        """Taylor in Δξ of the projected form (scalar, Vᵀ b or Vᵀ A V); ``transform`` acts on the
        assembled matrix before the projection (e.g. lumping)."""
        _, compiled, storage = self.fom.keep(("taylor", id(form), self.order), lambda: self._compiled(form))
        rank = len(form.arguments())

        def project(derivative: int) -> np.ndarray:
            if rank == 0:
                return np.array(fx.assemble_scalar(compiled[derivative], self.fom.comm))
            if rank == 1:
                return self.vector(fx.assemble_vector_into(storage, compiled[derivative]))
            matrix = fx.assemble_matrix_into(storage, compiled[derivative])
            return self.matrix(transform(matrix) if transform else matrix)

        [taylor] = self.taylor_terms(lambda derivative: (project(derivative),))
        return taylor

    def _compiled(self, form) -> tuple:
        """(the form, its compiled ξ-derivatives up to the order, its PETSc storage or None), kept on the
        model (the form with them: its id names them while it lives)."""
        compiled = [fx.compile_form(form)]
        if self.order >= 1:
            first = self.fom.shape_derivative(form, self.directions[0])
            compiled.append(fx.compile_form(first))
        if self.order >= 2:
            compiled.append(fx.compile_form(self.fom.shape_derivative(first, self.directions[1])))
        rank = len(form.arguments())
        storage = fx.create_matrix(compiled[0]) if rank == 2 else fx.create_vector(compiled[0]) if rank == 1 else None
        return form, compiled, storage

    def taylor_terms(self, evaluate: Callable[[int], tuple]) -> list[Taylor]:
        """The Taylor in Δξ of each value of ``evaluate(d)``, a tuple whose entries are the d-th
        ξ-derivatives of the values along the directions as this method sets them (d = 0: the values;
        1: along e_k; 2: along e_k and e_l): :func:`taylor_of`."""
        def along(indices: tuple[int, ...]) -> tuple:
            for direction, k in zip(self.directions, indices):
                direction.set_parameter(k)
            return evaluate(len(indices))
        return taylor_of(along, self.n_parameters, self.order)
