"""Elastic force (SPEC §5): f_int = ∂Π/∂u of the energy of ``forms/elasticity.py`` (the scene's
``[material] law``: Saint Venant-Kirchhoff, or Neo-Hookean on the FOM).

On the FOM the energy is assembled as a UFL form; its reduction samples the same forms at the
quadrature points (``fem/cellwise.py``, SPEC §8) into the force tensors of

    f_int,r(η) = K1 η + K2 η η + K3 η η η,   K_t,r = K1 + 2 K2 η + 3 K3 η η.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import ufl
from petsc4py import PETSc

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.cellwise import CellSampler, internal_force_taylor
from aquarom_fenics.forms.elasticity import strain_energy
from aquarom_fenics.physics.taylor import Taylor


class ElasticTerm:
    """The elastic energy of one FOM (stiffer head cells), its force and tangent forms."""

    def __init__(self, fom):
        self.fom = fom
        material = fom.scene.material
        stiffness_by_cell = np.full(fom.n_cells, material.young_modulus)
        stiffness_by_cell[fom.fish.tags.head_cells] *= material.head_stiffness_factor
        self.young_modulus = fom.cell_field(stiffness_by_cell, "young_modulus")
        self.poisson_ratio = fx.constant(fom.mesh, material.poisson_ratio)
        u = fom.displacement
        self.law = material.law
        self.energy_form = fom.stiffness_rule(strain_energy(u, fom.shape_gradients["stiffness"],
                                                            self.young_modulus, self.poisson_ratio, self.law))
        self.force_form = ufl.derivative(self.energy_form, u, fom.test_function)
        self.tangent_form = ufl.derivative(self.force_form, u, fom.trial_function)
        self._energy = fx.compile_form(self.energy_form)
        self._force = fx.compile_form(self.force_form)
        self._vector = fx.create_vector(self._force)
        self._tangent = None

    def destroy(self) -> None:
        """Release the force's PETSc vector."""
        self._vector.destroy()

    def force(self) -> np.ndarray:
        """f_int at the FOM's displacement, owned entries [N]."""
        return fx.assemble_vector_into(self._vector, self._force).copy()

    def energy(self) -> float:
        """Π at the FOM's displacement [J]."""
        return fx.assemble_scalar(self._energy, self.fom.comm)

    def rest_stiffness(self, into: PETSc.Mat | None = None) -> PETSc.Mat:
        """K_0 = ∂f_int/∂u at u = 0 (no boundary conditions), assembled into ``into`` when given (a
        matrix of this tangent's pattern), else into a new matrix."""
        self.fom.set_displacement(np.zeros(self.fom.n_owned_dofs))
        if self._tangent is None:
            self._tangent = fx.compile_form(self.tangent_form)
        return fx.assemble_matrix_into(into or fx.create_matrix(self._tangent), self._tangent)

    def reduce(self, projector, head_only: bool = False) -> "ElasticTensors":
        """(K1, K2, K3) on the projector's basis with their Taylor terms in ξ, sampled at the quadrature points;
        with ``head_only`` the head cells' share alone (the sums restricted to their samples, dx(head)): the
        tensors are linear in each cell's modulus, so at a head factor h the total is
        rest + (h / h_0) head = total + (h / h_0 - 1) head, h_0 the scene's."""
        sampler = self.fom.keep(("cell_sampler", projector.order, projector.n_parameters),
                                lambda: CellSampler(self.fom, projector.order, projector.n_parameters))
        samples = None
        if head_only:
            head = np.isin(sampler.cells, fx.owned_cells_among(self.fom.mesh, self.fom.fish.tags.head_cells))
            samples = np.repeat(head, sampler.reference_weights.size)
        taylor = internal_force_taylor(sampler, projector.vectors, projector.n_parameters, projector.order,
                                       self.fom.comm, samples)
        terms = list(taylor) + [None] * (3 - len(taylor))     # (constant, first, second), each (K1, K2, K3)
        return ElasticTensors(*(Taylor(*(term[i] if term is not None else None for term in terms))
                                for i in range(3)))


@dataclass
class ElasticTensors:
    """The reduced internal force f_int,r(η) = K1 η + K2 η η + K3 η η η (symmetric tensors)."""

    linear: Taylor                       # K1 (m, m); also K_0,r of the Rayleigh damping
    quadratic: Taylor                    # K2 (m, m, m)
    cubic: Taylor                        # K3 (m, m, m, m)

    def at(self, delta: np.ndarray) -> "ReducedElastic":
        return ReducedElastic(self, delta)


class ReducedElastic:
    """The reduced internal force at one design ξ (a :class:`ReducedTerm`).

    The tensors are contracted with η as matrices, K2 as (m², m) and K3 as (m³, m); the contractions
    K2 η and K3 η η of the last η are kept for the tangent at the same point.
    """

    def __init__(self, tensors: ElasticTensors, delta: np.ndarray):
        self.tensors, self.delta = tensors, delta
        self.k1, self.k2, self.k3 = (t.at(delta) for t in (tensors.linear, tensors.quadratic, tensors.cubic))
        m = self.k1.shape[0]
        self._k2_rows, self._k3_rows = self.k2.reshape(-1, m), self.k3.reshape(-1, m)
        self._eta, self._contractions = None, None

    def contractions(self, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K2 η, K3 η η), each (m, m)."""
        key = eta.tobytes()
        if key != self._eta:
            m = eta.size
            k2_eta = (self._k2_rows @ eta).reshape(m, m)
            k3_eta_eta = ((self._k3_rows @ eta).reshape(-1, m) @ eta).reshape(m, m)
            self._eta, self._contractions = key, (k2_eta, k3_eta_eta)
        return self._contractions

    def force(self, eta: np.ndarray) -> np.ndarray:
        """K1 η + K2 η η + K3 η η η."""
        k2_eta, k3_eta_eta = self.contractions(eta)
        return self.k1 @ eta + k2_eta @ eta + k3_eta_eta @ eta

    def tangent(self, eta: np.ndarray) -> np.ndarray:
        """K1 + 2 K2 η + 3 K3 η η."""
        k2_eta, k3_eta_eta = self.contractions(eta)
        return self.k1 + 2.0 * k2_eta + 3.0 * k3_eta_eta

    def tangents(self, time, eta, eta_dot, eta_ddot):
        return self.tangent(eta), None, None

    @cached_property
    def gradients(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(∂K1/∂ξ_k, ∂K2/∂ξ_k, ∂K3/∂ξ_k) at this design, each with a leading axis k of length p."""
        return tuple(t.gradient(self.delta) for t in (self.tensors.linear, self.tensors.quadratic, self.tensors.cubic))

    @cached_property
    def _gradient_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gradients as matrices on η's index: (p m, m), (p m², m), (p m³, m)."""
        m = self.k1.shape[0]
        return tuple(gradient.reshape(-1, m) for gradient in self.gradients)

    def force_gradient(self, eta: np.ndarray) -> np.ndarray:
        """∂f_int,r/∂ξ_k = K1_k η + K2_k η η + K3_k η η η, shape (p, m) (contracted one η at a time)."""
        m = eta.size
        k1_k, k2_k, k3_k = self._gradient_rows
        linear = k1_k @ eta
        quadratic = (k2_k @ eta).reshape(-1, m) @ eta
        cubic = ((k3_k @ eta).reshape(-1, m) @ eta).reshape(-1, m) @ eta
        return (linear + quadratic + cubic).reshape(-1, m)

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        return self.force_gradient(eta)
