"""The per-design kernel's adjoint gradient of the distance (``kernel_adjoint``) against its forward sensitivity
columns (to 1e-10 relative, on every thrust variant, with moving rest stations, drag and the amplitude's column)
and against central differences of the distance; its transposed solve and banded product against numpy."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import kernel_adjoint, reduced_kernel
from aquarom_fenics.dynamics.batched import simulate_batch
from aquarom_fenics.dynamics.batched_system import BatchedSystem
from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.kernel_terms import factorize
from aquarom_fenics.dynamics.simulate import check_time_grid
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import MOVING_TAIL, MOVING_TAIL_SWIM, THRUST_VARIANTS, coarse_scene, moving_tail_designs

pytestmark = pytest.mark.skipif(not reduced_kernel.available(), reason="numba is not installed")


def both_gradients(prom, scene, xis, amplitudes, sensitivities=True, amplitude_sensitivity=True):
    """(distance, gradient) of each design alone by the adjoint, then by the forward columns."""
    system = BatchedSystem(prom, scene, xis, TimeScheme.from_solver(scene.solver), amplitudes)
    packed = reduced_kernel.pack(system, scene, check_time_grid(scene), sensitivities, amplitude_sensitivity)
    adjoint = reduced_kernel.integrate_packed(packed, lockstep=False, adjoint=True)
    forward = reduced_kernel.integrate_packed(packed, lockstep=False, adjoint=False)
    assert not adjoint[2].any() and not forward[2].any()
    return adjoint, forward


def relative_difference(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


@THRUST_VARIANTS
def test_the_adjoint_gradient_equals_the_forward_columns(fluid):
    scene, prom, xis, amplitudes = moving_tail_designs(fluid)
    adjoint, forward = both_gradients(prom, scene, xis, amplitudes)
    np.testing.assert_array_equal(adjoint[0], forward[0])                 # the same forward run
    for b in range(len(xis)):
        assert relative_difference(adjoint[3][b], forward[3][b]) < 1e-10
        assert np.all(np.abs(adjoint[3][b]) > 0.0)                        # every column carries a gradient


def test_the_adjoint_without_the_amplitude_or_without_the_shapes():
    scene = coarse_scene(shapes=MOVING_TAIL, solver=MOVING_TAIL_SWIM)
    prom = build_prom(scene, fish=load_fish(scene))
    xis = prom.xi_center + prom.validity_radius * np.array([[0.5, -0.4]])
    amplitudes = np.array([scene.actuation.amplitude])
    for flags in ((True, False), (False, True)):
        adjoint, forward = both_gradients(prom, scene, xis, amplitudes, *flags)
        assert adjoint[3].shape == forward[3].shape == (1, 2 if flags[0] else 1)
        assert relative_difference(adjoint[3][0], forward[3][0]) < 1e-10


def test_the_adjoint_gradient_against_central_differences_of_the_distance():
    """dd/dξ_k and dd/dA of one design alone against (d(x + δ e_k) - d(x - δ e_k)) / 2δ, δ = 1e-4 of the radius
    (the amplitude); Newton's tolerance, here 1e-11 of the force scale, bounds the differences' accuracy."""
    scene = coarse_scene(shapes=MOVING_TAIL, solver={"duration": 0.3, "tolerance": 1e-11})
    prom = build_prom(scene, fish=load_fish(scene))
    xi = prom.xi_center + prom.validity_radius * np.array([0.3, -0.2])
    amplitude = scene.actuation.amplitude
    gradient = simulate_batch(prom, scene, xi[None], sensitivities=True, amplitude_sensitivity=True,
                              amplitudes=[amplitude], engine="compiled").distance_gradient[0]
    differences = []
    for k in range(3):
        step = 1e-4 * (prom.validity_radius[k] if k < 2 else amplitude)
        sides = []
        for sign in (1.0, -1.0):
            shifted, shifted_amplitude = xi.copy(), amplitude
            if k < 2:
                shifted[k] += sign * step
            else:
                shifted_amplitude += sign * step
            sides.append(simulate_batch(prom, scene, shifted[None], amplitudes=[shifted_amplitude],
                                        engine="compiled").distance[0])
        differences.append((sides[0] - sides[1]) / (2.0 * step))
    np.testing.assert_allclose(gradient, differences, rtol=1e-5)


def test_the_transposed_solve_and_banded_product_against_numpy():
    rng = np.random.default_rng(3)
    matrix = rng.standard_normal((7, 7))
    matrix[0, 0] = 1e-9                                                   # partial pivoting swaps rows
    factors, pivots = np.zeros((7, 7)), np.zeros(7, np.int64)
    assert factorize(matrix, factors, pivots)
    assert np.any(pivots != np.arange(7))
    rhs = rng.standard_normal(7)
    solution = rhs.copy()
    kernel_adjoint.lu_solve_transposed(factors, pivots, solution)
    np.testing.assert_allclose(solution, np.linalg.solve(matrix.T, rhs), rtol=1e-10)
    n_points = 5
    banded = rng.standard_normal((n_points, 3, 2, 2))
    dense = np.zeros((2 * n_points, 2 * n_points))
    for a in range(n_points):
        for b in range(max(a - 1, 0), min(a + 2, n_points)):
            dense[2 * a:2 * a + 2, 2 * b:2 * b + 2] = banded[a, b - a + 1]
    diagonal = np.zeros_like(banded)
    diagonal[:, 1] = banded[:, 1]                                         # the added mass: block-diagonal
    right, out = rng.standard_normal(2 * n_points), np.zeros((2 * n_points, 3))
    kernel_adjoint.banded_transposed_times(banded, 2.0 * banded, diagonal, right, out)
    block_diagonal = np.zeros_like(dense)
    for a in range(n_points):
        block_diagonal[2 * a:2 * a + 2, 2 * a:2 * a + 2] = banded[a, 1]
    np.testing.assert_allclose(out, np.column_stack([dense.T @ right, 2.0 * dense.T @ right,
                                                     block_diagonal.T @ right]), rtol=1e-12)
