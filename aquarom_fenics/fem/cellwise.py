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

import collections
import itertools

import numpy as np
import ufl
from mpi4py import MPI
from scipy.linalg import blas

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem import pair_kernel
from aquarom_fenics.forms.elasticity import small_strain_energy_density
from aquarom_fenics.forms.kinematics import relative_displacement_gradient, volume_ratio

# Orthonormal basis of symmetric 3×3 tensors: E = Σ_a s_a B_a with s_a = E:B_a.
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
SYMMETRIC_BASIS = np.zeros((6, 3, 3))
for _a, (_i, _j) in enumerate(_PAIRS):
    SYMMETRIC_BASIS[_a, _i, _j] = SYMMETRIC_BASIS[_a, _j, _i] = 1.0 if _i == _j else 1.0 / np.sqrt(2.0)


_TO_SYMMETRIC = np.ascontiguousarray(SYMMETRIC_BASIS.reshape(6, 9).T)   # contiguous: a fast matmul
_HALF_ROOT = 1.0 / np.sqrt(2.0)


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

    def relative_gradients(self, vectors: np.ndarray) -> np.ndarray:
        """H_j = ∇V_j F_1⁻¹ and its ξ-derivatives at every sample, (count, 3, 3, m, n_samples) (index tuple of
        ``strain_indices``, row, column, basis vector, sample): one evaluation per basis vector V_j."""
        count = len(self.strain_indices)
        values = np.empty((count, 3, 3, vectors.shape[1], self.n_samples))
        for j in range(vectors.shape[1]):
            fx.set_owned_values(self.direction, vectors[:, j])
            values[:, :, :, j] = (self.evaluate(self.gradients, 9 * count).reshape(self.n_samples, count, 3, 3)
                                  .transpose(1, 2, 3, 0))
        return values

    def whitened_strain_coefficients(self, vectors: np.ndarray, transform: "Whitening",
                                     compiled: bool | None = None) -> dict[tuple, tuple[np.ndarray, np.ndarray]]:
        """(ẽ, q̃) = (Rᵀ e, Rᵀ q) of E(V η) = e η + ½ q η η and of each of its ξ-derivatives (by the index
        tuples of ``strain_indices``): shapes (m, 6, n_samples) and (n_pairs, 6, n_samples), R from
        :func:`whitening`, q for the pairs j ≤ k of :func:`pair_index` (:func:`strain_coefficients`). q̃ by the
        compiled kernel (``pair_kernel``) where numba is installed (``compiled`` None), else, or with
        ``compiled=False``, by numpy."""
        stacked = self.relative_gradients(vectors)
        gradients = dict(zip(self.strain_indices, stacked))
        if not (pair_kernel.available() if compiled is None else compiled):
            return {indices: tuple(whiten(part, transform) for part in strain_coefficients(gradients, indices))
                    for indices in self.strain_indices}
        return {indices: (whiten(symmetric_parts(gradients[indices]), transform),
                          whitened_pair_products(stacked, self.strain_indices, [(indices, None, 1.0)], transform))
                for indices in self.strain_indices}


