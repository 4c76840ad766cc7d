"""Eight lanes' values held as a tuple (in registers, not in memory), so that straight-line code on them runs as
vectors: numba's compiler does not vectorise a loop over the lanes of arrays it cannot prove apart, but it packs
eight like operations on values. ``load`` and ``store`` move a row's eight lanes between an array and a tuple."""
from __future__ import annotations

from aquarom_fenics.dynamics.compiled import jit as _jit


@_jit
def load(array, i):
    """The eight lanes of row i of array (·, 8)."""
    return (array[i, 0], array[i, 1], array[i, 2], array[i, 3], array[i, 4], array[i, 5], array[i, 6], array[i, 7])


@_jit
def load3(array, i, j):
    """The eight lanes of row (i, j) of array (·, ·, 8)."""
    return (array[i, j, 0], array[i, j, 1], array[i, j, 2], array[i, j, 3], array[i, j, 4], array[i, j, 5],
            array[i, j, 6], array[i, j, 7])


@_jit
def store3(array, i, j, a):
    """array[i, j, :] = a."""
    array[i, j, 0], array[i, j, 1], array[i, j, 2], array[i, j, 3] = a[0], a[1], a[2], a[3]
    array[i, j, 4], array[i, j, 5], array[i, j, 6], array[i, j, 7] = a[4], a[5], a[6], a[7]


@_jit
def store(array, i, a):
    """array[i, :] = a."""
    array[i, 0], array[i, 1], array[i, 2], array[i, 3] = a[0], a[1], a[2], a[3]
    array[i, 4], array[i, 5], array[i, 6], array[i, 7] = a[4], a[5], a[6], a[7]


@_jit
def add_to(array, i, a):
    """array[i, :] += a."""
    array[i, 0] += a[0]
    array[i, 1] += a[1]
    array[i, 2] += a[2]
    array[i, 3] += a[3]
    array[i, 4] += a[4]
    array[i, 5] += a[5]
    array[i, 6] += a[6]
    array[i, 7] += a[7]


@_jit
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4], a[5] + b[5], a[6] + b[6], a[7] + b[7])


@_jit
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3], a[4] - b[4], a[5] - b[5], a[6] - b[6], a[7] - b[7])


@_jit
def mul(a, b):
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2], a[3] * b[3], a[4] * b[4], a[5] * b[5], a[6] * b[6], a[7] * b[7])


@_jit
def neg(a):
    return (-a[0], -a[1], -a[2], -a[3], -a[4], -a[5], -a[6], -a[7])



@_jit
def div(a, b):
    return (a[0] / b[0], a[1] / b[1], a[2] / b[2], a[3] / b[3], a[4] / b[4], a[5] / b[5], a[6] / b[6], a[7] / b[7])


@_jit
def splat(x):
    """The eight lanes of one number."""
    return (x, x, x, x, x, x, x, x)
