"""One FOM-answer cache: an entry written by the optimiser's FOM check is read by a sweep without a
FOM run, and the other way round; old entries and stopped runs are handled as the module says."""
import json
from types import SimpleNamespace

import pytest

from aquarom_fenics.errors import SolverError
from aquarom_fenics.io.persistence import store, write_json_atomic
from aquarom_fenics.studies import fom_cache
from aquarom_fenics.geometry.fish_cache import shared_fish
from aquarom_fenics.studies.sweep import SweepTask, cached_designs, evaluate


@pytest.fixture
def counted_fom(monkeypatch, tmp_path):
    """A cache of this test's own, and the FOM runs made through the FOM cache counted."""
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    runs = []
    original = fom_cache.simulate_fom

    def counting(scene, design, **options):
        runs.append(dict(design))
        return original(scene, design, **options)

    monkeypatch.setattr(fom_cache, "simulate_fom", counting)
    return runs


def sweep_row(scene, design):
    return evaluate(SweepTask(0, design, "fom", scene))


def test_an_optimiser_entry_is_reused_by_a_sweep_and_a_sweep_entry_by_the_optimiser(make_scene, counted_fom):
    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    fish = shared_fish(scene)
    checked, swept = {"z_tail": 0.1}, {"z_tail": -0.1}

    distance = fom_cache.fom_distance(scene, fish, checked, None)        # the optimiser's FOM check
    assert counted_fom == [checked]
    row = sweep_row(scene, checked)
    assert counted_fom == [checked], "the sweep ran the FOM again at a design the check had answered"
    assert row["status"] == "completed" and row["cached"] and row["distance_m"] == distance
    assert row["tail_amplitude_m"] > 0

    first = sweep_row(scene, swept)                                         # the sweep first ...
    assert counted_fom == [checked, swept] and not first["cached"]
    assert fom_cache.fom_distance(scene, fish, swept, None) == first["distance_m"]   # ... then the check
    assert counted_fom == [checked, swept], "the optimiser's check ran the FOM again at a swept design"
    assert cached_designs(scene, [checked, swept, {"z_tail": 0.0}], "fom") == 2


def test_an_entry_holds_the_answer_its_stop_reason_and_what_computed_it(make_scene, counted_fom):
    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    design = {"z_tail": 0.05}
    answer = fom_cache.fom_answer(scene, design)
    entry = json.loads(fom_cache.fom_cache_path(scene, design, None).read_text())
    assert entry["distance"] == answer.distance and entry["tail_amplitude"] == answer.tail_amplitude
    assert entry["stop_reason"] == "completed" and entry["fom_hash"] == scene.fom_hash
    computed_by = entry["computed_by"]
    assert computed_by["model"] == "fom" and computed_by["cells"] > 0 and computed_by["steps"] == 10
    assert computed_by["wall_time"] > 0 and "dolfinx" in computed_by["versions"]
    again = fom_cache.fom_answer(scene, design)
    assert again.cached and not answer.cached and again.distance == answer.distance and len(counted_fom) == 1


def test_a_distance_only_entry_serves_the_optimiser_and_is_a_miss_for_the_sweep(make_scene, counted_fom):
    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    design = {"z_tail": 0.0}
    path = fom_cache.fom_cache_path(scene, design, None)
    old = {"design": design, "scene_hash": scene.hash, "fom_hash": scene.fom_hash, "distance": 0.0123}
    store(path, lambda target: write_json_atomic(target, old))          # as the optimiser wrote it before
    assert fom_cache.fom_distance(scene, shared_fish(scene), design, None) == 0.0123
    assert counted_fom == [] and cached_designs(scene, [design], "fom") == 0
    row = sweep_row(scene, design)
    assert counted_fom == [design] and not row["cached"] and row["distance_m"] != 0.0123
    rewritten = json.loads(path.read_text())
    assert rewritten["tail_amplitude"] == row["tail_amplitude_m"] and rewritten["stop_reason"] == "completed"


def test_a_stopped_run_gives_its_reason_to_both_callers_and_is_not_stored(make_scene, monkeypatch, tmp_path):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    reason = "Newton did not converge at t = 0.1 s (step 5 of 10)"
    stopped = SimpleNamespace(completed=False, error=reason, distance=None, tail_amplitude=None, n_cells=1,
                              n_dofs=3, trajectory=[0] * 6, wall_time=0.5)
    monkeypatch.setattr(fom_cache, "simulate_fom", lambda scene, design, **options: stopped)
    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    design = {"z_tail": 0.1}
    with pytest.raises(SolverError, match="step 5 of 10"):
        fom_cache.fom_distance(scene, object(), design, None)
    row = sweep_row(scene, design)
    assert row["status"] == "stopped" and row["reason"] == reason
    assert not fom_cache.fom_cache_path(scene, design, None).exists()


def test_a_validation_fom_case_offers_its_answer_to_the_studies(make_scene, counted_fom, tmp_path):
    from aquarom_fenics.verification.validation.cases import fom_case
    from aquarom_fenics.verification.validation.runner import Runner

    scene = make_scene(solver={"duration": 0.2}, shapes={"z_tail": {"bounds": [-0.2, 0.2]}})
    with open(tmp_path / "progress.txt", "w") as stream:
        record, _ = Runner(tmp_path / "validation", stream=stream).compute_and_store(
            fom_case("FOM", scene, xi=[0.1], energy=False))
    assert record["status"] == "completed"
    runs = len(counted_fom)
    answer = fom_cache.fom_answer(scene, {"z_tail": 0.1}, need_tail=True)
    assert len(counted_fom) == runs and answer.cached, "the studies ran the FOM the validation had run"
    assert (answer.distance, answer.tail_amplitude) == (record["distance"], record["tail_amplitude"])
    from aquarom_fenics.dynamics.simulate import simulate_fom

    again = simulate_fom(scene, {"z_tail": 0.1}, progress=False)        # what the studies would compute
    assert (again.distance, again.tail_amplitude) == (record["distance"], record["tail_amplitude"])