def whitened_pair_products(stacked: np.ndarray, strain_indices: list, terms: list,
                           transform: "Whitening") -> np.ndarray:
    """Rᵀ Σ_t c_t w_t q_t by the compiled kernel, (n_pairs, 6, n_samples): q_t the q of :func:`strain_coefficients`
    of the index tuple I_t, Σ_{A ⊔ B = I_t} sym(∂_A H_jᵀ ∂_B H_k), over every term t = (I_t, w_t, c_t) of ``terms``
    (w_t a weight per sample or None for 1, c_t a number), formed and whitened in one pass over the samples.
    ``stacked`` (count, 3, 3, m, n_samples) holds ∂_J H for the index tuples J of ``strain_indices``."""
    position = {key: number for number, key in enumerate(strain_indices)}
    splits, coefficients, weights = [], [], []
    for indices, weight, coefficient in terms:
        row = -1 if weight is None else len(weights)
        if weight is not None:
            weights.append(weight)
        for left, right in leibniz_terms(indices, 2):
            splits.append((position[left], position[right], row))
            coefficients.append(coefficient)
    used = sorted({number for left, right, _ in splits for number in (left, right)})
    local = {number: place for place, number in enumerate(used)}
    table = np.array([[local[left], local[right], row] for left, right, row in splits], dtype=np.int64)
    m, n_samples = stacked.shape[3:]
    out = np.empty((m * (m + 1) // 2, 6, n_samples))
    pair_kernel.whitened_pair_products(stacked, np.array(used, dtype=np.int64), table,
                                       np.array(coefficients, dtype=float),
                                       np.array(weights, dtype=float).reshape(len(weights), n_samples),
                                       *transform.kernel_arguments(), out)
    return out


def strain_coefficients(gradients: dict[tuple, np.ndarray], indices: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(e, q) in symmetric coordinates of the ξ-derivative ∂_I E (I = ``indices``) of E(V η) = e η + ½ q η η,
    from the relative displacement gradients: ``gradients[J]`` is ∂_J H_j, (3, 3, m, n_samples).

    E = ½ (H + Hᵀ + Hᵀ H) with H = Σ_j η_j H_j, so by Leibniz' rule over the two factors of Hᵀ H

        e_j = sym ∂_I H_j,   q_jk = Σ_{A ⊔ B = I} sym(∂_A H_jᵀ ∂_B H_k)

    (the sum over every way to split the indices between the factors, :func:`leibniz_terms`; it holds each
    split and its mirror, so that q_jk = q_kj). Shapes (m, 6, n_samples) and (n_pairs, 6, n_samples), q for
    the pairs j ≤ k of :func:`pair_list`; sym X and X have the same coordinates X:B_a.
    """
    value = gradients[indices]
    m, n_samples = value.shape[2:]
    quadratic = np.zeros((m * (m + 1) // 2, 6, n_samples))
    for left, right in leibniz_terms(indices, 2):
        if left < right:     # the mirror split (right, left): sym(∂_B H_jᵀ ∂_A H_k), added with its own
            continue
        add_pair_products(quadratic, gradients[left], gradients[right])
        if left != right:
            add_pair_products(quadratic, gradients[right], gradients[left])
    return symmetric_parts(value), quadratic


def symmetric_parts(tensors: np.ndarray) -> np.ndarray:
    """(3, 3, m, n) tensors X_j → (m, 6, n) coordinates X_j:B_a."""
    parts = np.empty((tensors.shape[2], 6, tensors.shape[3]))
    for a, (r, c) in enumerate(_PAIRS):
        parts[:, a] = tensors[r, r] if r == c else (tensors[r, c] + tensors[c, r]) * _HALF_ROOT
    return parts


def add_pair_products(into: np.ndarray, left: np.ndarray, right: np.ndarray) -> None:
    """into[(j, k), a] += (A_jᵀ B_k):B_a for the pairs j ≤ k of :func:`pair_list` at every sample, of the
    (3, 3, m, n) tensors A = ``left`` and B = ``right``: (AᵀB)_rc = Σ_i A_ir B_ic, its coordinate a = (r, c)
    X_rr, or (X_rc + X_cr)/√2 off the diagonal. One row j (its pairs k ≥ j) at a time, every sample at once."""
    m = left.shape[2]
    start = 0
    for j in range(m):
        stop = start + m - j
        for a, (r, c) in enumerate(_PAIRS):
            value = np.einsum("is,iks->ks", left[:, r, j], right[:, c, j:])
            if r != c:
                value += np.einsum("is,iks->ks", left[:, c, j], right[:, r, j:])
                value *= _HALF_ROOT
            into[start:stop, a] += value
        start = stop


def leibniz_terms(indices: tuple, factors: int):
    """Every way to distribute the ξ-derivative indices I among the ``factors`` factors f_1 … f_n of a
    product: ∂_I (f_1 ⋯ f_n) = Σ_{A_1 ⊔ … ⊔ A_n = I} ∂_{A_1} f_1 ⋯ ∂_{A_n} f_n, one (A_1, …, A_n) per
    term, each A_i sorted (n^|I| terms; a derivative is symmetric in its indices)."""
    for owners in itertools.product(range(factors), repeat=len(indices)):
        yield tuple(tuple(sorted(index for index, owner in zip(indices, owners) if owner == factor))
                    for factor in range(factors))


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


class Whitening:
    """R_s with w_s ℂ_s = R_s R_sᵀ (Cholesky) at every sample s, so that w x:ℂ:y = (R_sᵀ x)·(R_sᵀ y).

    Where every ℂ_s is one matrix scaled, ℂ_s = c_s ℂ̂ (an isotropic law with one Poisson ratio: c_s ∝ E_s),
    to ``SHARED_TOLERANCE`` relative, R_s = √(w_s c_s) R̂ with ℂ̂ = R̂ R̂ᵀ: Rᵀ x is one 6 × 6 product and a
    scaling per sample (``shared``); otherwise each sample has its own R_s. ``samples`` (bool) zeroes R_s
    outside a region."""

    SHARED_TOLERANCE = 1e-13

    def __init__(self, weight: np.ndarray, moduli: np.ndarray, samples: np.ndarray | None = None,
                 allow_shared: bool = True):
        mask = 1.0 if samples is None else samples
        size = np.abs(moduli).max(axis=(1, 2))
        shapes = moduli / np.where(size > 0, size, 1.0)[:, None, None]
        self.shared = bool(allow_shared and np.all(size > 0)
                           and np.abs(shapes - shapes[0]).max() <= self.SHARED_TOLERANCE)
        if self.shared:
            self.factor = np.ascontiguousarray(np.linalg.cholesky(shapes[0]).T)          # R̂ᵀ
            self.scale = np.sqrt(weight * size) * mask                                    # √(w_s c_s)
        else:
            self.factors = (np.sqrt(weight) * mask)[:, None, None] * np.linalg.cholesky(moduli)   # R_s

    def kernel_arguments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R̂ᵀ, scale, an empty (6, 6, 0)) when shared, else (zeros, ones, factors[b, a, s] = (R_sᵀ)_ba): the
        whitening as ``pair_kernel.whitened_pair_products`` takes it."""
        if self.shared:
            return self.factor, np.ascontiguousarray(self.scale, dtype=float), np.empty((6, 6, 0))
        if not hasattr(self, "_transposed"):
            self._transposed = np.ascontiguousarray(self.factors.transpose(2, 1, 0))
        return np.zeros((6, 6)), np.ones(self.factors.shape[0]), self._transposed

    def apply(self, factor: np.ndarray) -> np.ndarray:
        """R_sᵀ x at every sample of a (count, 6, n_samples) array x, the same shape."""
        if self.shared:
            whitened = np.matmul(self.factor, factor)
            whitened *= self.scale
            return whitened
        return np.einsum("sab,kas->kbs", self.factors, factor)


def whitening(weight: np.ndarray, moduli: np.ndarray, samples: np.ndarray | None = None) -> Whitening:
    """R_s with w_s ℂ_s = R_s R_sᵀ (:class:`Whitening`), zero outside ``samples`` when given."""
    return Whitening(weight, moduli, samples)


def whiten(factor: np.ndarray, transform: Whitening) -> np.ndarray:
    """R_sᵀ x for every sample of a (count, 6, n_samples) array x, the same shape."""
    return transform.apply(factor)


def symmetric_product(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """½ (L Rᵀ + R Lᵀ) of two (count, …) arrays flattened to (count, k), by BLAS' symmetric rank-2k update (the
    symmetrised product in the operations of L Rᵀ alone); L Lᵀ by the rank-k update, half of them, when
    ``right`` is ``left``."""
    a, b = left.reshape(left.shape[0], -1), right.reshape(right.shape[0], -1)
    upper = blas.dsyrk(1.0, a.T, trans=1) if right is left else blas.dsyr2k(0.5, a.T, b.T, trans=1)
    return np.triu(upper) + np.triu(upper, 1).T


def energy_tensors(left, right, m: int):
    """Symmetrised Σ_s w (e_l·ℂ·e_r, ½(e_l·ℂ·q_r + e_r·ℂ·q_l), q_l·ℂ·q_r) from whitened factors.

    ``left`` and ``right`` are (ẽ, q̃) pairs, (count, 6, n_samples) each; P3 and P4 are expanded from the pairs
    j ≤ k.
    """
    (e_left, q_left), (e_right, q_right) = left, right
    flat = [part.reshape(part.shape[0], -1) for part in (e_left, q_left, e_right, q_right)]
    e_left, q_left, e_right, q_right = flat
    same = left is right
    p2 = symmetric_product(e_left, e_left if same else e_right)
    p3_pairs = e_left @ q_right.T if same else 0.5 * (e_left @ q_right.T + e_right @ q_left.T)
    p4_pairs = symmetric_product(q_left, q_left if same else q_right)
    index = pair_index(m)
    p3 = p3_pairs[:, index]
    p4 = p4_pairs[index[:, :, None, None], index[None, None, :, :]]
    return p2, p3, p4


def force_tensors(p2, p3, p4):
    """Symmetric force tensors of f(η) = ∂Π/∂η = K1 η + K2 η η + K3 η η η."""
    p3_sym = (p3 + p3.transpose(1, 0, 2) + p3.transpose(1, 2, 0)) / 3.0   # T_ijk + T_jik + T_kij
    p4_sym = (p4 + p4.transpose(0, 2, 1, 3) + p4.transpose(0, 3, 2, 1)) / 3.0
    return p2, 1.5 * p3_sym, 0.5 * p4_sym


def internal_force_taylor(sampler: CellSampler, vectors: np.ndarray, n_parameters: int, order: int, comm: MPI.Comm,
                          samples: np.ndarray | None = None, compiled: bool | None = None):
    """Taylor coefficients in Δξ of (K1, K2, K3): lists [constant, first (p, ...), second (p, p, ...)].

    Π = ½ Σ_c w_c E_c:ℂ_c:E_c; its ξ-derivatives follow Leibniz' rule over the three factors
    (w, E, E). The weight enters as w_I / w_0 on the left factor of strains whitened with w_0.
    ``samples`` (bool, one per sample) restricts the sums to those samples (the measure dx of a region):
    the other samples' whitened strains are zero. Where numba is installed (``compiled`` None) or ``compiled``,
    the weighted sum of one right factor's left terms is formed by the compiled pair products with the weights
    (:func:`whitened_pair_products`); otherwise by numpy from ``sampler.whitened_strain_coefficients``.
    """
    m = vectors.shape[1]
    base_weight = sampler.weights(sampler.weight[0])
    transform = whitening(base_weight, sampler.elasticity(), samples)
    p = n_parameters if order >= 1 else 0
    whitened, weight_ratio, stacked = {}, {}, []
    fused = pair_kernel.available() if compiled is None else compiled

    def strain(indices):
        key = tuple(sorted(indices))
        if fused and key not in whitened:
            whitened[key] = fused_strain([((), key)])
        elif not whitened:             # E and all its ξ-derivatives from one evaluation per basis vector
            whitened.update(sampler.whitened_strain_coefficients(vectors, transform, compiled=False))
        return whitened[key]

    def fused_strain(terms):
        """Σ_t w_t (ẽ, q̃) of the terms (weight indices, strain indices), repeated terms counted."""
        if not stacked:                # H and all its ξ-derivatives from one evaluation per basis vector
            stacked.append(sampler.relative_gradients(vectors))
        counted = collections.Counter(terms)
        linear = sum(whiten(symmetric_parts(stacked[0][sampler.strain_indices.index(left)]), transform)
                     * (count * weight(weights) if weights else float(count))
                     for (weights, left), count in counted.items())
        quadratic = whitened_pair_products(stacked[0], sampler.strain_indices, [
            (left, weight(weights) if weights else None, float(count)) for (weights, left), count in counted.items()],
            transform)
        return linear, quadratic

    def weight(indices):
        if indices not in weight_ratio:
            sampler.set_shape_directions(*indices)
            weight_ratio[indices] = sampler.weights(sampler.weight[len(indices)]) / base_weight
        return weight_ratio[indices]

    def tensors_for(derivative_indices):
        totals = [np.zeros((m, m)), np.zeros((m, m, m)), np.zeros((m, m, m, m))]
        # energy_tensors is bilinear and symmetric in its two factors, and the weight, a scalar per sample,
        # may go with either: the terms of one right factor (the lesser of the two) are summed on the left
        # first, one call per right factor (w_k E + 2 ∂_k E against E for a first derivative).
        lefts: dict[tuple, list] = {}
        for weight_indices, left_indices, right_indices in leibniz_terms(derivative_indices, 3):
            left_indices, right_indices = sorted((left_indices, right_indices), reverse=True)
            lefts.setdefault(right_indices, []).append((weight_indices, left_indices))
        for right_indices, terms in lefts.items():
            if fused:              # one unweighted term: the strain itself (cached; E against E by the rank-k update)
                single = len(terms) == 1 and not terms[0][0]
                left = strain(terms[0][1]) if single else fused_strain(terms)
                for total, part in zip(totals, energy_tensors(left, strain(right_indices), m)):
                    total += part
                continue
            terms.sort(key=lambda term: not term[0])          # the weighted terms first: they make the sum's arrays
            combined = None
            for weight_indices, left_indices in terms:
                left = strain(left_indices)
                if combined is None:
                    combined = (tuple(part * weight(weight_indices) for part in left) if weight_indices
                                else left if len(terms) == 1 else tuple(part.copy() for part in left))
                    continue
                for total, part in zip(combined, left):
                    if weight_indices:
                        total += part * weight(weight_indices)
                    else:
                        total += part
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
