"""The lanes' LU without pivoting (``lane_lu``) against the per-design kernel's (``kernel_terms.factorize``): the
same factors where the check accepts a lane, the pivoted fall-back where a pivot vanishes or grows."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import reduced_kernel

pytestmark = pytest.mark.skipif(not reduced_kernel.available(), reason="numba is not installed")


def lanes_of_matrices(m: int = 8, seed: int = 1) -> np.ndarray:
    """(m, m, 8): six symmetric, diagonally dominant matrices (as k_a M dominates S), then one with a zero leading
    pivot and one whose second pivot is 1e-9 of its column (growth about 1e9)."""
    rng = np.random.default_rng(seed)
    matrices = np.empty((8, m, m))
    for lane in range(8):
        a = rng.normal(size=(m, m))
        matrices[lane] = a + a.T + np.diag(rng.uniform(3.0 * m, 5.0 * m, m))
    matrices[6, 0, 0] = 0.0
    matrices[7, 1, 1] = matrices[7, 1, 0] * matrices[7, 0, 1] / matrices[7, 0, 0] + 1e-9
    return np.ascontiguousarray(np.moveaxis(matrices, 0, -1))


def test_accepted_lanes_have_the_per_design_factors_and_the_others_fall_back_to_pivoting():
    from aquarom_fenics.dynamics.kernel_terms import factorize, lu_solve, lu_unpivoted
    from aquarom_fenics.dynamics.lane_lu import factor_lanes, solve_lanes

    m = 8
    matrices = lanes_of_matrices(m)
    factors, accepted = np.zeros_like(matrices), np.zeros(8, bool)
    factor_lanes(matrices, factors, accepted)
    assert accepted.tolist() == [True] * 6 + [False, False]
    rhs = np.random.default_rng(2).normal(size=(m, 3, 8))
    solved = np.zeros_like(rhs)
    solve_lanes(factors, rhs, solved)
    for lane in range(8):
        matrix = np.ascontiguousarray(matrices[:, :, lane])
        alone, pivots = np.zeros((m, m)), np.zeros(m, np.int64)
        assert lu_unpivoted(matrix, alone, pivots) == accepted[lane]
        if accepted[lane]:
            np.testing.assert_array_equal(alone, factors[:, :, lane])
            np.testing.assert_array_equal(pivots, np.arange(m))
            np.testing.assert_allclose(matrix @ solved[:, :, lane], rhs[:, :, lane], rtol=0, atol=1e-12)
        assert factorize(matrix, alone, pivots)
        assert (pivots != np.arange(m)).any() != accepted[lane]          # the fall-back pivots
        solution = np.ascontiguousarray(rhs[:, :, lane])
        lu_solve(alone, pivots, solution)
        np.testing.assert_allclose(solution, np.linalg.solve(matrix, rhs[:, :, lane]), rtol=1e-9)


def test_a_singular_matrix_is_refused():
    from aquarom_fenics.dynamics.kernel_terms import factorize

    matrix = np.ones((3, 3))
    assert not factorize(matrix, np.zeros((3, 3)), np.zeros(3, np.int64))
