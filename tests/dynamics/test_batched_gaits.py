"""A batch whose designs each carry their own gait (``simulate_batch(..., scenes=...)``): both engines agree with
``simulate_reduced`` of each design's driven scene, on the coarsest block's wave."""
import numpy as np
import pytest

from aquarom_fenics.dynamics import reduced_kernel
from aquarom_fenics.dynamics.batched import simulate_batch
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.io.scene_gait import apply_gait
from aquarom_fenics.reduction.reductor import build_prom

PAIRS = [{"region": f"{side}_{k}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (k - 1)}
         for k in (1, 2, 3) for side in ("left", "right")]
GAITS = [{"frequency": 1.0, "phase_lag": 120.0}, {"frequency": 1.4, "phase_lag": 60.0},
         {"frequency": 0.8, "phase_lag": 150.0, "amplitude_2": 0.25}]


@pytest.fixture(scope="module")
def wave():
    scene = scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "muscles": PAIRS,
                             "shapes": {"z_tail": {"bounds": [-0.2, 0.2]}}, "solver": {"duration": 0.3},
                             "gait": {"frequency": {"bounds": [0.5, 2.0]}, "phase_lag": {"bounds": [30, 180]},
                                      "amplitude_2": {"bounds": [0.1, 0.3]}}}, source="<test>")
    return scene, build_prom(scene)


@pytest.mark.parametrize("engine", ["numpy", "compiled"])
def test_each_design_of_a_batch_runs_its_own_gait_as_a_single_run_would(wave, engine):
    if engine == "compiled" and not reduced_kernel.available():
        pytest.skip("numba is not installed")
    scene, prom = wave
    driven = [apply_gait(scene, gait) for gait in GAITS]
    xis = np.array([[0.0], [0.03], [-0.02]])
    batch = simulate_batch(prom, scene, xis, scenes=driven, engine=engine)
    assert batch.completed.all() and not batch.alone.any()
    for b, own in enumerate(driven):
        single = simulate_reduced(prom, own, xis[b])
        assert abs(batch.distance[b] - single.distance) <= 1e-12 * abs(single.distance)
        assert abs(batch.tail_amplitude[b] - single.tail_amplitude) <= 1e-12 * single.tail_amplitude
    same = simulate_batch(prom, scene, xis, engine=engine)               # the scene's own gait for all
    assert same.distance[1] != pytest.approx(batch.distance[1], rel=1e-3)
    assert same.distance[0] == pytest.approx(batch.distance[0], rel=1e-12)


def test_a_batch_refuses_a_scene_count_other_than_its_designs(wave):
    scene, prom = wave
    with pytest.raises(ValueError, match="2 scenes for 3 designs"):
        simulate_batch(prom, scene, np.zeros((3, 1)), scenes=[scene, scene])
