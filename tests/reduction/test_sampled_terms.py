"""Reduced inertia and muscle tensors sampled at the quadrature points equal the projected assembled forms (SPEC §8)."""
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.physics.inertia import sampled_inertia
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.muscle import muscle_energy_density
from aquarom_fenics.physics.muscle import MuscleTensors, muscle_cells
from aquarom_fenics.physics.taylor import taylor_of
from aquarom_fenics.reduction.basis import build_basis
from aquarom_fenics.physics.taylor import stack_taylor
from aquarom_fenics.reduction.projection import Projector
from aquarom_fenics.io.scene import scene_from_dict
from conftest import coarse_scene
from prom_checks import SO1_SHAPES


@pytest.mark.parametrize("degree, order", [(1, 2), (2, 1)])
def test_sampled_inertia_equals_the_projected_assembled_forms(degree, order):
    """Vᵀ M V, Vᵀ m_x, ∫ρ dV_ξ, Vᵀ m_y and their first and second ξ-derivatives, off the nominal design."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES)
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, order)
    inertia = model.inertia
    assembled = [projector.taylor(form) for form in (inertia.mass_form, inertia.mass_moment_form,
                                                     inertia.total_mass_form, inertia.mass_moment_y_form)]
    for expected, sampled in zip(assembled, sampled_inertia(model, projector, inertia.density)):
        for name in ("constant", "first", "second"):
            reference, value = getattr(expected, name), getattr(sampled, name)
            assert (reference is None) == (value is None), name
            if reference is not None:
                assert np.abs(value - reference).max() <= 1e-12 * np.abs(reference).max(), name
    assert assembled[0].second is not None or order == 1


def muscle_tensor_pairs(expected, computed):
    """(part, name, reference, value, scale) of the muscle tensors' constant and linear parts, each Taylor term
    (constant, first, second; None where not built); scale = max |part's constant term| of ``expected``."""
    for part in ("constant", "linear"):
        scale = np.abs(getattr(expected, part).constant).max()
        for name in ("constant", "first", "second"):
            yield part, name, getattr(getattr(expected, part), name), getattr(getattr(computed, part), name), scale


