"""The compiled kernels' call without numba's per-call typing (``machine_code.TypedCall``)."""
import numpy as np
import pytest

from aquarom_fenics import machine_code
from aquarom_fenics.machine_code import TypedCall

numba = pytest.importorskip("numba")


@numba.njit
def weighted_sum(arrays, weight, flag):
    """Σ weight · a_ij over the two arrays of the tuple (negated without ``flag``)."""
    first, second = arrays
    total = 0.0
    for i in range(first.shape[0]):
        for j in range(first.shape[1]):
            total += first[i, j]
    for i in range(second.shape[0]):
        total += second[i]
    return weight * total if flag else -weight * total


def arguments(rng, rows=3):
    return (rng.standard_normal((rows, 4)), rng.standard_normal(5)), 2.0, True


def test_a_repeated_call_skips_the_typing_and_gives_the_dispatchers_answer(monkeypatch):
    rng = np.random.default_rng(0)
    call = TypedCall(weighted_sum)
    first = arguments(rng)
    assert call(*first) == weighted_sum(*first)
    assert len(call._entries) == 1

    def no_typing(value):
        raise AssertionError("typed again")

    monkeypatch.setattr(weighted_sum, "typeof_pyval", no_typing)
    for rows in (1, 3, 7):                                  # other sizes, the same kind of arguments
        again = arguments(rng, rows)
        assert call(*again) == pytest.approx(2.0 * (again[0][0].sum() + again[0][1].sum()), rel=1e-14)


@pytest.mark.parametrize("other", ["strided", "float32", "fortran", "read-only", "int weight"])
def test_arguments_of_another_kind_go_through_the_dispatcher(other):
    """An array of another layout, dtype or writeability (compiled code for C-contiguous float64 would read the
    wrong memory) or a scalar of another type is typed again, and the answer is right."""
    rng = np.random.default_rng(1)
    call = TypedCall(weighted_sum)
    call(*arguments(rng))
    matrix, vector = rng.standard_normal((6, 8)), rng.standard_normal(5)
    weight = 2.0
    if other == "strided":
        matrix = matrix[::2, ::2]
    elif other == "float32":
        matrix = matrix.astype(np.float32)
    elif other == "fortran":
        matrix = np.asfortranarray(matrix)
    elif other == "read-only":
        matrix.flags.writeable = False
    else:
        weight = 3
    expected = weight * (float(matrix.sum(dtype=float)) + vector.sum())
    assert call((matrix, vector), weight, True) == pytest.approx(expected, rel=1e-6)
    assert len(call._entries) == 2
    assert len(weighted_sum.signatures) >= 2


def test_the_fingerprint_tells_apart_what_numba_types_apart():
    array = np.zeros((2, 3))
    kinds = [array, array.T, array[:, ::2], array.astype(np.float32), array.astype(np.int64), array[None],
             1.0, 1, 2 ** 70, True, (array,), (array, array)]
    prints = [machine_code._fingerprint(kind) for kind in kinds]
    assert len(set(prints)) == len(prints)
    assert machine_code._fingerprint(np.ones((5, 4))) == machine_code._fingerprint(array)
