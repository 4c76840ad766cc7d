"""The basis's defaults that follow the gait and the body: ``[reduction] vibration_modes = "auto"``, one
mode for the antagonist pair (its hash and basis unchanged), for a wave of G muscle groups the lowest
modes that hold G lateral ones (reduction/mode_count.py); ``stroke_amplitude = "auto"``, off on the
built-in block, the largest amplitude the scene runs on a body from a mesh file."""
import dataclasses

import numpy as np
import pytest

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.io.scene_muscles import muscle_groups, planned_vibration_modes, scene_vibration_modes, stroke_amplitude
from aquarom_fenics.reduction.basis import build_basis, clamped_stiffness, vibration_modes
from aquarom_fenics.reduction.mode_count import lateral_shares, modes_for_groups
from conftest import coarse_scene

WAVE_MUSCLES = [{"region": f"{side}_{pair}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (pair - 1)}
                for pair in (1, 2, 3) for side in ("left", "right")]


def with_phases(scene: Scene, phases: dict[str, float], frequencies: dict[str, float] | None = None) -> Scene:
    """The scene with the muscles of the named regions at these phases (and frequencies)."""
    frequencies = frequencies or {}
    muscles = tuple(dataclasses.replace(m, phase=phases.get(m.region, m.phase), frequency=frequencies.get(m.region, m.frequency))
                    for m in scene.muscles)
    return dataclasses.replace(scene, muscles=muscles)


def test_muscle_groups_count_the_rhythms_up_to_a_sign():
    wave = Scene.load("fish_wave")
    assert muscle_groups(Scene.load("fish")) == 1 and muscle_groups(Scene.load("nominal")) == 1
    assert muscle_groups(wave) == 3 and muscle_groups(Scene.load("wave")) == 3
    assert muscle_groups(with_phases(wave, {"left_2": 60.0, "right_2": 60.0, "left_3": 120.0, "right_3": 120.0})) == 3
    # pairs a half period apart move in one rhythm (antiphase is a sign); -180° and 540° too
    assert muscle_groups(with_phases(wave, {"left_2": 180.0, "right_2": -180.0, "left_3": 540.0, "right_3": 0.0})) == 1
    assert muscle_groups(with_phases(wave, {m: 0.0 for m in ("left_2", "right_2", "left_3", "right_3")},
                                     {"left_3": 2.0, "right_3": 2.0})) == 2
    assert muscle_groups(wave.replace("actuation", amplitude=0.0)) == 0


def test_auto_keeps_one_mode_and_the_hash_of_the_antagonist_scenes():
    for name in ("nominal", "so1", "fish", "co"):
        scene = Scene.load(name)
        assert scene.reduction.vibration_modes == "auto"
        assert scene_vibration_modes(scene) == planned_vibration_modes(scene) == 1
        assert scene.hash == scene.replace("reduction", vibration_modes=1).hash
    wave = Scene.load("fish_wave")
    assert scene_vibration_modes(wave) is None and planned_vibration_modes(wave) == 4
    assert wave.hash != wave.replace("reduction", vibration_modes=1).hash
    assert scene_vibration_modes(wave.replace("reduction", vibration_modes=2)) == 2


def test_the_mode_count_is_the_first_that_holds_g_lateral_modes():
    shares = np.array([0.98, 0.00, 0.89, 0.96, 0.02, 0.93])     # the fish's: lateral, vertical, lateral, lateral, …
    assert [modes_for_groups(shares, g) for g in (0, 1, 2, 3, 4)] == [1, 1, 3, 4, 6]
    assert modes_for_groups(shares, 5) is None
    assert modes_for_groups(np.array([0.5, 0.9]), 2) is None     # half the energy in y is not lateral


def test_lateral_shares_split_the_kinetic_energy_by_direction():
    rng = np.random.default_rng(3)
    nodes = 5
    nodal_mass = rng.uniform(1.0, 2.0, nodes)
    mass = np.kron(np.diag(nodal_mass), np.eye(3))              # M = M_s ⊗ I, dofs interleaved x, y, z
    modes = rng.normal(size=(3 * nodes, 2))
    modes[0::3, 1] = modes[2::3, 1] = 0.0                       # the second: y only
    shares = lateral_shares(modes, mass @ modes)
    expected = (nodal_mass * modes[1::3, 0] ** 2).sum() / (np.repeat(nodal_mass, 3) * modes[:, 0] ** 2).sum()
    assert shares[0] == pytest.approx(expected) and 0.0 < shares[0] < 1.0
    assert shares[1] == pytest.approx(1.0)


def test_the_block_wave_basis_takes_the_modes_up_to_its_third_lateral_one():
    scene = scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "muscles": WAVE_MUSCLES}, source="<test>")
    fish = load_fish(scene)
    fom = FullOrderModel(scene, fish)
    stiffness = clamped_stiffness(fom)
    try:
        modes, _ = vibration_modes(fom, stiffness, 8)
    finally:
        stiffness.destroy()
    shares = lateral_shares(modes, np.column_stack([fom.matvec(fom.mass_matrix, v) for v in modes.T]))
    expected = modes_for_groups(shares, 3)
    assert expected is not None and expected >= 3
    labels = build_basis(fom, 0).labels
    assert [label for label in labels if label.startswith("mode_")] == [f"mode_{i + 1}" for i in range(expected)]
    pair = build_basis(FullOrderModel(coarse_scene(), load_fish(coarse_scene())), 0).labels
    assert [label for label in pair if label.startswith("mode_")] == ["mode_1"]


