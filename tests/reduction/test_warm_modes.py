"""The eigen-solve of a build started from a nearby design's modes: the same modes to the solver's
tolerance, with the start's signs."""
import numpy as np
import pytest

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.basis import clamped_stiffness, vibration_modes


@pytest.fixture(scope="module")
def models():
    scene = Scene.load("so1").replace("mesh", level=1, degree=1)
    fish = load_fish(scene)
    fom = FullOrderModel(scene, fish, np.zeros(3))
    stiffness = clamped_stiffness(fom)
    start, _ = vibration_modes(fom, stiffness, 2)
    stiffness.destroy()
    fom.move_to(np.array([-0.3, 0.2, 0.1]))
    yield fom, start
    fom.destroy()


def test_modes_from_a_nearby_start_equal_the_cold_ones_with_the_start_sign(models):
    fom, start = models
    stiffness = clamped_stiffness(fom)
    cold, cold_frequencies = vibration_modes(fom, stiffness, 2)
    for sign in (1.0, -1.0):
        warm, warm_frequencies = vibration_modes(fom, stiffness, 2, initial=sign * start)
        np.testing.assert_allclose(warm_frequencies, cold_frequencies, rtol=1e-10)
        for i in range(2):
            assert warm[:, i] @ (sign * start[:, i]) > 0            # the start's sign
            aligned = cold[:, i] * np.sign(cold[:, i] @ warm[:, i])
            assert np.linalg.norm(warm[:, i] - aligned) <= 1e-8 * np.linalg.norm(aligned)
    mismatched, _ = vibration_modes(fom, stiffness, 1, initial=start)      # a start of another count: cold
    assert np.linalg.norm(mismatched[:, 0] - cold[:, 0] * np.sign(cold[:, 0] @ mismatched[:, 0])) <= 1e-8 * np.linalg.norm(cold[:, 0])
    stiffness.destroy()
