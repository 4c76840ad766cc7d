"""Muscle and actuation inputs refused (or warned about) with their real cause, by the scene's own
validation (the Python API and the command line alike): a muscle period under 10 time steps, a muscle
on the head region, a fibre whose squares overflow, a peak muscle stress beyond the body's fibre
stiffness, more actuation modes than a reduced basis holds."""
import math

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.diagnostics import muscle_stiffness_hint
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.geometry.tags import tagged_regions
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.physics.muscle import ActivationLaw
from aquarom_fenics.studies.plan import MAX_TENSOR_BYTES, check_plan_bounds
from aquarom_fenics.studies.estimate import reduced_tensor_bytes
from conftest import one_line

PAIR = [{"region": "left_muscle"}, {"region": "right_muscle", "scale": -1.0}]


def pair(**first):
    return [{**PAIR[0], **first}, PAIR[1]]


def coarse_scene(**tables):
    """A level-1 scene of TOML tables (``muscles``: the list of [[muscles]] tables)."""
    return scene_from_dict({"mesh": {"level": 1}, **tables}, source="<test>")


# ---------------------------------------------------------------------------------------------
# The activation period against the time step


def test_a_muscle_period_under_ten_time_steps_is_refused_naming_the_muscle_and_the_valid_frequency():
    with pytest.raises(InputError) as error:
        coarse_scene(muscles=pair(frequency=1e9))
    message = str(error.value)
    for words in ("[[muscles]] 1 (region 'left_muscle') frequency = 1e+09 Hz", "10 time steps",
                  "[solver] time_step = 0.02 s", "frequency <= 5 Hz", "time_step <= 1e-10 s"):
        assert words in message, (words, message)
    assert coarse_scene(muscles=pair(frequency=5.0)).muscles[0].frequency == 5.0     # exactly 10 steps


def test_the_actuation_frequency_of_the_pair_and_of_muscles_without_their_own_is_checked_too():
    with pytest.raises(InputError, match=r"\[actuation\] frequency = 6 Hz .* frequency <= 5 Hz"):
        coarse_scene(actuation={"frequency": 6.0})
    with pytest.raises(InputError, match=r"\[actuation\] frequency \(of \[\[muscles\]\] 2, region 'right_muscle'\)"):
        coarse_scene(actuation={"frequency": 6.0}, muscles=pair(frequency=1.0))
    scene = coarse_scene()
    with pytest.raises(InputError, match=r"time_step = 0.2 s"):
        scene.replace("solver", time_step=0.2)          # the Python API validates across sections too
    assert coarse_scene(actuation={"frequency": 6.0, "amplitude": 0.0}).actuation.frequency == 6.0   # no drive


def test_a_too_fast_muscle_is_one_line_and_exit_code_2(tmp_path, capsys):
    scene = tmp_path / "fast.toml"
    scene.write_text('[mesh]\nlevel = 1\n[[muscles]]\nregion = "left_muscle"\nfrequency = 1e9\n'
                     '[[muscles]]\nregion = "right_muscle"\nscale = -1.0\n')
    assert main(["simulate", str(scene), "--dry-run"]) == 2
    assert "[[muscles]] 1 (region 'left_muscle') frequency = 1e+09 Hz" in one_line(capsys)


# ---------------------------------------------------------------------------------------------
# Regions


def test_a_muscle_on_the_head_region_is_refused_naming_the_muscle_and_the_head():
    with pytest.raises(InputError, match=r"\[\[muscles\]\] 2 names region 'head', the stiff head \(\[regions\] head\)"):
        coarse_scene(muscles=[{"region": "left_muscle"}, {"region": "head"}])
    with pytest.raises(InputError, match=r"\[regions\] muscles = \['head', 'right_muscle'\] names the stiff head"):
        coarse_scene(regions={"muscles": ["head", "right_muscle"]})


def test_a_region_named_twice_on_a_mesh_names_both_keys_not_an_overlap():
    mesh = block_mesh(1)
    with pytest.raises(InputError, match=r"\[regions\] head and \[\[muscles\]\] 1 both name region 'head'"):
        tagged_regions(mesh, ("head", "head", "right_muscle"), "[[muscles]] {}")


# ---------------------------------------------------------------------------------------------
# Numbers whose squares or products overflow


