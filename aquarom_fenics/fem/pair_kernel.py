"""The whitened pair products of the strain compiled (numba): q̃_jk = R_sᵀ Σ_{A ⊔ B = I} sym(∂_A H_jᵀ ∂_B H_k) in
one pass over the samples, without the unwhitened products or any other array of their size; also a weighted
sum of several such terms, Σ_t c_t w_t q̃_t (the internal force's Leibniz terms of one right factor, with the
weight's ξ-derivatives w_t per sample: ``cellwise.internal_force_taylor``).

numpy forms the same sums (``cellwise.strain_coefficients``, then ``Whitening.apply``) one basis row and
coordinate at a time over every sample: each step reads and writes arrays of n_samples values, memory-bound.
Here a block of samples stays in cache while every pair (j, k), every Leibniz split and the whitening run over
it. The numpy path is the fallback (numba missing) and the reference (``tests/reduction``).

Compiled once per machine into numba's cache beside this module (``python -m aquarom_fenics.fem.pair_kernel``,
which ``make setup`` runs); one signature, every argument float64 or int64 and C-contiguous.
"""
from __future__ import annotations

import numpy as np

from aquarom_fenics.machine_code import available, jit as _jit  # noqa: F401  (available: cellwise asks here)

_HALF_ROOT = 1.0 / np.sqrt(2.0)
BLOCK = 128
"""Samples per block: the block's gradient rows (a few hundred kB) stay in the second-level cache, its
accumulators (6 × BLOCK) in the first."""


@_jit
def _copy_block(gradients, used, start, width, scratch):  # pragma: no cover (compiled)
    """scratch[((u m + j) 9 + 3 i + r) BLOCK + s] = gradients[used[u], i, r, j, start + s]: the block's nine rows of
    each H_j side by side, at distances known when compiled (the loops below vectorise)."""
    m = gradients.shape[3]
    for u in range(used.size):
        tensor = gradients[used[u]]
        for j in range(m):
            for i in range(3):
                for r in range(3):
                    row = tensor[i, r, j, start:start + width]
                    into = scratch[((u * m + j) * 9 + 3 * i + r) * BLOCK:]
                    for s in range(width):
                        into[s] = row[s]


@_jit
def _add_pair(left, right, into, width, weight, coefficient):  # pragma: no cover (compiled)
    """into[a BLOCK + s] += coefficient weight_s (AᵀB):B_a (a = (0, 0), (1, 1), (2, 2), then (0, 1), (0, 2), (1, 2)
    without the 1/√2) at each sample s of the block, A's nine rows at left[(3 i + r) BLOCK + s], B's at right[...]:
    (AᵀB)_rc = Σ_i A_ir B_ic. The three i unrolled and ``width`` not a constant: LLVM vectorises the loop over
    the samples."""
    for s in range(width):
        a0, a1, a2 = left[s], left[BLOCK + s], left[2 * BLOCK + s]
        b0, b1, b2 = right[s], right[BLOCK + s], right[2 * BLOCK + s]
        c0, c1, c2 = a0 * b0, a1 * b1, a2 * b2
        c3, c4, c5 = a0 * b1 + a1 * b0, a0 * b2 + a2 * b0, a1 * b2 + a2 * b1
        a0, a1, a2 = left[3 * BLOCK + s], left[4 * BLOCK + s], left[5 * BLOCK + s]
        b0, b1, b2 = right[3 * BLOCK + s], right[4 * BLOCK + s], right[5 * BLOCK + s]
        c0, c1, c2 = c0 + a0 * b0, c1 + a1 * b1, c2 + a2 * b2
        c3, c4, c5 = c3 + (a0 * b1 + a1 * b0), c4 + (a0 * b2 + a2 * b0), c5 + (a1 * b2 + a2 * b1)
        a0, a1, a2 = left[6 * BLOCK + s], left[7 * BLOCK + s], left[8 * BLOCK + s]
        b0, b1, b2 = right[6 * BLOCK + s], right[7 * BLOCK + s], right[8 * BLOCK + s]
        scale = coefficient * weight[s]
        into[s] += scale * (c0 + a0 * b0)
        into[BLOCK + s] += scale * (c1 + a1 * b1)
        into[2 * BLOCK + s] += scale * (c2 + a2 * b2)
        into[3 * BLOCK + s] += scale * (c3 + (a0 * b1 + a1 * b0))
        into[4 * BLOCK + s] += scale * (c4 + (a0 * b2 + a2 * b0))
        into[5 * BLOCK + s] += scale * (c5 + (a1 * b2 + a2 * b1))


@_jit
def _combine_shared(block, scale, g0, g1, g2, g3, g4, g5, into, width):  # pragma: no cover (compiled)
    """into[s] = scale_s Σ_a g_a block[a BLOCK + s]: one whitened coordinate of the shared factor's row g."""
    for s in range(width):
        into[s] = scale[s] * (g0 * block[s] + g1 * block[BLOCK + s] + g2 * block[2 * BLOCK + s]
                              + g3 * block[3 * BLOCK + s] + g4 * block[4 * BLOCK + s] + g5 * block[5 * BLOCK + s])


@_jit
def _combine_per_sample(block, factors, into, width):  # pragma: no cover (compiled)
    """into[s] = Σ_a factors[a, s] c_a block[a BLOCK + s], c_a = 1 on the diagonal coordinates, 1/√2 off it."""
    for s in range(width):
        into[s] = (factors[0, s] * block[s] + factors[1, s] * block[BLOCK + s] + factors[2, s] * block[2 * BLOCK + s]
                   + _HALF_ROOT * (factors[3, s] * block[3 * BLOCK + s] + factors[4, s] * block[4 * BLOCK + s]
                                   + factors[5, s] * block[5 * BLOCK + s]))