@pytest.mark.parametrize("degree, order, volume", [(1, 2, "shape"), (2, 1, "shape"), (1, 1, "nominal")])
def test_sampled_muscle_tensors_equal_the_projected_assembled_forms(degree, order, volume):
    """b_j, B_j of both muscles and their ξ-derivatives, off the nominal design, either muscle volume."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES, actuation={"muscle_volume": volume})
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, order)
    expected, sampled = projected_muscle_tensors(model, projector), model.muscle.reduce(projector)
    for part, name, reference, value, scale in muscle_tensor_pairs(expected, sampled):
        assert (reference is None) == (value is None), (part, name)
        if reference is not None:
            assert np.abs(value - reference).max() <= 1e-11 * scale, (part, name)


@pytest.mark.parametrize("degree, order, volume", [(1, 2, "shape"), (2, 2, "shape"), (2, 1, "nominal")])
def test_muscle_tensors_from_the_stretch_equal_the_sampled_energy(degree, order, volume):
    """b_j, B_j and their ξ-derivatives from the stretches (1 + m evaluations a muscle) against the muscle energy
    itself sampled at u = 0, ±V_i and V_i + V_k (it is quadratic in u), to 1e-12."""
    scene = coarse_scene(mesh={"degree": degree}, shapes=SO1_SHAPES, actuation={"muscle_volume": volume})
    model = FullOrderModel(scene, load_fish(scene), np.array([0.1, -0.2, 0.05]))
    projector = Projector(model, build_basis(model, 3).vectors, 3, order)
    expected, computed = energy_sampled_muscle_tensors(model, projector), model.muscle.reduce(projector)
    for part, name, reference, value, part_scale in muscle_tensor_pairs(expected, computed):
        assert (reference is None) == (value is None) and (reference is not None or (name, order) == ("second", 1))
        if reference is not None:
            # relative to the term itself; to the part's value for a term zero but for rounding (with the
            # nominal muscle volume B_j does not vary with ξ)
            scale = np.abs(reference).max()
            scale = part_scale if scale < 1e-6 * part_scale else scale
            assert scale > 0 and np.abs(value - reference).max() <= 1e-12 * scale, (part, name)


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


def energy_sampled_muscle_tensors(model, projector) -> MuscleTensors:
    """b_j, B_j from muscle j's energy Π_j at unit activation sampled at u = 0, ±V_i and V_i + V_k, with its
    ξ-derivatives (UFL derivatives of ψ along the shape directions) in the same evaluations:
    b_i = (Π(V_i) - Π(-V_i)) / 2, B_ii = Π(V_i) + Π(-V_i) - 2 Π(0), B_ik = Π(V_i + V_k) - Π(0) - b_i - b_k - ½ (B_ii + B_kk)."""
    scene, vectors = model.scene, projector.vectors
    m, p, order = vectors.shape[1], projector.n_parameters, projector.order
    sample = fx.new_function(model.space, "reference_muscle_sample")
    directions = [model.shape_direction(f"reference_direction_{k}") for k in range(p if order >= 1 else 0)]
    for k, direction in enumerate(directions):
        direction.set_parameter(k)
    pairs = [(k, l) for k in range(p) for l in range(k, p)] if order >= 2 else []
    degree = model.quadrature_degrees["stiffness"]
    reference_weights = fx.quadrature_rule(degree)[1]
    column = {index: n for n, index in enumerate([()] + [(k,) for k in range(len(directions))] + pairs)}

    def expression(fibre):
        density = muscle_energy_density(sample, model.shape_gradients["stiffness"],
                                        fx.constant(model.mesh, scene.actuation.stiffness),
                                        nominal_volume=scene.actuation.muscle_volume == "nominal", fibre=fibre)
        first = [model.shape_derivative(density, direction) for direction in directions]
        second = [model.shape_derivative(first[k], directions[l]) for k, l in pairs]
        return fx.compile_quadrature_expression(
            abs(ufl.JacobianDeterminant(model.mesh)) * ufl.as_vector([density] + first + second), degree)

    def energies(compiled, cells, displacement):
        fx.set_owned_values(sample, displacement)
        values = fx.evaluate_expression(compiled, cells).reshape(cells.size, reference_weights.size, len(column))
        return np.einsum("cqt,q->t", values, reference_weights)

    pair_list = [(i, k) for i in range(m) for k in range(i + 1, m)]
    shifts = ([vectors[:, i] for i in range(m)] + [-vectors[:, i] for i in range(m)]
              + [vectors[:, i] + vectors[:, k] for i, k in pair_list])
    constants, linears = [], []
    for region, muscle in zip(muscle_cells(scene, model.fish.tags), scene.actuated_muscles):
        cells, compiled = fx.owned_cells_among(model.mesh, region), expression(tuple(muscle.fibre))
        sampled = np.stack([energies(compiled, cells, np.zeros(model.n_owned_dofs))]
                           + [energies(compiled, cells, u) for u in shifts])
        sampled = model.comm.allreduce(sampled, op=MPI.SUM)
        rest, plus, minus, both = sampled[0], sampled[1: 1 + m], sampled[1 + m: 1 + 2 * m], sampled[1 + 2 * m:]
        gradient = (plus - minus) / 2.0
        hessian = np.empty((m, m, len(column)))
        for i in range(m):
            hessian[i, i] = plus[i] + minus[i] - 2.0 * rest
        for (i, k), value in zip(pair_list, both):
            hessian[i, k] = hessian[k, i] = value - rest - gradient[i] - gradient[k] - 0.5 * (hessian[i, i] + hessian[k, k])
        b, b_matrix = taylor_of(lambda index: (gradient[..., column[index]], hessian[..., column[index]]), p, order)
        constants.append(b)
        linears.append(b_matrix)
    return MuscleTensors(stack_taylor(constants), stack_taylor(linears))
