"""The shipped fish (meshes/fish.toml): its recipe's regions conform and partition the body, the shipped
.msh files are what the recipe generates, and the fish scene swims."""
import json

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish_recipe import (FISH_LEVELS, FISH_RECIPE, fish_atoms, fish_profile, fish_regions,
                                                 fish_unions, generate_fish, level_size, shipped_fish_path, write_msh)
from aquarom_fenics.geometry.mesh import FishMesh, signed_cell_volumes
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.geometry.tags import tag_fish
from aquarom_fenics.io.scene import SCENES_DIR, Scene

REGIONS = fish_regions()
ATOMS = fish_atoms(REGIONS)
UNIONS = fish_unions(REGIONS)


@pytest.fixture(scope="module")
def fish():
    return generate_fish(1)


def test_recipe_names_head_three_muscle_pairs_body_and_the_unions():
    assert REGIONS.pairs == 3
    assert ATOMS == ("head", "left_1", "left_2", "left_3", "right_1", "right_2", "right_3", "body")
    assert UNIONS == {"left_muscle": ("left_1", "left_2", "left_3"), "right_muscle": ("right_1", "right_2", "right_3")}
    assert FISH_LEVELS == (1, 2, 3, 4)


def test_profile_is_tapered_with_the_head_at_plus_x():
    profile = fish_profile()
    s = np.linspace(0.0, 1.0, 201)
    b, c = profile.semi_axes(s)
    assert np.all(c > b) and np.all(b > 0)
    thickest = s[np.argmax(b)]
    assert 0.1 < thickest < 0.5                          # thickest in the front half, behind the head face
    assert b[-1] < 0.5 * b.max() and c[-1] < c.max()      # narrow tail
    assert b.max() == pytest.approx(profile.half_width, rel=1e-6)


def test_regions_partition_the_body_and_no_cell_is_in_two_muscles(fish):
    counts = np.zeros(len(fish.cells), dtype=int)
    for name in ATOMS:
        counts[fish.regions[name]] += 1
    assert np.all(counts == 1)
    volumes = np.abs(signed_cell_volumes(fish.points, fish.cells))
    assert sum(volumes[fish.regions[name]].sum() for name in ATOMS) == pytest.approx(volumes.sum(), rel=1e-12)
    muscles = [name for name in ATOMS if name.startswith(("left_", "right_"))]
    for i, first in enumerate(muscles):
        for second in muscles[i + 1:]:
            assert len(np.intersect1d(fish.regions[first], fish.regions[second])) == 0
    for union, parts in UNIONS.items():
        assert np.array_equal(fish.regions[union], np.sort(np.concatenate([fish.regions[p] for p in parts])))
    assert all(len(fish.regions[name]) > 0 for name in ATOMS)


def test_regions_conform_to_the_interface_planes_and_the_plane_y_0(fish):
    """Every vertex of a region's cells lies inside that region's x-slab and on its side of y = 0."""
    length = fish_profile().length
    tolerance = 1e-12
    bounds = REGIONS.segment_bounds() * length
    slabs = {"head": (-REGIONS.head * length, 0.0), "body": (-length, REGIONS.muscles[0] * length)}
    for k in range(REGIONS.pairs):
        slabs[f"left_{k + 1}"] = slabs[f"right_{k + 1}"] = (bounds[k], bounds[k + 1])
    for name, (rear, front) in slabs.items():
        vertices = fish.points[fish.cells[fish.regions[name]]]
        assert vertices[..., 0].min() >= rear - tolerance and vertices[..., 0].max() <= front + tolerance, name
        if name.startswith("left_"):
            assert vertices[..., 1].min() >= 0.0
        if name.startswith("right_"):
            assert vertices[..., 1].max() <= 0.0


def test_segments_are_numbered_from_the_tail_like_the_block_s(fish):
    """left_1/right_1 is the rearmost pair and left_n/right_n the one on the head side (the block's
    convention, ``block_region_names``): the segments' mean x grows with k, on both sides."""
    assert REGIONS.segment_bounds()[0] == REGIONS.muscles[0] and REGIONS.segment_bounds()[-1] == REGIONS.muscles[1]
    for side in ("left", "right"):
        mean_x = [fish.points[fish.cells[fish.regions[f"{side}_{k}"]]][..., 0].mean() for k in range(1, REGIONS.pairs + 1)]
        assert np.all(np.diff(mean_x) > 0), (side, mean_x)
    length = fish_profile().length
    assert fish.points[fish.cells[fish.regions["left_1"]]][..., 0].min() == pytest.approx(REGIONS.muscles[0] * length)
    assert fish.points[fish.cells[fish.regions["left_3"]]][..., 0].max() == pytest.approx(-REGIONS.head * length)


