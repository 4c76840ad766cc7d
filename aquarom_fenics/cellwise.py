"""Reduced internal-force tensors by sampling the SVK forms cell by cell (SPEC §8).

On linear tetrahedra the displacement gradient is constant per cell, so the strain of u = V η is,
per cell c, a quadratic polynomial of η:

    E_c(η) = Σ_j e_cj η_j + ½ Σ_jk q_cjk η_j η_k,

and the energy density ψ(E) = ½ E:ℂ_c:E is a quadratic form of E. The coefficients e, q are
obtained by evaluating the UFL strain of ``forms/`` at the cell midpoints for u = ±V_j and
u = V_j + V_k, and ℂ_c by evaluating the UFL energy density at unit strains: the physics stays in
the forms, this module only samples and contracts. With weights w_c = |cell| det F_1,

    Π(η) = ½ P2(η,η) + ½ P3(η,η,η) + ⅛ P4(η,η,η,η),
    P2_ij = Σ_c w_c e_ci:ℂ_c:e_cj,  P3_ijk = Σ_c w_c e_ci:ℂ_c:q_cjk,  P4_ijkl = Σ_c w_c q_cij:ℂ_c:q_ckl.

ξ-derivatives (Taylor terms) come from the UFL derivatives of the same expressions with respect
to the shape displacement u_ξ in the directions U_k.
"""
from __future__ import annotations

import itertools

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from . import dolfinx_adapter as fx
from .forms.elasticity import svk_energy_density
from .forms.kinematics import green_lagrange_strain, volume_ratio

MIDPOINT = np.array([[0.25, 0.25, 0.25]])

# Orthonormal basis of symmetric 3×3 tensors: E = Σ_a s_a B_a with s_a = E:B_a.
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
SYMMETRIC_BASIS = np.zeros((6, 3, 3))
for _a, (_i, _j) in enumerate(_PAIRS):
    SYMMETRIC_BASIS[_a, _i, _j] = SYMMETRIC_BASIS[_a, _j, _i] = 1.0 if _i == _j else 1.0 / np.sqrt(2.0)


def symmetric_coordinates(tensors: np.ndarray) -> np.ndarray:
    """(..., 9) row-major 3×3 tensors → (..., 6) coordinates s_a = E:B_a."""
    return tensors @ SYMMETRIC_BASIS.reshape(6, 9).T


