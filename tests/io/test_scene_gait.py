"""The [gait] table: its variables mapped onto the [[muscles]] keys, their starts, the hash, and bad
input as one line with exit code 2."""
import math
import textwrap
import tomllib

import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.io.scene_gait import apply_gait, gait_pairs
from aquarom_fenics.io.scene_muscles import start_ramp_time

from tests.io.test_scene import assert_one_line_error, run_cli, write_scene

WAVE = textwrap.dedent("""\
    [mesh]
    level = 1
    [regions]
    muscle_pairs = 3
    """) + "".join(textwrap.dedent(f"""\
    [[muscles]]
    region = "left_{k}"
    phase = {120.0 * (k - 1)}
    [[muscles]]
    region = "right_{k}"
    scale = -1.0
    phase = {120.0 * (k - 1)}
    """) for k in (1, 2, 3))


def scene_of(text: str) -> Scene:
    return scene_from_dict(tomllib.loads(text), source="gait.toml")


def test_starts_are_the_scenes_values_unless_given():
    scene = scene_of(WAVE + "[actuation]\nfrequency = 1.5\n[gait]\nfrequency = { bounds = [0.5, 2.0] }\n"
                     "phase_lag = { bounds = [60, 180] }\namplitude_3 = { bounds = [0.1, 0.3], start = 0.25 }\n")
    assert [(v.name, v.start) for v in scene.gait] == [("frequency", 1.5), ("phase_lag", 120.0), ("amplitude_3", 0.25)]
    assert scene.gait_names == ["frequency", "phase_lag", "amplitude_3"]


def test_variables_map_onto_the_muscles_keys():
    scene = scene_of(WAVE + "[gait]\nfrequency = { bounds = [0.5, 2.0] }\nphase_lag = { bounds = [0, 180] }\n"
                     "amplitude_2 = { bounds = [0.1, 0.3] }\n")
    driven = apply_gait(scene, {"frequency": 1.25, "phase_lag": 45.0, "amplitude_2": 0.3})
    assert driven.actuation.frequency == 1.25 and driven.actuation.amplitude == 0.2
    assert [m.phase for m in driven.muscles] == [0.0, 0.0, 45.0, 45.0, 90.0, 90.0]      # (k - 1) λ, from the tail
    assert [m.scale for m in driven.muscles] == pytest.approx([1.0, -1.0, 1.5, -1.5, 1.0, -1.0])   # A_2 / A
    assert [m.region for m in driven.muscles] == [m.region for m in scene.muscles]
    assert apply_gait(scene, {}).muscles == scene.muscles        # the starts are the scene as written
    with pytest.raises(ValueError, match="not a gait variable"):
        apply_gait(scene, {"amplitude_1": 0.2})


def test_the_regions_pair_takes_frequency_and_its_amplitude():
    scene = scene_of("[mesh]\nlevel = 1\n[gait]\nfrequency = { bounds = [0.5, 2.0] }\n"
                     "amplitude_1 = { bounds = [0.1, 0.3] }\n")
    assert len(gait_pairs(scene.actuated_muscles, scene.regions)) == 1
    driven = apply_gait(scene, {"frequency": 0.75, "amplitude_1": 0.3})
    assert driven.muscles == () and (driven.actuation.frequency, driven.actuation.amplitude) == (0.75, 0.3)


def test_a_varying_lag_ramps_at_every_lag():
    """With phase_lag a variable, "auto" gives the quarter period at 0° too (τ continuous in λ); fixed
    phases keep SPEC's law at 0°."""
    scene = scene_of(WAVE + "[gait]\nphase_lag = { bounds = [0, 180] }\nfrequency = { bounds = [0.5, 2] }\n")
    assert start_ramp_time(apply_gait(scene, {"phase_lag": 0.0})) == 0.25
    assert start_ramp_time(apply_gait(scene, {"phase_lag": 0.0, "frequency": 2.0})) == 0.125
    fixed = scene_of(WAVE.replace("120.0", "0.0").replace("240.0", "0.0")
                     + "[gait]\nfrequency = { bounds = [0.5, 2] }\n")
    assert start_ramp_time(fixed) == 0.0


