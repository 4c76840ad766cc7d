"""The lockstep kernel (``lockstep_kernel``: blocks of designs advanced through each step together) against the
per-design kernel and ``simulate_reduced``: lanes that converge at different iterations, a lane that fails, a last
block that the batch does not fill; and its one compiled signature."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import lockstep_kernel, reduced_kernel
from aquarom_fenics.dynamics.batched import simulate_batch
from aquarom_fenics.dynamics.batched_system import BatchedSystem
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import check_time_grid
from aquarom_fenics.fem.time_scheme import TimeScheme
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene
from prom_checks import SO1_SHAPES, assert_batch_matches_single_runs, max_relative_error

pytestmark = pytest.mark.skipif(not reduced_kernel.available(), reason="numba is not installed")

LANES = lockstep_kernel.LANES
FEW_ITERATIONS = {"duration": 0.4, "max_iterations": 5}
"""Enough Newton iterations for SO1's designs at up to 1.5 times the amplitude, too few at 4 times (with each step's
factors refreshed at its predictor the kernel's Newton fails from 3.5 times on)."""


@pytest.fixture(scope="module")
def prom():
    scene = coarse_scene(shapes=SO1_SHAPES, solver=FEW_ITERATIONS)
    return build_prom(scene, fish=load_fish(scene))


@pytest.fixture
def blocks(monkeypatch) -> list[int]:
    """The batch size of every call of the lockstep kernel in the test (``reduced_kernel.integrate_lockstep``)."""
    sizes = []
    integrate = reduced_kernel.integrate_lockstep

    def counted(arguments, batch, columns):
        sizes.append(batch)
        return integrate(arguments, batch, columns)

    monkeypatch.setattr(reduced_kernel, "integrate_lockstep", counted)
    return sizes


def spread(prom, count: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return prom.xi_center + prom.validity_radius * rng.uniform(-1.0, 1.0, (count, prom.n_parameters))


def test_the_lockstep_kernel_equals_the_per_design_kernel_lane_by_lane(prom):
    """Eleven designs: a full block and a last block of three; amplitudes 0.3-1.5 times the scene's make the
    lanes' Newton iterations differ from step to step, and the fifth design's 4 times makes its Newton fail."""
    scene = coarse_scene(shapes=SO1_SHAPES, solver=FEW_ITERATIONS)
    count = LANES + 3
    xis = spread(prom, count)
    amplitudes = scene.actuation.amplitude * np.linspace(0.3, 1.5, count)
    amplitudes[4] = 4.0 * scene.actuation.amplitude
    iterations = np.array([simulate_reduced(prom, scene, xis[b], amplitude=amplitudes[b]).trajectory
                           .newton_iterations[1:] for b in range(LANES) if b != 4])     # the full block's

    assert (iterations.min(axis=0) != iterations.max(axis=0)).sum() > iterations.shape[1] // 2
    system = BatchedSystem(prom, scene, xis, TimeScheme.from_solver(scene.solver), amplitudes)
    packed = reduced_kernel.pack(system, scene, check_time_grid(scene), True, True)
    distance, amplitude, failed, gradient = reduced_kernel.integrate_packed(packed, lockstep=False)
    results, gradients = lockstep_kernel.integrate_lockstep(packed.arguments, count, packed.columns)
    assert np.flatnonzero(failed).tolist() == [4]
    assert np.flatnonzero(results[:, 2] != reduced_kernel.OK).tolist() == [4]
    for b in np.flatnonzero(~failed):
        assert max_relative_error(results[b, 0], distance[b]) < 1e-12
        assert max_relative_error(results[b, 1], amplitude[b]) < 1e-12
        assert max_relative_error(gradients[b], gradient[b]) < 1e-12


def test_a_batch_in_lockstep_agrees_with_single_runs(blocks):
    """Nine designs through ``simulate_batch``: eight in one block, the ninth alone (``LOCKSTEP_TAIL``)."""
    scene = coarse_scene(shapes=SO1_SHAPES, solver={"duration": 0.4})
    prom = build_prom(scene, fish=load_fish(scene))
    xis = spread(prom, LANES + 1)
    amplitudes = scene.actuation.amplitude * np.linspace(0.8, 1.2, LANES + 1)
    batch = simulate_batch(prom, scene, xis, sensitivities=True, amplitudes=amplitudes, amplitude_sensitivity=True,
                           engine="compiled")
    assert blocks == [LANES]
    assert_batch_matches_single_runs(prom, scene, xis, amplitudes, batch)


def test_the_lockstep_kernel_has_one_compiled_signature_for_a_real_batch_and_the_warm_up(prom):
    reduced_kernel.warm_up()
    scene = coarse_scene(shapes=SO1_SHAPES, solver={"duration": 0.1})
    simulate_batch(prom, scene, spread(prom, LANES), sensitivities=True, engine="compiled")
    assert len(lockstep_kernel.integrate_blocks.signatures) == 1


@pytest.mark.parametrize("fluid", [
    {"spine_force": "lagrangian", "spine_rule": "rear"},
    {"spine_force": "lagrangian", "spine_rule": "trapezoid", "drag": False},
], ids=["lagrangian-rear", "lagrangian-trapezoid-no-drag"])
def test_a_block_with_the_lagrangian_spine_force_agrees_with_single_runs(fluid, blocks):
    """The Lagrangian force's extra blocks (the other point's stiffness and damping) in lockstep: a full block of
    designs with two shape parameters, one of which moves the tail's rest stations."""
    shapes = {"xz_concave_tail": {"bounds": [-0.01, 0.2]}, "y_thin": {"bounds": [-0.15, 0.15]}}
    scene = coarse_scene(shapes=shapes, solver={"duration": 0.3}, fluid=fluid)
    prom = build_prom(scene, fish=load_fish(scene))
    xis = spread(prom, LANES, seed=5)
    amplitudes = scene.actuation.amplitude * np.linspace(0.8, 1.2, LANES)
    batch = simulate_batch(prom, scene, xis, sensitivities=True, amplitudes=amplitudes, amplitude_sensitivity=True,
                           engine="compiled")
    assert blocks == [LANES]
    assert_batch_matches_single_runs(prom, scene, xis, amplitudes, batch)
