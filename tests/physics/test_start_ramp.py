"""A gait starts smoothly by construction: a muscle whose activation would jump at t = 0
(a_j(0) = A s_j sin φ_j ≠ 0) makes ``[actuation] start_ramp = "auto"`` give the whole gait the smooth
start r(t) = sin²(π t / 2τ), τ a quarter of the slowest period; phases 0° and 180° keep SPEC §5's law
(r = 1) bit for bit, their hashes too; an explicit start_ramp wins, with a warning line for 0 on a
jumping gait."""
import logging
import tomllib

import numpy as np
import pytest

from aquarom_fenics.api import simulate
from aquarom_fenics.cli import main
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.paths import shipped_scenes
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.io.scene_muscles import abrupt_muscles, start_ramp_time
from aquarom_fenics.physics.muscle import ActivationLaw
from conftest import coarse_scene, one_line

WAVE = [{"region": f"{side}_{k}", "scale": 1.0 if side == "left" else -1.0, "phase": 120.0 * (k - 1)}
        for k in (1, 2, 3) for side in ("left", "right")]
"""The block's three pairs as a travelling wave, 120° per pair (as scenes/wave.toml)."""

PAIR_BY_PHASE = [{"region": "left_muscle"}, {"region": "right_muscle", "phase": 180}]
"""The antagonist pair as [[muscles]] tables, the right muscle half a period behind."""


def wave_scene(**actuation):
    """The level-1 block driven by :data:`WAVE`, with these [actuation] keys."""
    return scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "actuation": actuation,
                            "muscles": WAVE}, source="<test>")


def antagonist_scenes():
    """The shipped scenes whose muscles all start at a_j(0) = 0."""
    scenes = [Scene.load(path) for path in sorted(shipped_scenes().glob("*.toml"))]
    return [scene for scene in scenes if not abrupt_muscles(scene)]


def test_a_phase_shifted_muscle_starts_from_zero_and_smoothly():
    """a_j(0) = 0 for every muscle, a_j = O(t²) at the start, SPEC's sine once t ≥ τ = 0.25 s (1 Hz)."""
    law = ActivationLaw.of(wave_scene())
    assert law.ramp_time == 0.25
    np.testing.assert_array_equal(law.unit(0.0), np.zeros(6))
    spec = ActivationLaw(law.scales, law.phases, law.frequencies, 0.0)
    assert np.abs(spec.unit(0.0)).max() == pytest.approx(np.sin(np.radians(120.0)))    # the jump it replaces
    for t in (1e-3, 1e-2):
        assert np.abs(law.unit(t)).max() <= (np.pi / (2 * 0.25)) ** 2 * t ** 2      # r(t) ≤ (π t / 2τ)²
    for t in (0.25, 0.4, 1.3):
        np.testing.assert_array_equal(law.unit(t), spec.unit(t))
    ramped = np.array([law.unit(t) for t in np.linspace(0.0, 0.25, 201)])
    # |ȧ| ≤ |ṙ| + 2π f ≤ 2 · 2π f: the envelope rises no faster than the sine it multiplies (measured 7.3 /s)
    assert np.abs(np.diff(ramped, axis=0)).max() / (0.25 / 200) <= 2 * (2 * np.pi * 1.0)


def test_the_default_ramp_is_a_quarter_of_the_slowest_period_for_the_whole_gait():
    assert start_ramp_time(wave_scene(frequency=2.0)) == 0.125
    slow = [dict(table, frequency=0.5) if table["region"] == "left_1" else table for table in WAVE]
    scene = scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3}, "muscles": slow}, source="<t>")
    law = ActivationLaw.of(scene)
    assert law.ramp_time == 0.5
    assert law.unit(0.1)[0] == pytest.approx(np.sin(np.pi * 0.1 / 1.0) ** 2 * np.sin(2 * np.pi * 0.5 * 0.1))
    for name in ("fish_wave", "wave"):          # the shipped waves
        assert ActivationLaw.of(Scene.load(name)).ramp_time == 0.25


