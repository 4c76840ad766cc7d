"""Any number of muscles ([[muscles]] tables): each a region with its fibre and activation
a_j = A s_j r(t) sin(2π f_j t + φ_j); the default pair is today's antagonist pair; the block's muscle
pairs; bad tables are one line and exit code 2."""
import textwrap
import tomllib

import numpy as np
import pytest

from aquarom_fenics.api import simulate
from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.block import block_mesh, block_region_names
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.geometry.mesh import signed_cell_volumes
from aquarom_fenics.geometry.tags import tag_fish
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.io.scene_sections import MuscleSpec
from aquarom_fenics.physics.muscle import ActivationLaw
from conftest import coarse_scene, one_line

NOMINAL_DISTANCE = 0.04613398137692568
"""nominal.toml (level 1, degree 2, 2 s) before the [[muscles]] tables existed [m]."""

PAIR = [{"region": "left_muscle"}, {"region": "right_muscle", "phase": 180}]
"""The antagonist pair written as [[muscles]] tables, the right muscle half a period behind."""


# ---------------------------------------------------------------------------------------------
# Scene tables


def test_a_muscle_table_takes_its_defaults_and_normalises_its_fibre():
    scene = scene_from_dict({"muscles": [{"region": "a"}, {"region": "b", "fibre": [0, 3, 4], "scale": -2,
                                                           "phase": 90, "frequency": 2.5}]}, source="t.toml")
    first, second = scene.muscles
    assert first == MuscleSpec("a", (1.0, 0.0, 0.0), 1.0, 0.0, None)
    assert second == MuscleSpec("b", (0.0, 0.6, 0.8), -2.0, 90.0, 2.5)
    law = ActivationLaw.of(scene.replace("actuation", frequency=1.5))
    assert law.frequencies == (1.5, 2.5) and law.scales == (1.0, -2.0)
    assert law.phases == pytest.approx((0.0, np.pi / 2), abs=1e-15)          # degrees in the file


def test_without_muscle_tables_the_pair_of_the_regions_is_driven_and_the_hash_is_kept():
    """The scenes without [[muscles]] keep their hash: the key is left out of what is hashed."""
    scene = Scene.load("nominal")
    assert scene.muscles == () and "muscles" not in scene.to_dict()
    assert [(m.region, m.scale, m.phase) for m in scene.actuated_muscles] == [("left_muscle", 1.0, 0.0),
                                                                              ("right_muscle", -1.0, 0.0)]
    np.testing.assert_array_equal(ActivationLaw.of(scene).unit(0.3), ActivationLaw.antagonist(1.0).unit(0.3))
    explicit = scene_from_dict(tomllib.loads(scene.to_toml()) | {"muscles": PAIR}, source=scene.source)
    assert explicit.hash != scene.hash and explicit.fom_hash != scene.fom_hash


def test_a_scene_with_muscle_tables_is_written_and_read_back_with_its_hash():
    wave = Scene.load("wave")
    again = scene_from_dict(tomllib.loads(wave.to_toml()), source=wave.source, base_dir=wave.base_dir)
    assert again == wave and again.hash == wave.hash
    assert [m.region for m in wave.muscles] == ["left_1", "right_1", "left_2", "right_2", "left_3", "right_3"]


@pytest.mark.parametrize("muscles, message", [
    ([{"region": "a", "fibre": [0, 0, 0]}], r"\[\[muscles\]\] 1: fibre = \[0, 0, 0\] has no direction"),
    ([{"region": "a", "fibre": [1, 0]}], r"fibre must be a direction \[m_x, m_y, m_z\] of 3 numbers"),
    ([{"region": "a", "scale": "big"}], r"\[\[muscles\]\] 1: scale must be a finite number, got 'big'"),
    ([{"region": "a", "phase": True}], r"phase must be a finite number"),
    ([{"region": "a", "frequency": 0.0}], r"frequency = 0.0 must be > 0"),
    ([{"region": "a"}, {"fibre": [1, 0, 0]}], r"\[\[muscles\]\] 2: region must be the name of a region"),
    ([{"region": "a", "speed": 1}], r"unknown key 'speed'; valid keys: region, fibre, scale, phase, frequency"),
    ([{"region": "a"}, {"region": "a"}], r"\[\[muscles\]\] 1 and 2 both name region 'a'"),
    ([], r"muscles must be an array of tables"),
    (["a"], r"\[\[muscles\]\] 1 must be a table"),
])
def test_bad_muscle_tables_are_one_line(muscles, message):
    with pytest.raises(InputError, match=message):
        scene_from_dict({"muscles": muscles}, source="bad.toml")