class CellSampler:
    """Compiled midpoint expressions of the strain, its ξ-derivatives, the weight and ψ."""

    def __init__(self, fom, taylor_order: int):
        self.fom = fom
        self.cells = np.arange(fom.mesh.topology.index_map(3).size_local, dtype=np.int32)
        self.direction = fx.new_function(fom.space, "direction")
        self.shape_directions = [fx.new_function(fom.space, f"shape_direction_{i}") for i in range(2)]
        u_xi = fom.shape_displacement
        strain = green_lagrange_strain(self.direction, u_xi)
        weight = abs(ufl.JacobianDeterminant(fom.mesh)) / 6.0 * volume_ratio(u_xi)
        self.strain = [self._compile(strain)]
        self.weight = [self._compile(weight)]
        first_strain = ufl.derivative(strain, u_xi, self.shape_directions[0])
        first_weight = ufl.derivative(weight, u_xi, self.shape_directions[0])
        if taylor_order >= 1:
            self.strain.append(self._compile(first_strain))
            self.weight.append(self._compile(first_weight))
        if taylor_order >= 2:
            self.strain.append(self._compile(ufl.derivative(first_strain, u_xi, self.shape_directions[1])))
            self.weight.append(self._compile(ufl.derivative(first_weight, u_xi, self.shape_directions[1])))
        self.unit_strain = fem.Constant(fom.mesh, np.zeros((3, 3)))
        self.energy_density = self._compile(svk_energy_density(
            self.unit_strain, fom.young_modulus, fx.constant(fom.mesh, fom.scene.material.poisson_ratio)))

    def _compile(self, expression):
        import logging

        logging.disable(logging.INFO)
        try:
            return fem.Expression(expression, MIDPOINT)
        finally:
            logging.disable(logging.NOTSET)

    def evaluate(self, expression) -> np.ndarray:
        return expression.eval(self.cells)

    def set_shape_directions(self, *fields) -> None:
        for function, owned in zip(self.shape_directions, fields):
            fx.set_owned_values(function, owned)

    def elasticity(self) -> np.ndarray:
        """ℂ_c in symmetric coordinates, (n_cells, 6, 6): ψ(s) = ½ sᵀ ℂ_c s."""
        def density(tensor):
            self.unit_strain.value = tensor
            return self.evaluate(self.energy_density)[:, 0]

        single = [density(SYMMETRIC_BASIS[a]) for a in range(6)]
        moduli = np.empty((self.cells.size, 6, 6))
        for a in range(6):
            moduli[:, a, a] = 2.0 * single[a]
            for b in range(a + 1, 6):
                moduli[:, a, b] = moduli[:, b, a] = density(SYMMETRIC_BASIS[a] + SYMMETRIC_BASIS[b]) - single[a] - single[b]
        return moduli

    def strain_coefficients(self, vectors: np.ndarray, expression) -> tuple[np.ndarray, np.ndarray]:
        """(e, q) of E(V η) = e η + ½ q η η: shapes (n_cells, m, 6) and (n_cells, m, m, 6).

        Sampled at u = ±V_j and u = V_j + V_k; exact because E is quadratic in u (also for the
        ξ-derivative expressions, which are quadratic in u as well).
        """
        m = vectors.shape[1]

        def strain_of(owned):
            fx.set_owned_values(self.direction, owned)
            return symmetric_coordinates(self.evaluate(expression))

        plus = [strain_of(vectors[:, j]) for j in range(m)]
        minus = [strain_of(-vectors[:, j]) for j in range(m)]
        linear = np.stack([(p - n) / 2.0 for p, n in zip(plus, minus)], axis=1)
        quadratic = np.empty((self.cells.size, m, m, 6))
        for j in range(m):
            quadratic[:, j, j] = plus[j] + minus[j]
        for j, k in itertools.combinations(range(m), 2):
            both = strain_of(vectors[:, j] + vectors[:, k])
            mixed = both - linear[:, j] - linear[:, k] - 0.5 * (quadratic[:, j, j] + quadratic[:, k, k])
            quadratic[:, j, k] = quadratic[:, k, j] = mixed
        return linear, quadratic


def energy_tensors(weight, moduli, linear, quadratic):
    """(P2, P3, P4) = Σ_c w (e·ℂ·e, e·ℂ·q, q·ℂ·q) for one set of factors (local cells only)."""
    m = linear.shape[1]
    weighted_moduli = weight[:, None, None] * moduli
    stressed_linear = np.einsum("cab,cjb->cja", weighted_moduli, linear)            # (c, m, 6)
    stressed_quadratic = np.einsum("cab,cjkb->cjka", weighted_moduli, quadratic)    # (c, m, m, 6)
    p2 = np.einsum("cia,cja->ij", linear, stressed_linear)
    p3 = np.einsum("cia,cjka->ijk", linear, stressed_quadratic)
    flat_q = quadratic.transpose(1, 2, 0, 3).reshape(m * m, -1)
    flat_stressed = stressed_quadratic.transpose(1, 2, 0, 3).reshape(m * m, -1)
    p4 = (flat_q @ flat_stressed.T).reshape(m, m, m, m)
    return p2, p3, p4


def force_tensors(p2, p3, p4):
    """Symmetric force tensors of f(η) = ∂Π/∂η = K1 η + K2 η η + K3 η η η."""
    p3_sym = (p3 + p3.transpose(1, 0, 2) + p3.transpose(1, 2, 0)) / 3.0   # T_ijk + T_jik + T_kij
    p4_sym = (p4 + p4.transpose(0, 2, 1, 3) + p4.transpose(0, 3, 2, 1)) / 3.0
    return p2, 1.5 * p3_sym, 0.5 * p4_sym


def _product_terms(factors_by_order, derivative_indices):
    """Leibniz rule: every way to distribute the ξ-derivative indices among the three factors."""
    count = len(derivative_indices)
    for assignment in itertools.product(range(3), repeat=count):
        picked = [tuple(derivative_indices[i] for i in range(count) if assignment[i] == slot) for slot in range(3)]
        yield [factors_by_order[slot](indices) for slot, indices in enumerate(picked)]


