"""Many designs of a PROM integrated at once (``simulate_batch``) against ``simulate_reduced`` one by one."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import reduced_kernel
from aquarom_fenics.dynamics.batched import ENGINES, simulate_batch
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene
from prom_checks import SO1_SHAPES, assert_batch_matches_single_runs, max_relative_error

SHORT = {"duration": 0.4}


@pytest.fixture(scope="module")
def scene():
    return coarse_scene(shapes=SO1_SHAPES, solver=SHORT)


@pytest.fixture(scope="module")
def prom(scene):
    return build_prom(scene, fish=load_fish(scene))


def designs(prom, count: int, seed: int = 3) -> np.ndarray:
    """``count`` designs spread over the PROM's validity box, its centre first."""
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-1.0, 1.0, (count, prom.n_parameters))
    offsets[0] = 0.0
    return prom.xi_center + prom.validity_radius * offsets


@pytest.fixture(params=ENGINES)
def engine(request):
    if request.param == "compiled" and not reduced_kernel.available():
        pytest.skip("numba is not installed")
    return request.param


def test_a_batch_agrees_with_single_runs_in_distance_amplitude_and_gradient(scene, prom, engine):
    xis = designs(prom, 5)
    amplitudes = scene.actuation.amplitude * np.array([1.0, 0.8, 1.1, 0.9, 1.2])
    batch = simulate_batch(prom, scene, xis, sensitivities=True, amplitudes=amplitudes, amplitude_sensitivity=True,
                           engine=engine)
    assert_batch_matches_single_runs(prom, scene, xis, amplitudes, batch)


def test_a_batch_of_one_is_the_single_run(scene, prom, engine):
    xi = designs(prom, 2)[1]
    batch = simulate_batch(prom, scene, xi[None], sensitivities=True, engine=engine)
    single = simulate_reduced(prom, scene, xi, sensitivities=True)
    assert max_relative_error(batch.distance[0], single.distance) < 1e-12
    assert max_relative_error(batch.distance_gradient[0], single.distance_gradient) < 1e-12


def test_a_design_whose_step_fails_in_the_batch_is_integrated_alone_with_step_cutting(prom, engine):
    """Two Newton iterations per step are too few for a full step: every design leaves the batch and gets
    the single run's line search and cut steps, its answer that of ``simulate_reduced``."""
    scene = coarse_scene(shapes=SO1_SHAPES, solver={**SHORT, "max_iterations": 2})
    xis = designs(prom, 3)
    batch = simulate_batch(prom, scene, xis, sensitivities=True, engine=engine)
    assert batch.alone.all()
    for b, xi in enumerate(xis):
        single = simulate_reduced(prom, scene, xi, sensitivities=True)
        assert batch.completed[b] == single.completed
        assert batch.cut_steps[b] == single.cut_steps > 0
        if single.completed:
            assert batch.distance[b] == single.distance
            assert np.array_equal(batch.distance_gradient[b], single.distance_gradient)
        else:
            assert batch.errors[b] == single.error