@pytest.mark.parametrize("value", ["many", 0, 51, 2.5, True])
def test_vibration_modes_takes_a_count_or_auto(value):
    from aquarom_fenics.errors import InputError

    with pytest.raises(InputError, match=r'\[reduction\] vibration_modes must be in \[1, 50\] or "auto"'):
        coarse_scene(reduction={"vibration_modes": value})
    assert coarse_scene(reduction={"vibration_modes": 50}).reduction.vibration_modes == 50


def test_auto_stroke_vectors_are_off_on_the_block_and_on_for_a_body_of_a_mesh_file():
    from aquarom_fenics.studies.estimate import expected_basis

    for name in ("nominal", "so1", "wave"):
        scene = Scene.load(name)
        assert scene.reduction.stroke_amplitude == "auto" and stroke_amplitude(scene) == 0.0
        assert scene.hash == scene.replace("reduction", stroke_amplitude=0.0).hash
        assert "stroke_plus" not in expected_basis(scene, parametric=False)
    assert stroke_amplitude(Scene.load("co")) == 0.4 and stroke_amplitude(Scene.load("fish")) == 0.2   # their own
    wave = Scene.load("fish_wave")
    assert wave.mesh_file is not None and stroke_amplitude(wave) == wave.actuation.amplitude == 0.2
    assert stroke_amplitude(wave.replace("actuation", amplitude=0.15)) == 0.15
    assert stroke_amplitude(wave.replace("cooptimization", enabled=True, amplitude_bounds=(0.05, 0.3))) == 0.3
    assert wave.hash == wave.replace("reduction", stroke_amplitude=0.2).hash != wave.replace("reduction", stroke_amplitude=0.0).hash
    assert "stroke_plus" in expected_basis(wave, parametric=False)
    assert stroke_amplitude(wave.replace("reduction", stroke_amplitude=0.0)) == 0.0


@pytest.mark.parametrize("value", ["large", -0.1, 11, False])
def test_stroke_amplitude_takes_an_amplitude_or_auto(value):
    from aquarom_fenics.errors import InputError

    with pytest.raises(InputError, match=r'\[reduction\] stroke_amplitude must be in \[0, 10\] \(0: off\) or "auto"'):
        coarse_scene(reduction={"stroke_amplitude": value})