def test_mesh_is_mirror_symmetric_and_tags_as_a_fish(fish):
    for axis in (1, 2):
        mirrored = fish.points.copy()
        mirrored[:, axis] *= -1
        assert np.array_equal(np.unique(mirrored, axis=0), np.unique(fish.points, axis=0))
    volumes = np.abs(signed_cell_volumes(fish.points, fish.cells))
    assert volumes[fish.regions["left_muscle"]].sum() == pytest.approx(volumes[fish.regions["right_muscle"]].sum(),
                                                                       rel=1e-12)
    tags = tag_fish(fish, head="head", muscles=("left_muscle", "right_muscle"))
    assert tags.box.length == pytest.approx(0.2, rel=1e-12) and tags.box.x_head == 0.0
    assert len(tags.spine_nodes) >= 10 and len(tags.dorsal_nodes) == len(tags.spine_nodes) - 1


POINT_TOLERANCE = 1e-9
"""How far [m per m of body length] a regenerated point may lie from the shipped one. gmsh's points
are not bit-identical across machines (its floating-point sums, and the libm under them, may round
otherwise: the last bits move, ~1e-16 L each, some 1e-13 L after the mesher's iterations); a change
of the recipe (profile, sizes, planes) moves points by a fraction of a cell, >= 1e-3 L. 1e-9 L is
also the recipe's own snapping tolerance (``_snapped``), below which two coordinates count as one."""


def assert_same_mesh(mesh, reference, what: str) -> None:
    """Same topology (cells, node numbering, physical groups with the same cells) and points within
    :data:`POINT_TOLERANCE` of the body length."""
    tolerance = POINT_TOLERANCE * fish_profile().length
    assert mesh.points.shape == reference.points.shape, what
    assert np.array_equal(mesh.cells, reference.cells), f"{what}: cells differ"
    assert set(mesh.regions) == set(reference.regions), what
    for name, cells in reference.regions.items():
        assert np.array_equal(mesh.regions[name], cells), f"{what}: group {name}"
    moved = np.abs(mesh.points - reference.points).max()
    assert moved <= tolerance, f"{what}: a point {moved:.3g} m off (tolerance {tolerance:.3g} m)"


def test_shipped_level_1_is_what_the_recipe_generates(fish):
    shipped = read_mesh(shipped_fish_path(1))
    assert set(shipped.regions) == set(ATOMS) | set(UNIONS)
    assert_same_mesh(shipped, fish, "shipped fish_l1.msh against the recipe")


COORDINATE_SECTIONS = {"$Entities": "$EndEntities", "$Nodes": "$EndNodes"}
"""The .msh sections that hold coordinates: the nodes' and the bounding boxes of the entities."""


def msh_differences(text: str, reference: str, tolerance: float) -> list[str]:
    """Lines where two .msh texts differ beyond ``tolerance`` [m]: outside the coordinate sections
    every line must be equal; inside them a line may differ only in numbers, each within ``tolerance``
    (a tag or count differs by 1 or more: refused)."""
    lines, expected = text.splitlines(), reference.splitlines()
    if len(lines) != len(expected):
        return [f"{len(lines)} lines, {len(expected)} expected"]
    differences, section_end = [], None
    for number, (line, wanted) in enumerate(zip(lines, expected), start=1):
        section_end = COORDINATE_SECTIONS.get(wanted, None if wanted == section_end else section_end)
        if line == wanted:
            continue
        values, wanted_values = line.split(), wanted.split()
        if not (section_end and len(values) == len(wanted_values)
                and np.all(np.abs(np.array(values, float) - np.array(wanted_values, float)) <= tolerance)):
            differences.append(f"line {number}: {line!r}, expected {wanted!r}")
    return differences


def test_written_msh_is_the_shipped_level_1_up_to_the_points_last_digits(fish, tmp_path):
    path = tmp_path / "fish_l1.msh"
    write_msh(fish, path, ATOMS, UNIONS)
    tolerance = POINT_TOLERANCE * fish_profile().length
    assert msh_differences(path.read_text(), shipped_fish_path(1).read_text(), tolerance) == []
    assert_same_mesh(read_mesh(path), read_mesh(shipped_fish_path(1)), "written fish_l1.msh against the shipped")