@_jit
def whitened_pair_products(gradients, used, splits, coefficients, weights, factor, scale, factors,
                           out):  # pragma: no cover (compiled)
    """out[(j, k), b, s] = Σ_a (R_sᵀ)_ba Σ_t c_t w_ts (A_jᵀ B_k):B_a, A = gradients[used[splits[t, 0]]],
    B = gradients[used[splits[t, 1]]], c_t = coefficients[t], w_ts = weights[splits[t, 2], s] (1 where splits[t, 2]
    is -1).

    gradients (count, 3, 3, m, n): ∂_J H_j for each index tuple J (row, column, basis vector, sample); used: the
    tensors a split reads; splits (n_splits, 3): (A, B) of every Leibniz split of the two factors, as positions in
    ``used``, and the row of its weight; weights (n_weights, n); out (m (m + 1) / 2, 6, n), the pairs j ≤ k in
    ``cellwise.pair_list``'s order. (AᵀB)_rc = Σ_i A_ir B_ic; its coordinate a = (r, c): X_rr, or
    (X_rc + X_cr)/√2 off the diagonal. The whitening
    (``cellwise.Whitening``): shared, R_sᵀ = scale_s R̂ᵀ with R̂ᵀ = ``factor`` (6, 6), when ``factors`` is empty
    (6, 6, 0); otherwise per sample, factors[b, a, s] = (R_sᵀ)_ba (6, 6, n)."""
    m, n = gradients.shape[3], gradients.shape[4]
    shared = factors.shape[2] == 0
    scratch = np.empty(used.size * m * 9 * BLOCK)
    block = np.empty(6 * BLOCK)
    unit = np.ones(BLOCK)
    for start in range(0, n, BLOCK):
        width = min(BLOCK, n - start)
        stop = start + width
        _copy_block(gradients, used, start, width, scratch)
        pair = 0
        for j in range(m):
            for k in range(j, m):
                block[:] = 0.0
                for t in range(splits.shape[0]):
                    left = ((splits[t, 0] * m + j) * 9) * BLOCK
                    right = ((splits[t, 1] * m + k) * 9) * BLOCK
                    weight = unit if splits[t, 2] < 0 else weights[splits[t, 2], start:stop]
                    _add_pair(scratch[left:left + 9 * BLOCK], scratch[right:right + 9 * BLOCK], block, width, weight,
                              coefficients[t])
                for b in range(6):
                    if shared:
                        _combine_shared(block, scale[start:stop], factor[b, 0], factor[b, 1], factor[b, 2],
                                        _HALF_ROOT * factor[b, 3], _HALF_ROOT * factor[b, 4],
                                        _HALF_ROOT * factor[b, 5], out[pair, b, start:stop], width)
                    else:
                        _combine_per_sample(block, factors[b, :, start:stop], out[pair, b, start:stop], width)
                pair += 1


def synthetic(m: int = 3, n: int = 2 * BLOCK + 5, count: int = 3, seed: int = 0):
    """(gradients, used, splits, coefficients, weights, factor, scale, factors) of random values in the kernel's
    one signature, the whitening per sample (``factors``); a shared one is (factor, scale, an empty (6, 6, 0))."""
    rng = np.random.default_rng(seed)
    gradients = rng.standard_normal((count + 1, 3, 3, m, n))
    used = np.arange(1, count + 1, dtype=np.int64)           # the first tensor unused
    splits = np.array([[0, 0, -1], [1, 2, 0], [2, 1, 1]], dtype=np.int64)
    coefficients = np.array([1.0, 2.0, 0.5])
    weights = rng.standard_normal((2, n))
    factor = np.triu(rng.standard_normal((6, 6)))
    scale = rng.random(n)
    return gradients, used, splits, coefficients, weights, factor, scale, rng.standard_normal((6, 6, n))


def reference(gradients, used, splits, coefficients, weights, factors):
    """The kernel's sums in numpy (for the warm-up's check), whitened by per-sample factors[b, a, s]."""
    m, n = gradients.shape[3], gradients.shape[4]
    rows, cols = np.triu_indices(m)
    products = np.zeros((rows.size, 3, 3, n))
    for (left, right, row), coefficient in zip(splits, coefficients):
        weight = coefficient * (1.0 if row < 0 else weights[row])
        products += weight * np.einsum("irjs,icjs->jrcs", gradients[used[left]][:, :, rows],
                                       gradients[used[right]][:, :, cols])
    coordinates = np.empty((rows.size, 6, n))
    for a, (r, c) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        coordinates[:, a] = products[:, r, c] if r == c else (products[:, r, c] + products[:, c, r]) * _HALF_ROOT
    return np.einsum("bas,kas->kbs", factors, coordinates)


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernel's one signature on a small synthetic input, both
    whitenings checked against numpy to 1e-12."""
    if not available():
        return
    gradients, used, splits, coefficients, weights, factor, scale, factors = synthetic()
    m, n = gradients.shape[3:]
    shared_factors = factor[:, :, None] * scale
    for per_sample, expected_factors in ((factors, factors), (np.empty((6, 6, 0)), shared_factors)):
        out = np.empty((m * (m + 1) // 2, 6, n))
        whitened_pair_products(gradients, used, splits, coefficients, weights, factor, scale, per_sample, out)
        expected = reference(gradients, used, splits, coefficients, weights, expected_factors)
        if not np.abs(out - expected).max() <= 1e-12 * np.abs(expected).max():
            raise RuntimeError("the compiled pair products differ from numpy's on their synthetic input")


if __name__ == "__main__":
    import time as clock
    started = clock.perf_counter()
    warm_up()
    print(f"setup: compiled pair products ready ({clock.perf_counter() - started:.1f} s)")
