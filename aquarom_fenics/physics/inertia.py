"""Inertia and Rayleigh damping (SPEC §5): M ü + C u̇ with the mass of ``forms/inertia.py`` and

    C = α_R M + β_R K_0,

K_0 the elastic tangent at rest. C is linear in (M, K_0), so ∂C/∂ξ_k = α_R ∂M/∂ξ_k + β_R ∂K_0/∂ξ_k:
:func:`rayleigh_damping` serves both, on PETSc matrices and on numpy arrays. The mass moment
m·u / ∫ρ dV_ξ gives the centre-of-mass x-displacement.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.inertia import mass_density, mass_form, mass_moment_x, mass_moment_y, total_mass
from aquarom_fenics.physics.taylor import Taylor, taylor_of


def linear_combination(a: float, x, b: float, y):
    """a x + b y of numpy arrays."""
    return a * x + b * y


def petsc_linear_combination(a: float, x: PETSc.Mat, b: float, y: PETSc.Mat) -> PETSc.Mat:
    """a x + b y of PETSc matrices, a new matrix on the pattern of x (y's pattern a subset of it).

    Two forms on one function space (M and K_0) have one pattern: then the sum is one pass over the
    values, several times faster than a subset pattern or one PETSc must merge."""
    result = x.copy()
    result.scale(a)
    same = x.getInfo()["nz_allocated"] == y.getInfo()["nz_allocated"] and x.getSizes() == y.getSizes()
    result.axpy(b, y, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN if same
                else PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    return result


def rayleigh_damping(alpha: float, mass, beta: float, stiffness, combine=linear_combination):
    """C = α_R M + β_R K_0 (or ∂C/∂ξ_k from ∂M/∂ξ_k, ∂K_0/∂ξ_k); ``combine`` is (a, x, b, y) ↦ a x + b y."""
    return combine(alpha, mass, beta, stiffness)


def lump(matrix: PETSc.Mat) -> PETSc.Mat:
    """Row sums on the diagonal, in place (the lumped mass of ``material.mass = "lumped"``)."""
    row_sums = matrix.getRowSum()
    matrix.zeroEntries()
    matrix.setDiagonal(row_sums)
    matrix.assemble()
    return matrix


class InertiaTerm:
    """Mass and Rayleigh damping matrices of one FOM, its mass moment and total mass."""

    def __init__(self, fom, rest_stiffness: PETSc.Mat):
        self.fom = fom
        material = fom.scene.material
        self.alpha, self.beta = material.rayleigh_alpha, material.rayleigh_beta
        self.lumped = material.mass == "lumped"
        density = self.density = fx.constant(fom.mesh, material.density)
        shape_gradient = fom.shape_gradients["mass"]
        test, trial = fom.test_function, fom.trial_function
        self.mass_form = fom.mass_rule(mass_form(trial, test, shape_gradient, density))
        self.mass_moment_form = fom.mass_rule(mass_moment_x(test, shape_gradient, density))
        self.mass_moment_y_form = fom.mass_rule(mass_moment_y(test, shape_gradient, density))
        self.total_mass_form = fom.mass_rule(total_mass(shape_gradient, density, fom.mesh))
        self._compiled = [fx.compile_form(form) for form in (self.mass_form, self.mass_moment_form, self.total_mass_form,
                                                                 self.mass_moment_y_form)]
        self.mass_matrix = fx.create_matrix(self._compiled[0])
        self._moment_vector = fx.create_vector(self._compiled[1])
        self._moment_y_vector = fx.create_vector(self._compiled[3])
        self.damping_matrix = None
        self.assemble(rest_stiffness)

    def assemble(self, rest_stiffness: PETSc.Mat) -> None:
        """M and C = α_R M + β_R K_0 at the FOM's design (again after the design moved); the mass moments
        and the total mass at their first use."""
        fx.assemble_matrix_into(self.mass_matrix, self._compiled[0])
        if self.lumped:
            lump(self.mass_matrix)
        if self.damping_matrix is not None:
            self.damping_matrix.destroy()
        self.damping_matrix = rayleigh_damping(self.alpha, self.mass_matrix, self.beta, rest_stiffness,
                                               petsc_linear_combination)
        self._observed = {}

    # The moments and the total mass serve the FOM's centre of mass; a PROM build samples its own
    # (``sampled_inertia``): each is assembled at its first use after the design moved. Every rank
    # asks for them together (the observations are collective), so the assembly stays collective.
    @property
    def mass_moment_x(self) -> np.ndarray:
        """m_x,i = ∫ρ φ_i·e_x dV_ξ (owned dofs) [kg]."""
        return self._observe("moment_x", lambda: fx.assemble_vector_into(self._moment_vector, self._compiled[1]).copy())

    @property
    def mass_moment_y(self) -> np.ndarray:
        """m_y,i = ∫ρ φ_i·e_y dV_ξ (owned dofs) [kg]."""
        return self._observe("moment_y", lambda: fx.assemble_vector_into(self._moment_y_vector, self._compiled[3]).copy())

    @property
    def total_mass(self) -> float:
        """∫ρ dV_ξ [kg]."""
        return self._observe("total", lambda: fx.assemble_scalar(self._compiled[2], self.fom.comm))

    def _observe(self, name: str, assemble):
        if name not in self._observed:
            self._observed[name] = assemble()
        return self._observed[name]

    def destroy(self) -> None:
        """Release the mass and damping matrices."""
        for petsc_object in (self.mass_matrix, self.damping_matrix, self._moment_vector, self._moment_y_vector):
            petsc_object.destroy()

    def newton_block(self, acceleration_factor: float, velocity_factor: float) -> PETSc.Mat:
        """k_a M + k_v C, the inertia and damping part of the Newton matrix."""
        return petsc_linear_combination(acceleration_factor, self.mass_matrix, velocity_factor, self.damping_matrix)

    def reduce(self, projector) -> "InertiaTensors":
        if self.lumped:     # row sums of M: projected from the assembled matrix
            return InertiaTensors(projector.taylor(self.mass_form, transform=lump), self.alpha, self.beta,
                                  projector.taylor(self.mass_moment_form), projector.taylor(self.total_mass_form),
                                  projector.taylor(self.mass_moment_y_form))
        mass, moment, total, moment_y = sampled_inertia(self.fom, projector, self.density)
        return InertiaTensors(mass, self.alpha, self.beta, moment, total, moment_y)


def sampled_inertia(fom, projector, density) -> tuple[Taylor, Taylor, Taylor, Taylor]:
    """Vᵀ M V, Vᵀ m_x, ∫ρ dV_ξ and Vᵀ m_y with their Taylor terms in ξ, as the quadrature sums of the mass forms:

        Vᵀ M V = Σ_s w_s ρ_s V(x_s)ᵀ V(x_s),   Vᵀ m_x = Σ_s w_s ρ_s V_x(x_s),   ∫ρ dV_ξ = Σ_s w_s ρ_s,
        Vᵀ m_y = Σ_s w_s ρ_s V_y(x_s),

    ρ_s = ρ det F_1 (``mass_density`` of ``forms/inertia.py``) and w_s = ω_q |det J_c| at the points
    of the FOM's mass rule. Only ρ_s depends on ξ: its UFL derivatives along every parameter's direction (and
    pair of them at Taylor order 2) are one stacked expression, evaluated point by point
    (``fx.evaluate_point_by_point``), with the basis evaluated once, the route of the internal force and the
    muscles. The same sums as the assembled forms projected, to rounding, in a fraction of their time.
    """
    mesh, comm = fom.mesh, fom.comm
    degree = fom.quadrature_degrees["mass"]
    cells = fx.owned_cells(mesh)
    reference_weights = fx.quadrature_rule(degree)[1]
    n_samples = cells.size * reference_weights.size
    vectors = projector.vectors
    p = projector.n_parameters if projector.order >= 1 else 0
    indices = [()] + [(k,) for k in range(p)] + ([(k, l) for k in range(p) for l in range(k, p)]
                                                  if projector.order >= 2 else [])

    def compile_sampling():        # kept on the model: the sample's field, its values, ρ_s and its ξ-derivatives
        field = fx.new_function(fom.space, "inertia_sample")
        # ρ_s and its derivatives along the directions ∇U_k, of fields held at one point per cell: they are
        # evaluated point by point (``evaluate_point_by_point``), the same values as at the rule's points
        gradient, *directions = [fx.new_function(fx.point_tensor_space(mesh), f"inertia_{name}")
                                 for name in ["gradient"] + [f"direction_{k}" for k in range(p)]]
        derivatives = {(): abs(ufl.JacobianDeterminant(mesh)) * mass_density(gradient, density)}
        for index in indices[1:]:
            derivatives[index] = ufl.derivative(derivatives[index[:-1]], gradient, directions[index[-1]])
        stacked = fx.compile_point_expression(ufl.as_vector([derivatives[index] for index in indices]),
                                              [gradient] + directions)
        return field, fx.compile_quadrature_expression(field, degree), stacked, [gradient] + directions

    field, at_points, stacked, point_fields = fom.keep(("inertia_sampling", p, projector.order), compile_sampling)
    values = np.empty((n_samples, 3, vectors.shape[1]))
    for j in range(vectors.shape[1]):
        fx.set_owned_values(field, vectors[:, j])
        values[:, :, j] = fx.evaluate_expression(at_points, cells).reshape(n_samples, 3)
    point_values = [fx.quadrature_values(fom.shape_gradients["mass"])] + [
        fom.shape_direction_gradient("mass", k).reshape(-1, reference_weights.size, 3, 3) for k in range(p)]
    weights = (fx.evaluate_point_by_point(stacked, point_fields, point_values, cells)
               * reference_weights[:, None]).reshape(n_samples, len(indices))
    column = {index: n for n, index in enumerate(indices)}
    m = vectors.shape[1]
    products = np.matmul(values.transpose(0, 2, 1), values).reshape(n_samples, m * m)      # V(x_s)ᵀ V(x_s)
    local = (weights.T @ products, weights.T @ values[:, 0, :], weights.sum(axis=0), weights.T @ values[:, 1, :])
    mass, moment_x, total, moment_y = (comm.allreduce(part, op=MPI.SUM) for part in local)

    def sums(index: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = column[index]
        return mass[n].reshape(m, m), moment_x[n], np.array(total[n]), moment_y[n]

    return tuple(taylor_of(sums, p, projector.order))


@dataclass
class InertiaTensors:
    """The reduced inertia M_r η̈ + C_r η̇, C_r = α_R M_r + β_R K1 (K1 of the elastic tensors)."""

    mass: Taylor                         # M_r (m, m)
    rayleigh_alpha: float                # α_R [1/s]
    rayleigh_beta: float                 # β_R [s]
    mass_moment_x: Taylor                # Vᵀ ∫ρ φ·e_x dV_ξ (m,)
    total_mass: Taylor                   # ∫ρ dV_ξ ()
    mass_moment_y: Taylor                # Vᵀ ∫ρ φ·e_y dV_ξ (m,)

    def at(self, delta: np.ndarray, rest_stiffness: Taylor, rest_stiffness_value: np.ndarray) -> "ReducedInertia":
        """At Δξ, with the Taylor of K_0,r and its value at Δξ."""
        return ReducedInertia(self, delta, rest_stiffness, rest_stiffness_value)

    @property
    def rayleigh(self) -> tuple[float, float]:
        """(α_R, β_R) of C_r = α_R M_r + β_R K1."""
        return self.rayleigh_alpha, self.rayleigh_beta

    def damping(self, mass, rest_stiffness):
        """C_r = α_R M_r + β_R K1 (or ∂C_r/∂ξ_k from ∂M_r/∂ξ_k, ∂K1/∂ξ_k), of arrays with any leading axes."""
        return rayleigh_damping(self.rayleigh_alpha, mass, self.rayleigh_beta, rest_stiffness)


class ReducedInertia:
    """The reduced inertia and damping at one design ξ (a :class:`ReducedTerm`)."""

    def __init__(self, tensors: InertiaTensors, delta: np.ndarray, rest_stiffness: Taylor,
                 rest_stiffness_value: np.ndarray):
        self.tensors, self.delta, self.rest_stiffness = tensors, delta, rest_stiffness
        self.mass = tensors.mass.at(delta)
        self.damping = rayleigh_damping(tensors.rayleigh_alpha, self.mass, tensors.rayleigh_beta, rest_stiffness_value)
        self.total_mass = float(tensors.total_mass.at(delta))
        self.com_weights = tensors.mass_moment_x.at(delta) / self.total_mass
        self.com_y_weights = tensors.mass_moment_y.at(delta) / self.total_mass
        self.mass_gradient = tensors.mass.gradient(delta)                       # ∂M_r/∂ξ_k, (p, m, m)
        self.damping_gradient = rayleigh_damping(tensors.rayleigh_alpha, self.mass_gradient, tensors.rayleigh_beta,
                                                 rest_stiffness.gradient(delta))     # ∂C_r/∂ξ_k

    def tangents(self, time, eta, eta_dot, eta_ddot):
        return None, self.damping, self.mass

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """∂M_r/∂ξ_k η̈ + ∂C_r/∂ξ_k η̇, shape (p, m)."""
        return self.mass_gradient @ eta_ddot + self.damping_gradient @ eta_dot

    def com_weights_gradient(self) -> np.ndarray:
        """∂c/∂ξ_k of com_x = c(ξ)·η, c = n(ξ)/mass(ξ): (∂n/∂ξ_k - c ∂mass/∂ξ_k) / mass, shape (p, m)."""
        tensors = self.tensors
        if tensors.mass_moment_x.first is None:
            return np.zeros((self.delta.size, self.com_weights.size))
        return (tensors.mass_moment_x.gradient(self.delta)
                - np.outer(tensors.total_mass.gradient(self.delta), self.com_weights)) / self.total_mass
