"""Reduced internal-force tensors by sampling the SVK forms point by point (SPEC §8).

The FOM integrates the elastic energy with a quadrature rule: Π = Σ_c Σ_q w_cq ψ(E_cq), with
w_cq = |det J_c| ω_q det F_1(x_cq) (ω_q the reference weights). At every quadrature point c, q
(a "sample" s below) the strain of u = V η is a quadratic polynomial of η:

    E_s(η) = Σ_j e_sj η_j + ½ Σ_jk q_sjk η_j η_k,

and the energy density ψ(E) = ½ E:ℂ_s:E is a quadratic form of E (the SVK law; of a Neo-Hookean
scene its second-order expansion at E = 0, ``small_strain_energy_density``, so that its reduced
model is SVK's: exact for SVK only). The strain is E = ½ (H + Hᵀ + Hᵀ H) with H = ∇u F_1⁻¹ linear
in u (``forms/kinematics.py``), so that with H_j the relative displacement gradient of V_j

    e_sj = ½ (H_j + H_jᵀ),   q_sjk = ½ (H_jᵀ H_k + H_kᵀ H_j):

H_j and its ξ-derivatives are evaluated from the UFL form of ``forms/`` at the quadrature points,
one evaluation per basis vector, and ℂ_s by evaluating the UFL energy density at unit strains.
Sampling at the FOM's own quadrature points with its weights makes the reduced energy equal the
FOM's quadrature sum exactly:

    Π(η) = ½ P2(η,η) + ½ P3(η,η,η) + ⅛ P4(η,η,η,η),
    P2_ij = Σ_s w_s e_si:ℂ_s:e_sj,  P3_ijk = Σ_s w_s e_si:ℂ_s:q_sjk,  P4_ijkl = Σ_s w_s q_sij:ℂ_s:q_skl.

ξ-derivatives (Taylor terms) come from the UFL derivatives of H with respect to the shape gradient
∇u_ξ in the directions ∇U_k (``FullOrderModel.shape_derivative``), combined by Leibniz' rule
(:func:`strain_coefficients`).
"""
from __future__ import annotations

import itertools

import numpy as np
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.elasticity import small_strain_energy_density
from aquarom_fenics.forms.kinematics import relative_displacement_gradient, volume_ratio

# Orthonormal basis of symmetric 3×3 tensors: E = Σ_a s_a B_a with s_a = E:B_a.
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
SYMMETRIC_BASIS = np.zeros((6, 3, 3))
for _a, (_i, _j) in enumerate(_PAIRS):
    SYMMETRIC_BASIS[_a, _i, _j] = SYMMETRIC_BASIS[_a, _j, _i] = 1.0 if _i == _j else 1.0 / np.sqrt(2.0)


_TO_SYMMETRIC = np.ascontiguousarray(SYMMETRIC_BASIS.reshape(6, 9).T)   # contiguous: a fast matmul


def symmetric_coordinates(tensors: np.ndarray) -> np.ndarray:
    """(..., 9) row-major 3×3 tensors → (..., 6) coordinates s_a = E:B_a."""
    return tensors @ _TO_SYMMETRIC