def test_the_hash_includes_the_table_and_toml_round_trips():
    plain = scene_of(WAVE)
    gait = scene_of(WAVE + "[gait]\nphase_lag = { bounds = [60, 180] }\n")
    wider = scene_of(WAVE + "[gait]\nphase_lag = { bounds = [30, 180] }\n")
    assert len({plain.hash, gait.hash, wider.hash}) == 3
    assert "gait" not in plain.to_dict()                    # scenes without [gait] keep their hash
    again = scene_from_dict(tomllib.loads(gait.to_toml()), source="again.toml")
    assert again.hash == gait.hash and again.gait == gait.gait


BAD_GAITS = {
    "unknown variable": (WAVE + "[gait]\nwave_number = { bounds = [0, 1] }\n", ["wave_number", "phase_lag"]),
    "bounds reversed": (WAVE + "[gait]\nphase_lag = { bounds = [180, 60] }\n", ["phase_lag", "lower bound above upper"]),
    "unknown key": (WAVE + "[gait]\nphase_lag = { bounds = [60, 180], radius = 3 }\n", ["radius", "bounds, start"]),
    "no bounds": (WAVE + "[gait]\nphase_lag = { start = 60 }\n", ["phase_lag", "bounds"]),
    "start outside": (WAVE + "[gait]\nphase_lag = { bounds = [130, 180] }\n", ["start = 120", "scene's value"]),
    "no pairs": ('[mesh]\nlevel = 1\n[regions]\nmuscle_pairs = 2\n[[muscles]]\nregion = "left_muscle"\n'
                 "[gait]\nfrequency = { bounds = [0.5, 2] }\n", ["needs muscle pairs", "left_muscle"]),
    "lag of one pair": ("[mesh]\nlevel = 1\n[gait]\nphase_lag = { bounds = [0, 90] }\n", ["at least two muscle pairs"]),
    "pair beyond": (WAVE + "[gait]\namplitude_4 = { bounds = [0.1, 0.3] }\n", ["amplitude_4", "3 muscle pair"]),
    "with co-design": (WAVE + "[cooptimization]\nenabled = true\n[gait]\namplitude_1 = { bounds = [0.1, 0.3] }\n",
                       ["amplitude_1", "co-design"]),
    "aliased frequency": (WAVE + "[gait]\nfrequency = { bounds = [0.5, 9] }\n", ["frequency", "5 Hz"]),
    "phases not a lag": (WAVE.replace("240.0", "200.0") + "[gait]\nphase_lag = { bounds = [0, 180] }\n",
                         ["(k - 1) x lag", "give phase_lag a start"]),
    "pair not antiphase": (WAVE.replace('scale = -1.0\nphase = 120.0', 'scale = -1.0\nphase = 300.0')
                           + "[gait]\nfrequency = { bounds = [0.5, 2] }\n", ["pair 2", "one phase"]),
    "stress at a bound": (WAVE + "[gait]\namplitude_1 = { bounds = [0.1, 12.0] }\n", ["amplitude_1", "upper bound 12", "scale"]),
    "zero amplitude bound": (WAVE + "[gait]\namplitude_1 = { bounds = [0, 0.3] }\n", ["amplitude_1", "> 0"]),
}


@pytest.mark.parametrize("case", sorted(BAD_GAITS))
def test_bad_gait_is_one_line_and_exit_code_2(case, tmp_path, capfd):
    text, names = BAD_GAITS[case]
    with pytest.raises(InputError):
        scene_of(text)
    path = write_scene(tmp_path, text)
    code, out, err = run_cli(["mesh", path], capfd)
    assert_one_line_error(code, out, err, "mesh", "[gait]", *names)