def test_the_mesh_comparison_takes_last_bits_and_refuses_a_moved_point_or_cell(fish):
    shipped = read_mesh(shipped_fish_path(1))
    other_machine = FishMesh(points=fish.points * (1 + 4e-16), cells=fish.cells, source="", regions=fish.regions)
    assert not np.array_equal(other_machine.points, shipped.points)
    assert_same_mesh(other_machine, shipped, "last bits")
    moved = fish.points.copy()
    moved[7, 0] += 3 * POINT_TOLERANCE * fish_profile().length
    with pytest.raises(AssertionError, match="a point"):
        assert_same_mesh(FishMesh(points=moved, cells=fish.cells, source="", regions=fish.regions), shipped, "moved")
    flipped = fish.cells.copy()
    flipped[0, [0, 1]] = flipped[0, [1, 0]]
    with pytest.raises(AssertionError, match="cells differ"):
        assert_same_mesh(FishMesh(points=fish.points, cells=flipped, source="", regions=fish.regions), shipped, "cell")


def test_the_msh_comparison_sees_a_moved_point_and_a_changed_group(tmp_path):
    shipped = shipped_fish_path(1).read_text()
    lines = shipped.splitlines()
    start = lines.index("$Nodes")
    coordinate = next(i for i in range(start, len(lines)) if len(lines[i].split()) == 3 and "." in lines[i])
    x, y, z = (float(value) for value in lines[coordinate].split())
    tolerance = POINT_TOLERANCE * fish_profile().length
    nudged = lines.copy()
    nudged[coordinate] = f"{x * (1 + 1e-15):.16g} {y} {z}"                     # last bits: accepted
    assert msh_differences("\n".join(nudged), shipped, tolerance) == []
    nudged[coordinate] = f"{x + 3 * tolerance:.16g} {y} {z}"                   # a real move: refused
    assert len(msh_differences("\n".join(nudged), shipped, tolerance)) == 1
    renamed = shipped.replace('"left_1"', '"left_9"')
    assert len(msh_differences(renamed, shipped, tolerance)) == 1
    regrouped = shipped.replace("\n3 2 \"left_1\"", "\n3 3 \"left_1\"")                 # outside the coordinates
    assert len(msh_differences(regrouped, shipped, tolerance)) == 1


@pytest.mark.parametrize("level", FISH_LEVELS)
def test_every_shipped_level_has_the_recipe_s_cells_and_conforming_groups(level):
    mesh = read_mesh(shipped_fish_path(level))
    assert len(mesh.cells) == FISH_RECIPE["levels"][str(level)]["cells"]
    counts = np.zeros(len(mesh.cells), dtype=int)
    for name in ATOMS:
        counts[mesh.regions[name]] += 1
    assert np.all(counts == 1)
    assert np.all(signed_cell_volumes(mesh.points, mesh.cells) > 0)


def test_cells_grow_with_the_level_and_unknown_levels_are_refused():
    cells = [FISH_RECIPE["levels"][str(level)]["cells"] for level in FISH_LEVELS]
    assert all(finer > 1.5 * coarser for coarser, finer in zip(cells, cells[1:]))
    assert cells[0] < 3000
    with pytest.raises(InputError, match="level 9 does not exist; use one of 1, 2, 3, 4"):
        level_size(9)


def test_fish_scenes_name_the_shipped_mesh_and_its_unions():
    for name in ("fish", "fish_optimize"):
        scene = Scene.load(name)
        assert scene.mesh_file == shipped_fish_path(1).resolve()
        assert scene.regions.head == "head" and tuple(scene.regions.muscles) == ("left_muscle", "right_muscle")
    assert Scene.load("fish_optimize").shape_names == ["z_tail", "z_head", "y_thin"]


def test_short_simulate_of_the_fish_scene_swims_forward(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["simulate", str(SCENES_DIR / "fish.toml"), "--set", "solver.duration=0.2", "--no-progress",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] and summary["cells"] == FISH_RECIPE["levels"]["1"]["cells"]
    columns = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert columns.shape == (11, 7)                       # t = 0, 0.02, ..., 0.2 s
    tail_y = columns[:, 2]
    assert np.all(np.isfinite(columns)) and np.isfinite(summary["distance"])
    assert tail_y.max() > 2e-3                            # the left muscles contract first: the tail swings to +y


def test_every_level_has_the_profile_s_volume(fish):
    """The cross-sections are scaled about the axis so that the mesh's volume is the lofted body's
    (without it the chords of the skin lose 3.3 % on level 1), here against ∫ π b c dx of the profile."""
    profile = fish_profile()
    s = np.linspace(0.0, 1.0, 20001)
    b, c = profile.semi_axes(s)
    exact = float(np.sum(0.5 * (np.pi * b[1:] * c[1:] + np.pi * b[:-1] * c[:-1]) * np.diff(s)) * profile.length)
    for level in FISH_LEVELS:
        mesh = read_mesh(shipped_fish_path(level))
        assert np.abs(signed_cell_volumes(mesh.points, mesh.cells)).sum() == pytest.approx(exact, rel=1e-4), level
    assert np.abs(fish.points[:, 1]).max() <= profile.half_width * 1.03      # scaled by a few per cent at most