def internal_force_taylor(sampler: CellSampler, vectors: np.ndarray, shape_fields: list[np.ndarray],
                          order: int, comm: MPI.Comm):
    """Taylor coefficients in Δξ of (K1, K2, K3): lists [constant, first (p, ...), second (p, p, ...)]."""
    moduli = sampler.elasticity()
    weight0 = sampler.evaluate(sampler.weight[0])[:, 0]
    strain0 = sampler.strain_coefficients(vectors, sampler.strain[0])
    p = len(shape_fields) if order >= 1 else 0
    first_strain, first_weight = [], []
    for k in range(p):
        sampler.set_shape_directions(shape_fields[k])
        first_strain.append(sampler.strain_coefficients(vectors, sampler.strain[1]))
        first_weight.append(sampler.evaluate(sampler.weight[1])[:, 0])

    def weight(indices):
        if not indices:
            return weight0
        if len(indices) == 1:
            return first_weight[indices[0]]
        sampler.set_shape_directions(*(shape_fields[i] for i in indices))
        return sampler.evaluate(sampler.weight[2])[:, 0]

    def strain(indices):
        if not indices:
            return strain0
        if len(indices) == 1:
            return first_strain[indices[0]]
        sampler.set_shape_directions(*(shape_fields[i] for i in indices))
        return sampler.strain_coefficients(vectors, sampler.strain[2])

    def tensors_for(derivative_indices):
        total = None
        factors = (weight, strain, strain)
        for w, (e_left, q_left), (e_right, q_right) in _product_terms(factors, derivative_indices):
            contribution = _mixed_energy_tensors(w, moduli, e_left, q_left, e_right, q_right)
            total = contribution if total is None else tuple(a + b for a, b in zip(total, contribution))
        total = tuple(comm.allreduce(t, op=MPI.SUM) for t in total)
        return force_tensors(*total)

    constant = tensors_for(())
    taylor = [constant]
    if p:
        taylor.append(tuple(np.stack(t) for t in zip(*(tensors_for((k,)) for k in range(p)))))
    if order >= 2 and p:
        second = [[tensors_for((k, l)) for l in range(p)] for k in range(p)]
        taylor.append(tuple(np.stack([np.stack([second[k][l][i] for l in range(p)]) for k in range(p)])
                            for i in range(3)))
    return taylor


def _mixed_energy_tensors(weight, moduli, e_left, q_left, e_right, q_right):
    """Σ_c w (e_l·ℂ·e_r, ½(e_l·ℂ·q_r + e_r·ℂ·q_l), q_l·ℂ·q_r) symmetrised in the two strain factors.

    With identical left and right factors this is :func:`energy_tensors`; the Leibniz terms of the
    ξ-derivatives use different ones (the factor ψ = ½ E:ℂ:E is bilinear in its two strains).
    """
    if e_left is e_right:
        return energy_tensors(weight, moduli, e_left, q_left)
    m = e_left.shape[1]
    weighted_moduli = weight[:, None, None] * moduli
    stressed_e_right = np.einsum("cab,cjb->cja", weighted_moduli, e_right)
    stressed_q_right = np.einsum("cab,cjkb->cjka", weighted_moduli, q_right)
    stressed_q_left = np.einsum("cab,cjkb->cjka", weighted_moduli, q_left)
    p2 = np.einsum("cia,cja->ij", e_left, stressed_e_right)
    p2 = 0.5 * (p2 + p2.T)
    p3 = 0.5 * (np.einsum("cia,cjka->ijk", e_left, stressed_q_right)
                + np.einsum("cia,cjka->ijk", e_right, stressed_q_left))
    flat_left = q_left.transpose(1, 2, 0, 3).reshape(m * m, -1)
    flat_stressed_right = stressed_q_right.transpose(1, 2, 0, 3).reshape(m * m, -1)
    p4 = (flat_left @ flat_stressed_right.T).reshape(m, m, m, m)
    p4 = 0.5 * (p4 + p4.transpose(2, 3, 0, 1))
    return p2, p3, p4