class CellSampler:
    """Compiled expressions of the relative displacement gradient H = ∇u F_1⁻¹, its ξ-derivatives, the
    weight and ψ at the quadrature points of the FOM's elastic energy; every array has one row per
    (owned cell, point).

    H and its ξ-derivatives (along every e_k; at Taylor order 2 also along every pair e_k, e_l, k ≤ l)
    are one stacked expression: each basis vector costs one evaluation for all of them."""

    def __init__(self, fom, taylor_order: int, n_parameters: int):
        self.fom = fom
        self.cells = fx.owned_cells(fom.mesh)
        self.degree = fom.quadrature_degrees["stiffness"]
        self.reference_weights = fx.quadrature_rule(self.degree)[1]
        self.n_samples = self.cells.size * self.reference_weights.size
        self.direction = fx.new_function(fom.space, "direction")
        self.shape_directions = [fom.shape_direction(f"shape_direction_{i}") for i in range(2)]
        shape_gradient = fom.shape_gradients["stiffness"]
        weight = abs(ufl.JacobianDeterminant(fom.mesh)) * volume_ratio(shape_gradient)
        self.weight = [self._compile(weight)]
        first_weight = fom.shape_derivative(weight, self.shape_directions[0])
        if taylor_order >= 1:
            self.weight.append(self._compile(first_weight))
        if taylor_order >= 2:
            self.weight.append(self._compile(fom.shape_derivative(first_weight, self.shape_directions[1])))
        self.parameter_directions = []
        for k in range(n_parameters if taylor_order >= 1 else 0):
            self.parameter_directions.append(fom.shape_direction(f"parameter_direction_{k}"))
            self.parameter_directions[k].set_parameter(k)
        p = len(self.parameter_directions)
        gradient = relative_displacement_gradient(self.direction, shape_gradient)
        derivatives = {(): gradient}
        for k, direction in enumerate(self.parameter_directions):
            derivatives[k,] = fom.shape_derivative(gradient, direction)
        for k, l in (pair_list(p) if taylor_order >= 2 else []):
            derivatives[k, l] = fom.shape_derivative(derivatives[k,], self.parameter_directions[l])
        self.strain_indices = list(derivatives)
        """The ξ-derivatives of the strain the sampler gives: (), (k,) and, at order 2, (k, l) with k ≤ l."""
        self.gradients = self._compile(ufl.as_vector([value for indices in self.strain_indices
                                                      for value in _flat(derivatives[indices])]))
        self.unit_strain = fx.tensor_constant(fom.mesh, (3, 3))
        self._moduli = None
        self.energy_density = self._compile(small_strain_energy_density(
            fom.elastic.law, self.unit_strain, fom.elastic.young_modulus, fom.elastic.poisson_ratio))

    def _compile(self, expression):
        return fx.compile_quadrature_expression(expression, self.degree)

    def evaluate(self, expression, value_size: int = 1) -> np.ndarray:
        """(n_samples, value_size) values at every owned cell's quadrature points."""
        return fx.evaluate_expression(expression, self.cells).reshape(self.n_samples, value_size)

    def weights(self, expression) -> np.ndarray:
        """w_s = ω_q × (the expression, e.g. |det J| det F_1, or a ξ-derivative of it)."""
        values = self.evaluate(expression).reshape(self.cells.size, -1)
        return (values * self.reference_weights).ravel()

    def set_shape_directions(self, *parameters) -> None:
        """Directions δξ = e_k for the given parameter indices k."""
        for direction, k in zip(self.shape_directions, parameters):
            direction.set_parameter(k)

    def elasticity(self) -> np.ndarray:
        """ℂ_s in symmetric coordinates, (n_samples, 6, 6): ψ(s) = ½ sᵀ ℂ_s s. The material's, not the
        design's: evaluated once per sampler."""
        if self._moduli is None:
            self._moduli = self._evaluated_elasticity()
        return self._moduli

    def _evaluated_elasticity(self) -> np.ndarray:
        def density(tensor):
            self.unit_strain.value = tensor
            return self.evaluate(self.energy_density)[:, 0]

        single = [density(SYMMETRIC_BASIS[a]) for a in range(6)]
        moduli = np.empty((self.n_samples, 6, 6))
        for a in range(6):
            moduli[:, a, a] = 2.0 * single[a]
            for b in range(a + 1, 6):
                moduli[:, a, b] = moduli[:, b, a] = density(SYMMETRIC_BASIS[a] + SYMMETRIC_BASIS[b]) - single[a] - single[b]
        return moduli

    def relative_gradients(self, vectors: np.ndarray) -> dict[tuple, np.ndarray]:
        """H_j = ∇V_j F_1⁻¹ and its ξ-derivatives at every sample, (m, n_samples, 3, 3) for each index
        tuple of ``strain_indices``: one evaluation per basis vector V_j."""
        count = len(self.strain_indices)
        values = np.empty((count, vectors.shape[1], self.n_samples, 3, 3))
        for j in range(vectors.shape[1]):
            fx.set_owned_values(self.direction, vectors[:, j])
            values[:, j] = self.evaluate(self.gradients, 9 * count).reshape(self.n_samples, count, 3, 3).transpose(1, 0, 2, 3)
        return dict(zip(self.strain_indices, values))

    def whitened_strain_coefficients(self, vectors: np.ndarray,
                                     transform: np.ndarray) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
        """(ẽ, q̃) = (Rᵀ e, Rᵀ q) of E(V η) = e η + ½ q η η and of each of its ξ-derivatives (by the index
        tuples of ``strain_indices``): shapes (m, 6 n_samples) and (n_pairs, 6 n_samples), R from
        :func:`whitening`, q for the pairs j ≤ k of :func:`pair_index` (:func:`strain_coefficients`)."""
        gradients = self.relative_gradients(vectors)
        return {indices: tuple(whiten(part, transform) for part in strain_coefficients(gradients, indices))
                for indices in self.strain_indices}


