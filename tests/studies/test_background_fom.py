"""The start design's FOM in a worker process: its distance lands in the FOM cache, equal to a run here."""
import json
import time

import pytest

from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.studies.background_fom import BackgroundFom
from aquarom_fenics.studies.study import fom_cache_path


def test_worker_stores_the_start_distance_a_run_here_computes(make_scene):
    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    design = {"z_tail": 0.05}
    path = fom_cache_path(scene, design, None)
    assert not path.exists()
    run = BackgroundFom(scene, design, None)
    run.finish(patience=300.0)
    assert run.future.done() and run.pool._pool is None     # the worker process is gone
    stored = json.loads(path.read_text())["distance"]
    assert stored == pytest.approx(simulate_fom(scene, design, progress=False).distance, rel=1e-12)


def test_stop_ends_the_worker_at_once_and_stores_nothing(make_scene):
    scene = make_scene(solver={"duration": 2.0}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    design = {"z_tail": -0.05}
    run = BackgroundFom(scene, design, None)
    started = time.perf_counter()
    run.stop()
    assert time.perf_counter() - started < 20.0
    assert run.future.done() and run.pool._pool is None
    assert not fom_cache_path(scene, design, None).exists()