def test_muscle_tables_and_a_changed_regions_pair_are_refused_together():
    with pytest.raises(InputError, match=r"\[regions\] muscles .* and \[\[muscles\]\] both name the muscles"):
        scene_from_dict({"regions": {"muscles": ["port", "starboard"]}, "muscles": [{"region": "port"}]},
                        source="bad.toml")


BAD_SCENES = {
    "unknown region": ('[[muscles]]\nregion = "left_9"\n', ["'left_9'", "left_3"]),
    "overlapping muscles": ('[[muscles]]\nregion = "left_muscle"\n[[muscles]]\nregion = "left_2"\n',
                            ["left_muscle and left_2 overlap"]),
    "zero fibre": ('[[muscles]]\nregion = "left_1"\nfibre = [0.0, 0.0, 0.0]\n', ["no direction"]),
    "bad type": ('[[muscles]]\nregion = 3\n', ["region must be the name of a region"]),
}


@pytest.mark.parametrize("kind", sorted(BAD_SCENES))
@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
def test_a_bad_muscle_table_is_one_line_and_exit_code_2(kind, command, tmp_path, capsys):
    table, words = BAD_SCENES[kind]
    scene = tmp_path / "scene.toml"
    scene.write_text("[mesh]\nlevel = 1\n[regions]\nmuscle_pairs = 3\n" + table)
    assert main([command[0], str(scene), *command[1:]]) == 2
    line = one_line(capsys)
    for word in words:
        assert word in line, (word, line)


# ---------------------------------------------------------------------------------------------
# The block's muscle pairs


@pytest.fixture(scope="module")
def paired_block():
    return block_mesh(1, pairs=3)


def test_the_block_muscle_pairs_are_equal_conforming_segments_of_the_muscles(paired_block):
    """left_k, right_k split left_muscle, right_muscle into 3 slabs of equal volume along x, tail to head."""
    regions, points, cells = paired_block.regions, paired_block.points, paired_block.cells
    assert set(regions) == set(block_region_names(3))
    volumes = np.abs(signed_cell_volumes(points, cells))
    ends = -0.20 * np.array([0.95, 0.75, 0.55, 0.35])
    for side in ("left", "right"):
        segments = [regions[f"{side}_{k}"] for k in (1, 2, 3)]
        np.testing.assert_array_equal(np.sort(np.concatenate(segments)), regions[f"{side}_muscle"])
        for k, segment in enumerate(segments):
            x = points[cells[segment], 0]
            assert x.min() >= ends[k] - 1e-12 and x.max() <= ends[k + 1] + 1e-12      # conforming: no cell crosses
            assert volumes[segment].sum() == pytest.approx(0.2 * 0.20 * 0.04 / 2 * 0.1, rel=1e-12)       # 0.2 L × W/2 × H
    assert set(block_mesh(1).regions) == {"head", "left_muscle", "right_muscle"}   # one pair: the block as before