def strain_coefficients(gradients: dict[tuple, np.ndarray], indices: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(e, q) in symmetric coordinates of the ξ-derivative ∂_I E (I = ``indices``) of E(V η) = e η + ½ q η η,
    from the relative displacement gradients: ``gradients[J]`` is ∂_J H_j, (m, n_samples, 3, 3).

    E = ½ (H + Hᵀ + Hᵀ H) with H = Σ_j η_j H_j, so by Leibniz' rule over the two factors of Hᵀ H

        e_j = sym ∂_I H_j,   q_jk = Σ_{A ⊔ B = I} sym(∂_A H_jᵀ ∂_B H_k)

    (the sum over every way to split the indices between the factors; it holds each split and its
    mirror, so that q_jk = q_kj). Shapes (m, n_samples, 6) and (n_pairs, n_samples, 6), q for the
    pairs j ≤ k of :func:`pair_list`; sym X and X have the same coordinates X:B_a.
    """
    value = gradients[indices]
    m, n_samples = value.shape[:2]
    rows, columns = np.array(pair_list(m)).T
    quadratic = np.empty((rows.size, n_samples, 6))
    step = max(1, PRODUCT_ENTRIES // (9 * m * m))
    for start in range(0, n_samples, step):
        chunk = slice(start, start + step)
        products = 0.0
        for left, right in _splits(indices):
            if left < right:     # the mirror split (right, left) gives the transposed blocks: added below
                continue
            block = _transposed_products(gradients[left][:, chunk], gradients[right][:, chunk])
            products = products + (block if left == right else block + block.transpose(0, 2, 1))
        blocks = products.reshape(-1, m, 3, m, 3).transpose(1, 3, 0, 2, 4)[rows, columns]    # (pairs, chunk, 3, 3)
        quadratic[:, chunk] = symmetric_coordinates(blocks.reshape(rows.size, -1, 9))
    return symmetric_coordinates(value.reshape(m, n_samples, 9)), quadratic


PRODUCT_ENTRIES = 1 << 22
"""Entries of the per-sample products A_jᵀ B_k :func:`strain_coefficients` holds at once (32 MB)."""


def _transposed_products(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(n, 3m, 3m): every block A_jᵀ B_k (rows j, columns k) at each of the n samples of (m, n, 3, 3)
    arrays A, B, as one (3m × 3) (3 × 3m) matrix product per sample."""
    m, n = left.shape[:2]
    a = np.ascontiguousarray(left.transpose(1, 2, 0, 3)).reshape(n, 3, 3 * m)
    b = np.ascontiguousarray(right.transpose(1, 2, 0, 3)).reshape(n, 3, 3 * m)
    return np.matmul(a.transpose(0, 2, 1), b)


def _splits(indices: tuple):
    """Every (A, B) with A ⊔ B = ``indices`` (each index to the left or the right factor), A and B sorted."""
    for assignment in itertools.product(range(2), repeat=len(indices)):
        yield tuple(tuple(sorted(index for index, side in zip(indices, assignment) if side == slot)) for slot in range(2))


def _flat(tensor) -> list:
    """The 9 components of a 3×3 UFL tensor, row-major."""
    return [tensor[i, j] for i in range(3) for j in range(3)]


def pair_list(m: int) -> list[tuple[int, int]]:
    return [(j, k) for j in range(m) for k in range(j, m)]


def pair_index(m: int) -> np.ndarray:
    """(m, m) → position of the pair (min, max) in :func:`pair_list`."""
    index = np.empty((m, m), dtype=np.int64)
    for number, (j, k) in enumerate(pair_list(m)):
        index[j, k] = index[k, j] = number
    return index


def whitening(weight: np.ndarray, moduli: np.ndarray) -> np.ndarray:
    """R_c with w_c ℂ_c = R_c R_cᵀ (Cholesky), so that w x:ℂ:y = (R_cᵀ x)·(R_cᵀ y)."""
    return np.sqrt(weight)[:, None, None] * np.linalg.cholesky(moduli)


def whiten(factor: np.ndarray, transform: np.ndarray) -> np.ndarray:
    """R_cᵀ x for every cell of an (n, n_cells, 6) array, flattened to (n, 6 n_cells)."""
    whitened = np.matmul(factor.transpose(1, 0, 2), transform)        # (c, n, 6): x R = (Rᵀ x)ᵀ
    return np.ascontiguousarray(whitened.transpose(1, 0, 2)).reshape(factor.shape[0], -1)


def energy_tensors(left, right, m: int):
    """Symmetrised Σ_c w (e_l·ℂ·e_r, ½(e_l·ℂ·q_r + e_r·ℂ·q_l), q_l·ℂ·q_r) from whitened factors.

    ``left`` and ``right`` are (ẽ, q̃) pairs; P3 and P4 are expanded from the pairs j ≤ k.
    """
    (e_left, q_left), (e_right, q_right) = left, right
    p2 = e_left @ e_right.T
    p3_pairs = 0.5 * (e_left @ q_right.T + e_right @ q_left.T)
    p4_pairs = q_left @ q_right.T
    index = pair_index(m)
    p2 = 0.5 * (p2 + p2.T)
    p3 = p3_pairs[:, index]
    p4_pairs = 0.5 * (p4_pairs + p4_pairs.T)
    p4 = p4_pairs[index[:, :, None, None], index[None, None, :, :]]
    return p2, p3, p4


def force_tensors(p2, p3, p4):
    """Symmetric force tensors of f(η) = ∂Π/∂η = K1 η + K2 η η + K3 η η η."""
    p3_sym = (p3 + p3.transpose(1, 0, 2) + p3.transpose(1, 2, 0)) / 3.0   # T_ijk + T_jik + T_kij
    p4_sym = (p4 + p4.transpose(0, 2, 1, 3) + p4.transpose(0, 3, 2, 1)) / 3.0
    return p2, 1.5 * p3_sym, 0.5 * p4_sym


def internal_force_taylor(sampler: CellSampler, vectors: np.ndarray, n_parameters: int,
                          order: int, comm: MPI.Comm, samples: np.ndarray | None = None):
    """Taylor coefficients in Δξ of (K1, K2, K3): lists [constant, first (p, ...), second (p, p, ...)].

    Π = ½ Σ_c w_c E_c:ℂ_c:E_c; its ξ-derivatives follow Leibniz' rule over the three factors
    (w, E, E). The weight enters as w_I / w_0 on the left factor of strains whitened with w_0.
    ``samples`` (bool, one per sample) restricts the sums to those samples (the measure dx of a region):
    the other samples' whitened strains are zero.
    """
    m = vectors.shape[1]
    moduli = sampler.elasticity()
    base_weight = sampler.weights(sampler.weight[0])
    transform = whitening(base_weight, moduli)
    if samples is not None:
        transform = transform * samples[:, None, None]
    p = n_parameters if order >= 1 else 0
    whitened, weight_ratio = {}, {}

    def strain(indices):
        if not whitened:               # E and all its ξ-derivatives from one evaluation per basis vector
            whitened.update(sampler.whitened_strain_coefficients(vectors, transform))
        return whitened[tuple(sorted(indices))]

    def weight(indices):
        if indices not in weight_ratio:
            sampler.set_shape_directions(*indices)
            ratio = sampler.weights(sampler.weight[len(indices)]) / base_weight
            weight_ratio[indices] = np.repeat(ratio, 6)
        return weight_ratio[indices]

    def tensors_for(derivative_indices):
        totals = [np.zeros((m, m)), np.zeros((m, m, m)), np.zeros((m, m, m, m))]
        # energy_tensors is bilinear and symmetric in its two factors, and the weight, a scalar per sample,
        # may go with either: the terms of one right factor (the lesser of the two) are summed on the left
        # first, one call per right factor (w_k E + 2 ∂_k E against E for a first derivative).
        lefts: dict[tuple, list] = {}
        for weight_indices, left_indices, right_indices in _leibniz(derivative_indices):
            left_indices, right_indices = sorted((left_indices, right_indices), reverse=True)
            lefts.setdefault(right_indices, []).append((weight_indices, left_indices))
        for right_indices, terms in lefts.items():
            combined = None
            for weight_indices, left_indices in terms:
                left = strain(left_indices)
                if weight_indices:
                    left = tuple(part * weight(weight_indices) for part in left)
                combined = left if combined is None else tuple(a + b for a, b in zip(combined, left))
            for total, part in zip(totals, energy_tensors(combined, strain(right_indices), m)):
                total += part
        return force_tensors(*(comm.allreduce(total, op=MPI.SUM) for total in totals))

    taylor = [tensors_for(())]
    if p:
        first = [tensors_for((k,)) for k in range(p)]
        taylor.append(tuple(np.stack(parts) for parts in zip(*first)))
    if order >= 2 and p:
        second = {}
        for k in range(p):
            for l in range(k, p):
                second[k, l] = second[l, k] = tensors_for((k, l))
        taylor.append(tuple(np.stack([np.stack([second[k, l][i] for l in range(p)]) for k in range(p)])
                            for i in range(3)))
    return taylor


def _leibniz(derivative_indices):
    """Every way to distribute the ξ-derivative indices among the factors (w, E_left, E_right)."""
    count = len(derivative_indices)
    for assignment in itertools.product(range(3), repeat=count):
        yield tuple(tuple(derivative_indices[i] for i in range(count) if assignment[i] == slot) for slot in range(3))