@pytest.mark.parametrize("fibre, unit", [([1e200, 1e200, 0], [math.sqrt(0.5), math.sqrt(0.5), 0.0]),
                                         ([1e-200, 0, -1e-200], [math.sqrt(0.5), 0.0, -math.sqrt(0.5)]),
                                         ([1.7e308, 0, 0], [1.0, 0.0, 0.0])])
def test_a_fibre_whose_squares_overflow_or_underflow_keeps_its_direction(fibre, unit):
    (muscle, _) = coarse_scene(muscles=pair(fibre=fibre)).muscles
    np.testing.assert_allclose(muscle.fibre, unit, rtol=1e-15, atol=0.0)


def test_a_huge_phase_is_reduced_exactly_to_its_angle():
    scene = coarse_scene(muscles=pair(phase=1e300))
    phase = ActivationLaw.of(scene).phases[0]
    assert phase == math.radians(math.fmod(1e300, 360.0)) and abs(phase) < 2 * math.pi


# ---------------------------------------------------------------------------------------------
# The peak muscle stress against the body's fibre stiffness


def test_a_huge_amplitude_is_refused_naming_the_amplitude_and_its_valid_range():
    with pytest.raises(InputError) as error:
        coarse_scene(actuation={"amplitude": 1e9})
    message = str(error.value)
    young, nu = 260e3, 0.4
    ceiling = young * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) / 6e4          # M = λ + 2μ over k
    assert message.startswith("scene <test>: [actuation] amplitude = 1e+09") and "stiffness = " not in message
    assert f"give amplitude in [0, {ceiling:.3g})" in message
    assert coarse_scene(actuation={"amplitude": 0.99 * ceiling}).actuation.amplitude == 0.99 * ceiling
    with pytest.raises(InputError, match=r"\[actuation\] amplitude"):
        coarse_scene(actuation={"amplitude": ceiling})


@pytest.mark.parametrize("tables, words", [
    ({"actuation": {"stiffness": 1e9}}, "[actuation] stiffness = 1e+09 Pa with amplitude A = 0.2"),
    ({"material": {"young_modulus": 500.0}}, "[material] young_modulus = 500 Pa"),
    ({"muscles": pair(scale=1e300)}, "[[muscles]] 1 (region 'left_muscle') scale = 1e+300"),
    ({"muscles": pair(scale=1e300), "actuation": {"amplitude": 1e300, "stiffness": 1e300}}, "amplitude = 1e+300"),
    ({"reduction": {"stroke_amplitude": 10.0}}, "[reduction] stroke_amplitude = 10"),
    ({"cooptimization": {"enabled": True, "amplitude_bounds": [0.1, 1e9]}}, "[cooptimization] amplitude_bounds"),
])
def test_a_muscle_stress_beyond_the_fibre_stiffness_names_the_key_at_fault(tables, words):
    with pytest.raises(InputError) as error:
        coarse_scene(**tables)
    assert words in str(error.value) and "no stiffness left" in str(error.value), str(error.value)


def test_the_newton_hint_for_strong_muscles_blames_an_amplitude_above_full_activation():
    hint = muscle_stiffness_hint(coarse_scene(actuation={"amplitude": 2.0, "stiffness": 3e4}))
    assert "[actuation] amplitude <= " in hint and "stiffness <=" not in hint
    assert "stiffness <= " in muscle_stiffness_hint(coarse_scene(actuation={"stiffness": 1e6}))


# ---------------------------------------------------------------------------------------------
# Many muscles and the reduced basis


def test_many_muscle_frequencies_are_blamed_for_the_basis_size_not_the_vibration_modes():
    muscles = [{"region": f"m{j}", "frequency": 1.0 + 0.1 * j} for j in range(20)]
    scene = coarse_scene(muscles=muscles)
    with pytest.raises(InputError) as error:
        check_plan_bounds("simulate", scene, "rom")
    message = str(error.value)
    assert "its 20 muscles make 20 actuation modes" in message and "vibration_modes" not in message
    fit = int(message.split("at most ")[1].split()[0])
    assert reduced_tensor_bytes(scene, False, fit) <= MAX_TENSOR_BYTES < reduced_tensor_bytes(scene, False, fit + 1)
