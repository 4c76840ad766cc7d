"""The LU of eight lanes' Newton matrices S (m, m, LANES) at once, without pivoting, on lane values
(``lane_values``): the arithmetic of ``kernel_terms.lu_unpivoted`` lane by lane, so that a lane's factors are those
of the per-design kernel. A lane whose check fails (a zero or non-finite pivot, growth above ``GROWTH_LIMIT``) is
factorised alone with partial pivoting by the caller (``kernel_terms.factorize``'s fall-back)."""
from __future__ import annotations

import math

from aquarom_fenics.dynamics.compiled import jit as _jit
from aquarom_fenics.dynamics.kernel_terms import GROWTH_LIMIT
from aquarom_fenics.dynamics.lane_values import div, load3, mul, splat, store3, sub


@_jit
def largest_lanes(a, b):
    """max(a, |b|) lane by lane."""
    return (max(a[0], abs(b[0])), max(a[1], abs(b[1])), max(a[2], abs(b[2])), max(a[3], abs(b[3])),
            max(a[4], abs(b[4])), max(a[5], abs(b[5])), max(a[6], abs(b[6])), max(a[7], abs(b[7])))


@_jit
def reciprocal(a):
    return (1.0 / a[0], 1.0 / a[1], 1.0 / a[2], 1.0 / a[3], 1.0 / a[4], 1.0 / a[5], 1.0 / a[6], 1.0 / a[7])


@_jit
def factor_lanes(matrices, factors, accepted):
    """factors (m, m, LANES) = each lane's LU of matrices (m, m, LANES) without pivoting; accepted[l] when lane l
    passes ``lu_unpivoted``'s checks (its factors are then that function's, entry for entry)."""
    size = matrices.shape[0]
    largest = splat(0.0)
    for i in range(size):
        for k in range(size):
            row = load3(matrices, i, k)
            store3(factors, i, k, row)
            largest = largest_lanes(largest, row)
    grown = splat(0.0)
    finite = (True, True, True, True, True, True, True, True)
    for column in range(size):
        pivot = load3(factors, column, column)
        finite = (finite[0] and abs(pivot[0]) > 0.0 and math.isfinite(pivot[0]),
                  finite[1] and abs(pivot[1]) > 0.0 and math.isfinite(pivot[1]),
                  finite[2] and abs(pivot[2]) > 0.0 and math.isfinite(pivot[2]),
                  finite[3] and abs(pivot[3]) > 0.0 and math.isfinite(pivot[3]),
                  finite[4] and abs(pivot[4]) > 0.0 and math.isfinite(pivot[4]),
                  finite[5] and abs(pivot[5]) > 0.0 and math.isfinite(pivot[5]),
                  finite[6] and abs(pivot[6]) > 0.0 and math.isfinite(pivot[6]),
                  finite[7] and abs(pivot[7]) > 0.0 and math.isfinite(pivot[7]))
        inverse = reciprocal(pivot)
        for below in range(column + 1, size):
            factor = mul(load3(factors, below, column), inverse)
            store3(factors, below, column, factor)
            for k in range(column + 1, size):
                value = sub(load3(factors, below, k), mul(factor, load3(factors, column, k)))
                store3(factors, below, k, value)
                grown = largest_lanes(grown, value)
    for l in range(8):
        accepted[l] = finite[l] and grown[l] <= GROWTH_LIMIT * largest[l]


@_jit
def solve_lanes(factors, rhs, out):
    """out (m, c, LANES) = S⁻¹ rhs lane by lane with ``factor_lanes``' factors (forward and back substitution in
    ``lu_solve``'s order)."""
    size, columns = rhs.shape[0], rhs.shape[1]
    for c in range(columns):
        for row in range(size):
            total = load3(rhs, row, c)
            for k in range(row):
                total = sub(total, mul(load3(factors, row, k), load3(out, k, c)))
            store3(out, row, c, total)
        for row in range(size - 1, -1, -1):
            total = load3(out, row, c)
            for k in range(row + 1, size):
                total = sub(total, mul(load3(factors, row, k), load3(out, k, c)))
            store3(out, row, c, div(total, load3(factors, row, row)))

