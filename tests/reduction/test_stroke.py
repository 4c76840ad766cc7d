"""The stroke vectors of the basis (``[reduction] stroke_amplitude``, docs/theory/basis.md "Large strokes"),
on the coarsest quadratic mesh (the labels on the linear one)."""
import pytest

from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.basis import build_basis
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.verification.compare import model_errors
from conftest import coarse_scene

STROKE_LABELS = ["stroke_plus", "stroke_minus", "tail_force", "tail_lateral", "theta_psi_tail", "psi_inertia",
                 "tail_inertia"]
CORNER = {"z_tail": -0.5, "z_head": 0.5, "y_lin_long_tail": 0.4, "y_head": 0.5, "y_ellipse": 0.5}
"""The CO box's corner where the basis without the stroke vectors is +12 % off the FOM's distance at A = 0.4."""


def labels(scene, fish):
    return build_basis(FullOrderModel(scene, fish), 0).labels


def test_stroke_vectors_are_in_the_basis_only_when_asked_for():
    """On linear tetrahedra: which vectors the basis asks for depends on the scene's settings, not on the
    degree (the five label lists are the same on the quadratic mesh, measured), and each build is 4× cheaper."""
    scene = coarse_scene()
    fish = load_fish(scene)
    assert not set(STROKE_LABELS) & set(labels(scene, fish))
    stroke = scene.replace("reduction", stroke_amplitude=0.3)
    assert labels(stroke, fish)[-len(STROKE_LABELS):] == STROKE_LABELS
    nodal = stroke.replace("fluid", stations="nodes")       # τ_x is a response vector there already: once
    assert labels(nodal, fish)[-8:] == ["psi_muscle", "tail_force"] + STROKE_LABELS[:2] + STROKE_LABELS[3:]
    without_thrust = stroke.replace("fluid", thrust=False)
    assert labels(without_thrust, fish)[-3:] == ["stroke_plus", "stroke_minus", "psi_inertia"]
    assert not set(STROKE_LABELS) & set(labels(stroke.replace("reduction", basis="paper"), fish))


def test_stroke_amplitude_enters_the_scene_hash_only_when_set(quadratic_scene):
    assert quadratic_scene.replace("reduction", stroke_amplitude=0.0).hash == quadratic_scene.hash
    assert quadratic_scene.replace("reduction", stroke_amplitude=0.4).hash != quadratic_scene.hash
    assert quadratic_scene.replace("reduction", stroke_amplitude=0.4).fom_hash == quadratic_scene.fom_hash


def stroke_vectors_alone():
    """The CO scene with the stroke vectors but not their ξ-sensitivities (CO ships both)."""
    return Scene.load("co").replace("reduction", stroke_sensitivities=False)


def test_stroke_vectors_reduce_the_rom_error_of_a_large_stroke():
    """CO corner, A = 0.4, 1 s: measured distance error +11.5 % without the stroke vectors, +2.2 % with them
    (tail y-trajectory 13.0 % and 1.9 % of its peak); the stroke vectors alone, without CO's sensitivities
    (their own test is below; they cost a FOM and two static solves per shape)."""
    scene = stroke_vectors_alone().replace("actuation", amplitude=0.4).replace("solver", duration=1.0)
    fish = load_fish(scene)
    fom = simulate_fom(scene, CORNER, fish=fish, progress=False)
    assert fom.completed

    def errors(stroke_amplitude):
        reduced_scene = scene.replace("reduction", stroke_amplitude=stroke_amplitude)
        rom = simulate_reduced(build_prom(reduced_scene, CORNER, fish=fish, parametric=False), reduced_scene)
        assert rom.completed
        return model_errors(fom, rom)

    without, stroke = errors(0.0), errors(0.4)
    assert abs(stroke["distance_relative"]) < 0.3 * abs(without["distance_relative"])
    assert abs(stroke["distance_relative"]) < 0.03
    assert stroke["tail_y_max_error_relative_to_peak"] < 0.3 * without["tail_y_max_error_relative_to_peak"]


def test_the_stroke_response_by_continuation_is_the_static_response(quadratic_scene, quadratic_fish):
    """A Newton that fails from rest (here: allowed two iterations at the full activation) is continued in
    steps of the activation."""
    from aquarom_fenics.errors import SolverError
    from aquarom_fenics.reduction.basis import stroke_response

    fom = FullOrderModel(quadratic_scene, quadratic_fish)
    direct = fom.static_response(0.4, -0.4)
    static_response = fom.static_response

    def short_from_rest(left, right, start=None):
        full_from_rest = start is None and abs(left) > 0.3
        return static_response(left, right, max_iterations=2 if full_from_rest else 30, start=start)

    fom.static_response = short_from_rest
    with pytest.raises(SolverError):
        short_from_rest(0.4, -0.4)
    continued = stroke_response(fom, 0.4)
    assert fom.norm(continued - direct) < 1e-8 * fom.norm(direct)


def test_stroke_sensitivities_are_listed_last_one_pair_per_parameter():
    from aquarom_fenics.reduction.basis import stroke_labels

    labels = stroke_labels(True, True, True, (), sensitivities=2)
    assert labels[-4:] == ("dstroke_plus_1", "dstroke_minus_1", "dstroke_plus_2", "dstroke_minus_2")
    assert stroke_labels(True, True, True, ())[-1] == "tail_inertia"
    scene = stroke_vectors_alone()
    assert scene.replace("reduction", stroke_sensitivities=False).hash == scene.replace("reduction").hash
    assert scene.replace("reduction", stroke_sensitivities=True).hash != scene.hash


def test_with_the_stroke_sensitivities_the_prom_gradient_follows_the_rebuilt_proms_near_the_corner():
    """Near the CO corner (A = 0.35) the FOM swims farther with y_ellipse; a PROM with the stroke vectors alone
    has the wrong sign of dd/dy_ellipse there. Against the difference of PROMs built at y_ellipse = 0.44 and 0.47
    (exact at their centres; 1 s: +0.021 m per unit, measured) the PROM's own sensitivity at 0.47 is -0.051
    with the stroke vectors alone and +0.017 with their sensitivities."""
    scene = stroke_vectors_alone().replace("solver", duration=1.0)
    fish = load_fish(scene)
    near = {**CORNER, "y_ellipse": 0.47}
    lower = {**near, "y_ellipse": 0.44}

    def distance(scene, design, gradient=False):
        prom = build_prom(scene, design, fish=fish)
        xi = [design[name] for name in scene.shape_names]
        result = simulate_reduced(prom, scene, xi, amplitude=0.35, sensitivities=gradient)
        assert result.completed
        return result

    at_near = distance(scene, near, gradient=True)     # its distance is the run's without sensitivities
    difference = (at_near.distance - distance(scene, lower).distance) / 0.03
    plain = at_near.distance_gradient[-1]
    sensitive = distance(scene.replace("reduction", stroke_sensitivities=True), near, gradient=True).distance_gradient[-1]
    assert abs(sensitive - difference) < 0.25 * abs(difference), (sensitive, difference, plain)
    assert abs(sensitive - difference) < 0.5 * abs(plain - difference), (sensitive, difference, plain)