def test_muscle_tables_name_the_regions_of_a_mesh(paired_block):
    """Any number of named regions are muscles, in their order; the sides for pictures by their y."""
    names = ("left_1", "right_1", "left_3")
    tags = tag_fish(paired_block, muscles=names, muscle_key="[[muscles]] {} region")
    for name, cells in zip(names, tags.muscle_cells):
        np.testing.assert_array_equal(cells, paired_block.regions[name])
    np.testing.assert_array_equal(tags.left_muscle_cells,
                                  np.union1d(paired_block.regions["left_1"], paired_block.regions["left_3"]))
    np.testing.assert_array_equal(tags.right_muscle_cells, paired_block.regions["right_1"])
    with pytest.raises(InputError, match=r"no region 'left_7' \(\[\[muscles\]\] 2 region\)"):
        tag_fish(paired_block, muscles=("left_1", "left_7"), muscle_key="[[muscles]] {} region")


# ---------------------------------------------------------------------------------------------
# Forces and runs


def muscle_force(scene, activations):
    """f_act at rest of a level-1 FOM at the given activations."""
    model = FullOrderModel(scene, load_fish(scene))
    model.set_displacement(np.zeros(model.n_owned_dofs))
    model.muscle.set_activations(activations)
    force = model.muscle.force()
    model.destroy()
    return force


def test_the_segments_forces_add_up_to_the_whole_muscle_and_the_fibre_turns_them():
    """Σ_k f_act(left_k) = f_act(left_muscle) (energy additive over disjoint cells); the energy is even
    in m (m and -m give the same force), and a vertical fibre another one."""
    pairs = coarse_scene(regions={"muscle_pairs": 3})
    segments = scene_from_dict({"mesh": {"level": 1}, "regions": {"muscle_pairs": 3},
                                "muscles": [{"region": f"left_{k}", "fibre": [-1, 0, 0]} for k in (1, 2, 3)]},
                               source="<test>")
    whole = muscle_force(pairs, (1.0, 0.0))
    assert np.abs(whole).max() > 0
    np.testing.assert_allclose(muscle_force(segments, (1.0, 1.0, 1.0)), whole, rtol=0, atol=1e-12 * np.abs(whole).max())
    vertical = scene_from_dict({"mesh": {"level": 1}, "muscles": [{"region": "left_muscle", "fibre": [0, 0, 1]}]},
                               source="<test>")
    assert np.abs(muscle_force(vertical, (1.0,)) - muscle_force(coarse_scene(), (1.0, 0.0))).max() > 0.1 * np.abs(whole).max()


def test_the_pair_as_muscle_tables_swims_the_nominal_distance():
    """nominal.toml swims what it swam before the tables, and the same pair written as [[muscles]]
    (the right muscle by phase = 180°, not by its scale) the same to 1e-12."""
    scene = Scene.load("nominal")
    assert simulate(scene).distance == pytest.approx(NOMINAL_DISTANCE, rel=0, abs=1e-12)
    explicit = scene_from_dict(tomllib.loads(scene.to_toml()) | {"muscles": PAIR}, source=scene.source)
    assert simulate(explicit).distance == pytest.approx(NOMINAL_DISTANCE, rel=0, abs=1e-12)


def test_the_travelling_wave_scene_runs_with_its_full_and_reduced_model(tmp_path):
    """scenes/wave.toml (3 pairs, 120° per pair), 0.3 s with SPEC's abrupt start (start_ramp = 0, as
    measured): the FOM moves it forward; the ROM, whose basis has the actuation responses of the wave's
    two activation patterns, within 3 % of it."""
    wave = Scene.load("wave").replace("solver", duration=0.3).replace("actuation", start_ramp=0.0)
    fish = load_fish(wave)
    assert len(fish.tags.muscle_cells) == 6
    full = simulate(wave, fish=fish)
    reduced = simulate(wave, model="rom", fish=fish)
    assert full.completed and reduced.completed
    assert full.distance > 1e-3 and full.tail_amplitude > 1e-2       # measured: 2.37 mm forward, 1.60 cm
    assert reduced.distance == pytest.approx(full.distance, rel=0.03)              # measured: -1.0 %
    assert reduced.tail_amplitude == pytest.approx(full.tail_amplitude, rel=0.03)  # measured: +0.6 %