def test_phases_of_0_and_180_degrees_keep_the_spec_law_and_the_hash():
    """Every shipped antagonist scene: τ = 0 and the hash of start_ramp = 0 (the value before "auto", so its FOM
    and PROM caches stay valid); the pair written with phase 180° too."""
    scenes = antagonist_scenes()
    assert {"fish", "nominal", "so1", "co", "fish_optimize"} <= {scene.name for scene in scenes}
    for scene in scenes:
        assert ActivationLaw.of(scene).ramp_time == 0.0, scene.name
        assert scene.hash == scene.replace("actuation", start_ramp=0.0).hash, scene.name
    pair = scene_from_dict({"mesh": {"level": 1}, "muscles": PAIR_BY_PHASE}, source="<t>")
    law, spec = ActivationLaw.of(pair), ActivationLaw.antagonist(1.0)
    assert law.ramp_time == 0.0
    for t in np.linspace(0.0, 1.0, 51):
        assert law.unit(t)[0] == spec.unit(t)[0] and law.unit(t)[1] == pytest.approx(spec.unit(t)[1], abs=1e-15)


def test_the_fish_swims_bit_for_bit_as_with_the_spec_law():
    fish = Scene.load("fish").replace("solver", duration=0.1)
    body = load_fish(fish)
    auto, spec = simulate(fish, fish=body), simulate(fish.replace("actuation", start_ramp=0.0), fish=body)
    assert auto.distance == spec.distance and auto.tail_amplitude == spec.tail_amplitude


def test_the_fish_wave_starts_without_cut_steps():
    """Its first 0.1 s: no cut step with the automatic start."""
    wave = Scene.load("fish_wave").replace("solver", duration=0.1)
    body = load_fish(wave)
    smooth = simulate(wave, fish=body)
    assert smooth.completed and smooth.cut_steps == 0


def test_an_explicit_start_ramp_wins_and_zero_on_a_jumping_gait_warns(caplog):
    with caplog.at_level(logging.WARNING, logger="aquarom"):
        assert ActivationLaw.of(wave_scene(start_ramp=0.1)).ramp_time == 0.1
        assert ActivationLaw.of(coarse_scene(actuation={"start_ramp": 0.3})).ramp_time == 0.3
        assert not caplog.records
        spec = wave_scene(start_ramp=0)
    assert ActivationLaw.of(spec).ramp_time == 0.0
    [record] = caplog.records
    message = record.getMessage()
    assert message.startswith("warning:") and "\n" not in message
    assert "region 'left_2'" in message and f"a_j(0) = {0.2 * np.sin(np.radians(120.0)):.3g}" in message
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="aquarom"):
        coarse_scene(actuation={"start_ramp": 0.0})
        scene_from_dict({"mesh": {"level": 1}, "muscles": PAIR_BY_PHASE, "actuation": {"start_ramp": 0}}, source="<t>")
        scene_from_dict({"mesh": {"level": 1}, "muscles": WAVE, "regions": {"muscle_pairs": 3},
                         "actuation": {"start_ramp": 0, "amplitude": 0}}, source="<t>")   # nothing driven
    assert not caplog.records


def test_the_warning_is_one_line_on_the_command_line(capsys):
    assert main(["simulate", "fish_wave", "--set", "actuation.start_ramp=0", "--dry-run"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "start_ramp = 0" in warnings[0] and "left_2" in warnings[0]


@pytest.mark.parametrize("value", ['"fast"', "-0.1", "true", "inf"])
def test_a_bad_start_ramp_is_one_line_and_exit_code_2(value, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(f"[actuation]\nstart_ramp = {value}\n")
    assert main(["simulate", str(path), "--dry-run"]) == 2
    assert "start_ramp" in one_line(capsys)


def test_auto_is_written_and_read_back():
    wave = Scene.load("fish_wave")
    assert wave.actuation.start_ramp == "auto" and 'start_ramp = "auto"' in wave.to_toml()
    again = scene_from_dict(tomllib.loads(wave.to_toml()), source=wave.source, base_dir=wave.base_dir)
    assert again.actuation == wave.actuation and again.muscles == wave.muscles
    assert again.hash == wave.hash == wave.replace("actuation", start_ramp=0.25).hash
