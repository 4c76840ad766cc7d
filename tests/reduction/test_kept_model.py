"""Builds on the kept model (moved from design to design) give the PROM of a model made at the design."""
import numpy as np
import pytest
from petsc4py import PETSc

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.kept_model import KEPT_MODEL
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene
from prom_checks import SO1_SHAPES


def prom_arrays(prom) -> dict[str, np.ndarray]:
    """Every tensor of a PROM by name, with its basis, radius, frequencies and observation rows."""
    return {**prom.term_arrays(), "basis": prom.basis, "validity_radius": prom.validity_radius,
            "frequencies": np.asarray(prom.frequencies), "head_x_row": prom.observation.head_x_row,
            "tail_y_row": prom.observation.tail_y_row}


@pytest.mark.parametrize("sections", [{"mesh": {"degree": 2}},
                                      {"mesh": {"degree": 1}, "reduction": {"taylor_order": 2},
                                       "material": {"mass": "lumped"}}])
def test_a_moved_model_builds_the_prom_of_a_new_one(sections):
    scene = coarse_scene(shapes=SO1_SHAPES, **sections)
    fish = load_fish(scene)
    start, target = np.array([0.0, 0.0, 0.0]), np.array([-0.3, 0.2, 0.1])
    KEPT_MODEL.release()
    fresh = build_prom(scene, xi_center=target, fish=fish)
    first = build_prom(scene, xi_center=start, fish=fish)
    model = KEPT_MODEL.model
    moved = build_prom(scene, xi_center=target, fish=fish)
    assert KEPT_MODEL.model is model                       # the same model, moved twice
    reused = build_prom(scene, xi_center=target, fish=fish, basis_from=first)
    KEPT_MODEL.release()
    fresh_reused = build_prom(scene, xi_center=target, fish=fish, basis_from=first)
    for expected, value in ((fresh, moved), (fresh_reused, reused)):
        reference, arrays = prom_arrays(expected), prom_arrays(value)
        assert reference.keys() == arrays.keys()
        for name, array in reference.items():
            scale = np.abs(array).max(initial=0.0)
            assert np.abs(arrays[name] - array).max(initial=0.0) <= 1e-12 * scale, name
    assert not np.allclose(prom_arrays(first)["elastic.linear.constant"], prom_arrays(fresh)["elastic.linear.constant"])


def test_another_scene_replaces_the_kept_model():
    scene = coarse_scene(shapes=SO1_SHAPES)
    fish = load_fish(scene)
    build_prom(scene, fish=fish)
    model = KEPT_MODEL.model
    other = scene.replace("material", young_modulus=2 * scene.material.young_modulus)
    build_prom(other, fish=fish)
    assert KEPT_MODEL.model is not model and KEPT_MODEL.key[0] == other.hash
    storages = [value[2] for value in KEPT_MODEL.model.kept.values() if isinstance(value, tuple) and len(value) == 3
                and isinstance(value[2], PETSc.Object)]
    assert storages and all(storage.handle != 0 for storage in storages)
    KEPT_MODEL.release()
    assert KEPT_MODEL.model is None
    assert all(storage.handle == 0 for storage in storages)
