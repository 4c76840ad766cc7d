"""PROMs keyed by what a build reads (``Scene.prom_hash``): scenes differing only in the optimiser's
settings (or the output, name, shape starts, constraints, co-optimisation weights) share their PROMs in
the cache and their PROM files; any value a build reads makes another PROM; an entry of the old format
or of other values is a miss, rebuilt. Coarsest mesh."""
import json

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.persistence import store
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.cache import cached_prom
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene

SHAPES = {"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1], "radius": 0.025}}
BASE = {"mesh": {"degree": 1}, "shapes": SHAPES, "solver": {"duration": 0.2}}


def scene_with(**changes):
    """The base scene (level 1, two shapes) with some tables changed or added."""
    tables = {name: dict(table) for name, table in BASE.items()}
    for name, table in changes.items():
        tables[name] = {**tables.get(name, {}), **table}
    return coarse_scene(**tables)


OPTIMIZER_ONLY = {
    "method": {"optimizer": {"method": "trust-region"}},
    "starts": {"optimizer": {"starts": 3, "seed": 4}},
    "screen": {"optimizer": {"starts": 2, "screen": 200}},
    "atlas": {"optimizer": {"atlas": True}},
    "tolerances": {"optimizer": {"optimality_tolerance": 1e-3, "step_tolerance": 1e-4, "max_iterations": 7,
                                 "rebuild_threshold": 0.3, "n_rebuild": 2, "tail_screen": True}},
    "output": {"output": {"xdmf": True, "plots": False}},
    "co-optimisation": {"cooptimization": {"enabled": True, "weights": [0.5], "energy_weight": 2.0,
                                           "effort": "power"}},
    "shape starts": {"shapes": {"z_tail": {"bounds": [-0.2, 0.2], "start": 0.1},
                                "y_thin": {"bounds": [-0.1, 0.1], "radius": 0.025, "start": -0.05}}},
}

READ_BY_A_BUILD = {
    "material": {"material": {"young_modulus": 2.5e5}},
    "mesh level": {"mesh": {"level": 2}},
    "mesh degree": {"mesh": {"degree": 2}},
    "vibration modes": {"reduction": {"vibration_modes": 2}},
    "taylor order": {"reduction": {"taylor_order": 2}},
    "validity fraction": {"reduction": {"validity_fraction": 0.3}},
    "stroke": {"reduction": {"stroke_amplitude": 0.2}},
    "shape bounds": {"shapes": {"z_tail": {"bounds": [-0.3, 0.2]}}},
    "shape radius": {"shapes": {"y_thin": {"bounds": [-0.1, 0.1], "radius": 0.03}}},
    "another shape": {"shapes": {"z_head": {"bounds": [-0.5, 0.5]}}},
    "fluid density": {"fluid": {"density": 1025.0}},
    "thrust off": {"fluid": {"thrust": False}},
    "amplitude": {"actuation": {"amplitude": 0.3}},
    "frequency": {"actuation": {"frequency": 1.5}},
    "time step": {"solver": {"time_step": 0.01}},
    "regions": {"regions": {"head_fraction": 0.3}},
}


def test_scenes_differing_only_in_what_no_build_reads_share_the_prom_key():
    base = scene_with()
    for label, change in OPTIMIZER_ONLY.items():
        other = scene_with(**change)
        assert other.prom_hash == base.prom_hash, label
        assert other.hash != base.hash, label         # the scene hash still tells them apart
    renamed = scene_from_toml(base.to_toml().replace('name = "<test>"', 'name = "copy"').replace(
        'description = ""', 'description = "a copy"'))
    assert renamed.name == "copy" and renamed.hash != base.hash and renamed.prom_hash == base.prom_hash
    constrained = scene_from_toml(base.to_toml() + '\n[[constraints]]\ncoefficients = { z_tail = 1.0 }\nupper = 0.1\n')
    assert constrained.constraints and constrained.prom_hash == base.prom_hash


def scene_from_toml(text: str) -> Scene:
    import tomllib

    from aquarom_fenics.io.scene import scene_from_dict
    return scene_from_dict(tomllib.loads(text), source="<test>")


@pytest.mark.parametrize("label", sorted(READ_BY_A_BUILD))
def test_what_a_build_reads_changes_the_prom_key(label):
    assert scene_with(**READ_BY_A_BUILD[label]).prom_hash != scene_with().prom_hash


def test_muscles_and_the_coupled_stroke_amplitude_change_the_prom_key():
    """[[muscles]] tables, and on a body from a mesh file the stroke amplitude "auto" = the largest
    amplitude the scene runs, which [cooptimization] sets when it is on: the only key of that section
    a build reads."""
    base = scene_with()
    muscles = scene_from_toml(base.to_toml() + (
        '\n[[muscles]]\nregion = "left_muscle"\n\n[[muscles]]\nregion = "right_muscle"\nscale = -0.5\n'))
    assert muscles.prom_hash != base.prom_hash
    fish = Scene.load("fish").replace("reduction", stroke_amplitude="auto")
    assert fish.reduction.stroke_amplitude == "auto" and fish.mesh_file is not None
    coupled = fish.replace("cooptimization", enabled=True, amplitude_bounds=(0.05, 0.35))
    assert coupled.prom_hash != fish.prom_hash
    weights_only = fish.replace("cooptimization", weights=(0.5, 0.6))
    assert weights_only.prom_hash == fish.prom_hash


def test_every_tensor_of_a_build_is_the_same_for_scenes_that_share_the_key():
    """What the key leaves out is never read by a build: two scenes differing in every such value build
    identical PROMs."""
    base = scene_with()
    other = scene_with(optimizer={"method": "trust-region", "starts": 3, "screen": 50, "tail_screen": True},
                       output={"render": False},
                       cooptimization={"enabled": True, "weights": [0.3], "effort": "power"},
                       shapes={"z_tail": {"bounds": [-0.2, 0.2], "start": 0.15}})
    assert other.prom_hash == base.prom_hash and other.hash != base.hash
    center = np.array([0.05, -0.01])
    first, second = build_prom(base, xi_center=center), build_prom(other, xi_center=center)
    assert first.labels == second.labels
    np.testing.assert_array_equal(first.basis, second.basis)
    np.testing.assert_array_equal(first.validity_radius, second.validity_radius)
    arrays = first.term_arrays()
    assert arrays.keys() == second.term_arrays().keys()
    for name, value in second.term_arrays().items():
        np.testing.assert_array_equal(value, arrays[name], err_msg=name)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "prom"


@pytest.fixture(scope="module")
def prom():
    return build_prom(scene_with(), xi_center=np.zeros(2))


def counting(prom):
    builds = []

    def build():
        builds.append(1)
        return prom
    return builds, build


def test_a_prom_cached_for_one_scene_is_served_to_a_scene_differing_in_the_optimiser(cache, prom):
    builds, build = counting(prom)
    cached_prom(scene_with(), np.zeros(2), build)
    served = cached_prom(scene_with(optimizer={"atlas": True}), np.zeros(2), build)
    served_again = cached_prom(scene_with(optimizer={"starts": 2, "screen": 100}), np.zeros(2), build)
    assert builds == [1] and len(list(cache.glob("*.npz"))) == 1
    for model in (served, served_again):
        np.testing.assert_array_equal(model.inertia.mass.constant, prom.inertia.mass.constant)
    cached_prom(scene_with(material={"young_modulus": 2.5e5}), np.zeros(2), build)
    assert builds == [1, 1] and len(list(cache.glob("*.npz"))) == 2


def rewritten(prom: ReducedModel, path, edit) -> None:
    """``prom`` saved to ``path`` with its header edited, sealed as the cache seals its entries."""
    prom.save(path)
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files}
    header = edit(json.loads(arrays["header"].tobytes().decode()))
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(path, **arrays)
    content = path.read_bytes()
    store(path, lambda target: target.write_bytes(content))