def test_the_fish_wave_scene_drives_its_three_pairs_from_the_head_to_the_tail():
    """left_k/right_k numbered from the tail (as the block's): the head-side pair leads by 120° per pair."""
    wave = Scene.load("fish_wave")
    assert [(m.region, m.scale, m.phase) for m in wave.muscles] == [
        ("left_1", 1.0, 0.0), ("right_1", -1.0, 0.0), ("left_2", 1.0, 120.0), ("right_2", -1.0, 120.0),
        ("left_3", 1.0, 240.0), ("right_3", -1.0, 240.0)]
    assert len(ActivationLaw.of(wave).patterns()) == 2                  # the sin and cos parts of one frequency


def test_the_fish_wave_scene_runs_with_its_full_and_reduced_model():
    """scenes/fish_wave.toml over its first 0.4 s (its automatic smooth start lasts 0.25 s): both models
    complete and the fish starts to swim. Its ROM is not within 3 % of the FOM over 2 s (-13 % in
    distance; the scene's comment and docs/your_own_swimmer.md), so no accuracy is asserted here."""
    wave = Scene.load("fish_wave").replace("solver", duration=0.4)
    fish = load_fish(wave)
    full, reduced = simulate(wave, fish=fish), simulate(wave, model="rom", fish=fish)
    assert len(fish.tags.muscle_cells) == 6
    assert full.completed and reduced.completed
    assert full.distance > 5e-4 and full.tail_amplitude > 1e-2       # measured: 1.01 mm forward, 1.42 cm


def test_the_wave_basis_has_the_responses_of_each_activation_pattern():
    """Two patterns (the sin and cos parts): ψ, θ_ψ and ψ_m of each, θ_ψ12 and K_0⁻¹Mψ_k; the plan's
    estimate names the same candidates; the pair keeps its basis of one pattern."""
    from aquarom_fenics.reduction.basis import build_basis
    from aquarom_fenics.studies.estimate import expected_basis

    wave = Scene.load("wave").replace("mesh", degree=1).replace("reduction", vibration_modes=1)   # one mode, as the pair
    model = FullOrderModel(wave, load_fish(wave))
    basis = build_basis(model, 0)
    model.destroy()
    wave_vectors = ["psi", "theta_psi", "psi_2", "theta_psi_2", "theta_psi_1_2", "psi_mass_1", "psi_mass_2",
                    "psi_muscle", "psi_muscle_2"]
    assert basis.labels[3:] == wave_vectors
    expected = expected_basis(wave, parametric=False)       # the nodal thrust's τ counted: an upper bound
    assert set(expected) - {"tail_force"} == set(basis.labels + basis.dropped)
    assert expected[3:-1] == wave_vectors
    assert expected_basis(coarse_scene(), parametric=False)[3:-1] == ["psi", "theta_psi", "psi_muscle"]


def test_muscle_pairs_with_a_mesh_file_is_one_line_and_exit_code_2(tmp_path, capsys):
    """The block's segments are the block's: a mesh file names its own regions."""
    (tmp_path / "body.msh").write_text("not read")
    scene = tmp_path / "scene.toml"
    scene.write_text('[mesh]\nfile = "body.msh"\n[regions]\nmuscle_pairs = 2\n')
    assert main(["mesh", str(scene)]) == 2
    assert "muscle_pairs = 2 splits the built-in block's muscles" in one_line(capsys)


def test_muscle_tables_on_a_mesh_without_regions_are_refused(paired_block):
    """The centroid rule chooses the pair of [regions] muscles only: a table's region must exist."""
    from aquarom_fenics.geometry.mesh import FishMesh

    untagged = FishMesh(points=paired_block.points, cells=paired_block.cells, source="untagged")
    with pytest.raises(InputError, match=r"no region 'head' \(\[regions\] head\); its regions are none"):
        tag_fish(untagged, muscles=("a", "b"), muscle_key="[[muscles]] {} region", fallback=False)
    assert len(tag_fish(untagged).muscle_cells) == 2          # the pair: by centroid, as before
