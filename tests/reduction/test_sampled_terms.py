"""Reduced inertia and muscle tensors sampled at the quadrature points equal the projected assembled forms (SPEC §8)."""
import numpy as np
import pytest

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.physics.inertia import sampled_inertia
from aquarom_fenics.physics.muscle import MuscleTensors
from aquarom_fenics.reduction.basis import build_basis
from aquarom_fenics.physics.taylor import stack_taylor
from aquarom_fenics.reduction.projection import Projector
from aquarom_fenics.io.scene import scene_from_dict
from conftest import coarse_scene
from prom_checks import SO1_SHAPES


@pytest.mark.parametrize("degree, order", [(1, 2), (2, 1)])
def test_sampled_inertia_equals_the_projected_assembled_forms(degree, order):
    """Vᵀ M V, Vᵀ m, ∫ρ dV_ξ and their first and second ξ-derivatives, off the nominal design."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES)
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, order)
    inertia = model.inertia
    assembled = [projector.taylor(form) for form in (inertia.mass_form, inertia.mass_moment_form,
                                                     inertia.total_mass_form)]
    for expected, sampled in zip(assembled, sampled_inertia(model, projector, inertia.density)):
        for name in ("constant", "first", "second"):
            reference, value = getattr(expected, name), getattr(sampled, name)
            assert (reference is None) == (value is None), name
            if reference is not None:
                assert np.abs(value - reference).max() <= 1e-12 * np.abs(reference).max(), name
    assert assembled[0].second is not None or order == 1


@pytest.mark.parametrize("degree, order, volume", [(1, 2, "shape"), (2, 1, "shape"), (1, 1, "nominal")])
def test_sampled_muscle_tensors_equal_the_projected_assembled_forms(degree, order, volume):
    """b_j, B_j of both muscles and their ξ-derivatives, off the nominal design, either muscle volume."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES, actuation={"muscle_volume": volume})
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, order)
    expected, sampled = projected_muscle_tensors(model, projector), model.muscle.reduce(projector)
    for part in ("constant", "linear"):
        scale = np.abs(getattr(expected, part).constant).max()
        for name in ("constant", "first", "second"):
            reference, value = getattr(getattr(expected, part), name), getattr(getattr(sampled, part), name)
            assert (reference is None) == (value is None), (part, name)
            if reference is not None:
                assert np.abs(value - reference).max() <= 1e-11 * scale, (part, name)


def test_sampled_tensors_of_several_muscles_with_their_own_fibres():
    """Three muscles of the block's segments, one with an oblique and one with a reversed fibre."""
    fibres = ([1.0, 0.0, 0.0], [0.6, 0.0, 0.8], [-1.0, 0.0, 0.0])
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": SO1_SHAPES, "regions": {"muscle_pairs": 3},
                             "muscles": [{"region": region, "fibre": fibre, "phase": 60 * k}
                                         for k, (region, fibre) in enumerate(zip(("left_1", "right_2", "left_3"), fibres))]},
                            source="<test>")
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, 1)
    expected, sampled = projected_muscle_tensors(model, projector), model.muscle.reduce(projector)
    assert sampled.constant.constant.shape[0] == 3
    for part in ("constant", "linear"):
        scale = np.abs(getattr(expected, part).constant).max()
        for name in ("constant", "first"):
            reference, value = getattr(getattr(expected, part), name), getattr(getattr(sampled, part), name)
            assert np.abs(value - reference).max() <= 1e-11 * scale, (part, name)


def projected_muscle_tensors(model, projector) -> MuscleTensors:
    """b_j, B_j projected from the assembled force and tangent forms of muscle j alone (a_j = 1) at rest."""
    muscle = model.muscle
    model.set_displacement(np.zeros(model.n_owned_dofs))
    constant_parts, linear_parts = [], []
    for unit in np.eye(len(muscle.measures)):
        muscle.set_activations(unit)
        constant_parts.append(projector.taylor(muscle.negative_force_form))
        linear_parts.append(projector.taylor(muscle.tangent_form))
    return MuscleTensors(stack_taylor(constant_parts), stack_taylor(linear_parts))