def format_4(header):
    """A header written before PROMs were keyed by what they read: format 4, no prom_hash."""
    header.pop("prom_hash")
    return header | {"format_version": 4}


@pytest.mark.parametrize("edit", [format_4, lambda header: header | {"prom_hash": "0123456789abcdef"}],
                         ids=["format 4", "other values"])
def test_an_old_format_or_mismatching_cache_entry_is_a_miss(cache, prom, edit):
    builds, build = counting(prom)
    scene = scene_with()
    cached_prom(scene, np.zeros(2), build)
    [entry] = cache.glob("*.npz")
    rewritten(prom, entry, edit)
    with pytest.raises(InputError):
        ReducedModel.load(entry, prom_hash=scene.prom_hash)
    again = cached_prom(scene, np.zeros(2), build)
    assert builds == [1, 1]
    assert ReducedModel.load(entry, prom_hash=scene.prom_hash).prom_hash == scene.prom_hash
    np.testing.assert_array_equal(again.basis, prom.basis)


def test_a_prom_file_is_checked_by_what_its_build_read(prom, tmp_path):
    path = tmp_path / "p.npz"
    prom.save(path)
    assert ReducedModel.load(path, prom_hash=scene_with(optimizer={"atlas": True}).prom_hash).size == prom.size
    with pytest.raises(InputError, match="PROM hash .* rebuild it"):
        ReducedModel.load(path, prom_hash=scene_with(fluid={"density": 1025.0}).prom_hash)
    rewritten(prom, tmp_path / "old.npz", format_4)
    with pytest.raises(InputError, match="format version 4"):
        ReducedModel.load(tmp_path / "old.npz")
