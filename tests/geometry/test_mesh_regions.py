"""Regions from mesh files (gmsh physical groups, Abaqus element sets), the head end along x, and the
bad meshes refused before any solve (SPEC §3)."""
import textwrap

import numpy as np
import pytest

from aquarom_fenics.api import simulate
from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry import gmsh_session
from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.geometry.body import in_swimming_frame
from aquarom_fenics.geometry.mesh import FishMesh, signed_cell_volumes
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.geometry.tags import tag_fish

REGIONS = ("head", "left_muscle", "right_muscle")


@pytest.fixture(scope="module")
def block():
    return block_mesh(1)


def passive_cells(mesh):
    """The cells in none of the mesh's regions (the block's passive body)."""
    tagged = np.concatenate([mesh.regions[name] for name in REGIONS])
    return np.setdiff1d(np.arange(len(mesh.cells)), tagged)


def write_msh(path, points, cells, groups, version=4.1, passive=None, surface_group=False):
    """A .msh file: one discrete volume per group {name: cell indices} (a volume physical group of
    that name) and one for ``passive`` cells (no group: saved with Mesh.SaveAll); element tags are
    the cell indices + 1. ``surface_group``: only a physical group on a skin triangle instead."""
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("written")
        node_volume = gmsh.model.addDiscreteEntity(3)
        gmsh.model.mesh.addNodes(3, node_volume, np.arange(1, len(points) + 1), np.asarray(points).ravel())
        parts = dict(groups) | ({"": passive} if passive is not None else {})
        for name, indices in parts.items():
            volume = gmsh.model.addDiscreteEntity(3)
            indices = np.asarray(indices, dtype=np.int64)
            gmsh.model.mesh.addElementsByType(volume, 4, indices + 1, (np.asarray(cells)[indices] + 1).ravel())
            if name and not surface_group:
                gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume]), name)
        if surface_group:
            surface = gmsh.model.addDiscreteEntity(2)
            gmsh.model.mesh.addElementsByType(surface, 2, [len(cells) + 1], np.asarray(cells)[0, :3] + 1)
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [surface]), "skin")
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.option.setNumber("Mesh.SaveAll", 1 if passive is not None and not surface_group else 0)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def write_inp(path, points, cells, sets):
    """An Abaqus .inp file with C3D4 elements (labels = index + 1) and one *Elset per set."""
    lines = ["*Heading", "*Node"]
    lines += [f"{number}, {x!r}, {y!r}, {z!r}" for number, (x, y, z) in enumerate(points, start=1)]
    lines.append("*Element, type=C3D4")
    lines += [f"{number}, " + ", ".join(str(node + 1) for node in cell) for number, cell in enumerate(cells, start=1)]
    for name, indices in sets.items():
        labels = [str(index + 1) for index in indices]
        lines.append(f"*Elset, elset={name}")
        lines += [", ".join(labels[start:start + 16]) for start in range(0, len(labels), 16)]
    path.write_text("\n".join(lines) + "\n")


def block_regions(mesh):
    return {name: mesh.regions[name] for name in REGIONS}


def assert_same_mesh(read, block, ordered=True):
    """Same points, the same cells (in the same order, or in any order with ``ordered`` False) and the
    same regions."""
    np.testing.assert_allclose(read.points, block.points, rtol=0, atol=1e-15)
    if ordered:
        np.testing.assert_array_equal(read.cells, block.cells)
        order = np.arange(len(block.cells))
    else:
        keys = [np.sort(mesh.cells, axis=1) @ (len(block.points) ** np.arange(4)) for mesh in (block, read)]
        assert len(np.unique(keys[0])) == len(block.cells)
        np.testing.assert_array_equal(np.sort(keys[1]), np.sort(keys[0]))
        order = np.argsort(keys[1])[np.argsort(np.argsort(keys[0]))]     # read cell of each block cell
    for name in REGIONS:
        np.testing.assert_array_equal(np.sort(order[block.regions[name]]), read.regions[name])


# ---------------------------------------------------------------------------------------------
# Reading regions


@pytest.mark.parametrize("version", [2.2, 4.1])
def test_block_written_with_its_physical_groups_reads_back_with_its_regions(tmp_path, block, version):
    path = tmp_path / f"block{version}.msh"
    write_msh(path, block.points, block.cells, block_regions(block) | {"body": passive_cells(block)}, version)
    read = read_mesh(path)
    assert_same_mesh(read, block, ordered=version > 4)        # format 2 numbers the elements group by group
    assert len(read.regions["body"]) == len(passive_cells(block))


def test_a_cell_in_two_groups_is_one_cell(tmp_path, block):
    """gmsh format 2 writes a tetrahedron once per physical group that holds it."""
    path = tmp_path / "twice.msh"
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("twice")
        volume = gmsh.model.addDiscreteEntity(3)
        gmsh.model.mesh.addNodes(3, volume, np.arange(1, len(block.points) + 1), block.points.ravel())
        gmsh.model.mesh.addElementsByType(volume, 4, np.arange(1, len(block.cells) + 1), (block.cells + 1).ravel())
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume]), "whole")
        gmsh.model.addPhysicalGroup(3, [volume], 7)
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    assert path.read_text().count("\n") > 2 * len(block.cells)       # every tetrahedron written twice
    read = read_mesh(path)
    np.testing.assert_array_equal(read.cells, block.cells)
    assert sorted(read.regions) == ["7", "whole"]                     # an unnamed group: its number
    for cells in read.regions.values():
        np.testing.assert_array_equal(cells, np.arange(len(block.cells)))


def test_block_written_with_element_sets_reads_back_with_its_regions(tmp_path, block):
    path = tmp_path / "block.inp"
    write_inp(path, block.points, block.cells, block_regions(block))
    read = read_mesh(path)
    assert_same_mesh(read, block)
    assert sorted(read.regions) == sorted(REGIONS)


def test_scene_names_its_regions(tmp_path, block):
    """[regions] head and muscles pick the file's groups by name; the muscles' order is left, right."""
    path = tmp_path / "renamed.msh"
    names = {"nose": block.regions["head"], "port": block.regions["left_muscle"],
             "starboard": block.regions["right_muscle"]}
    write_msh(path, block.points, block.cells, names, passive=passive_cells(block))
    tags = tag_fish(read_mesh(path), head="nose", muscles=("port", "starboard"))
    reference = tag_fish(block)
    np.testing.assert_array_equal(tags.head_cells, reference.head_cells)
    np.testing.assert_array_equal(tags.left_muscle_cells, reference.left_muscle_cells)
    np.testing.assert_array_equal(tags.right_muscle_cells, reference.right_muscle_cells)


# ---------------------------------------------------------------------------------------------
# The head end


def mirrored(mesh: FishMesh) -> FishMesh:
    points = mesh.points.copy()
    points[:, 0] *= -1.0
    return FishMesh(points=points, cells=mesh.cells[:, [0, 1, 3, 2]], source="mirrored", regions=mesh.regions)


def test_head_end_minus_x_mirrors_the_body_back(block):
    mirror = mirrored(block)
    assert np.all(signed_cell_volumes(mirror.points, mirror.cells) > 0.0)
    back = in_swimming_frame(mirror, "x", "-x", "head")
    np.testing.assert_array_equal(back.points, block.points)
    np.testing.assert_array_equal(back.cells, block.cells)
    assert np.all(signed_cell_volumes(back.points, back.cells) > 0.0)
    assert in_swimming_frame(block, "x", "+x", "head") is block


@pytest.mark.parametrize("mesh_of, declared, side", [(mirrored, "+x", "-x"), (lambda mesh: mesh, "-x", "+x")])
def test_a_head_region_at_the_other_end_is_refused(block, mesh_of, declared, side):
    with pytest.raises(InputError, match=rf"its region 'head' lies at the \{side} end of the body, but \[mesh\] "
                                         rf"head_end = \"\{declared}\"; set \[mesh\] head_end = \"\{side}\"$"):
        in_swimming_frame(mesh_of(block), "x", declared, "head")


# ---------------------------------------------------------------------------------------------
# The FOM on a mesh read from a file is the FOM on the block


@pytest.fixture(scope="module")
def block_distance(block):
    from conftest import coarse_scene

    scene = coarse_scene(solver={"duration": 0.5})
    result = simulate(scene)
    assert result.completed
    return scene, result.distance


def file_distance(scene, path, **mesh_keys):
    result = simulate(scene.replace("mesh", file=str(path), **mesh_keys))
    assert result.completed
    return result.distance


def test_fom_on_the_block_from_a_msh_file_equals_the_block(tmp_path, block, block_distance):
    scene, distance = block_distance
    path = tmp_path / "block.msh"
    write_msh(path, block.points, block.cells, block_regions(block), passive=passive_cells(block))
    assert abs(distance) > 1e-4              # 0.5 s: the first stroke has moved the body
    assert file_distance(scene, path) == pytest.approx(distance, rel=0, abs=1e-10)


def test_fom_on_the_block_from_an_inp_file_equals_the_block(tmp_path, block, block_distance):
    scene, distance = block_distance
    path = tmp_path / "block.inp"
    write_inp(path, block.points, block.cells, block_regions(block))
    assert file_distance(scene, path) == pytest.approx(distance, rel=0, abs=1e-10)


def test_fom_on_the_mirrored_block_with_its_head_declared_equals_the_block(tmp_path, block, block_distance):
    scene, distance = block_distance
    path = tmp_path / "mirrored.msh"
    mirror = mirrored(block)
    write_msh(path, mirror.points, mirror.cells, block_regions(block), passive=passive_cells(block))
    assert file_distance(scene, path, head_end="-x") == pytest.approx(distance, rel=0, abs=1e-10)


# ---------------------------------------------------------------------------------------------
# Bad meshes: one line and exit code 2 before any solve


def test_a_spine_with_a_gap_no_edge_spans_is_refused(block):
    """A vertex moved off the axis leaves its two neighbours on the axis with no edge between them."""
    spine = tag_fish(block).spine_nodes
    assert len(spine) > 4
    points = block.points.copy()
    points[spine[len(spine) // 2], 1] += 1e-3
    moved = FishMesh(points=points, cells=block.cells, source="moved", regions=block.regions)
    with pytest.raises(InputError, match=rf"^mesh moved: the body axis y = 0, z = 0 is not a line of mesh edges "
                                         rf"\({len(spine) - 1} vertices on it, 1 of the {len(spine) - 2} gaps"):
        tag_fish(moved, require_axis=True)
    assert not tag_fish(moved).has_spine           # the stations need no spine


def gmsh_body(path, build, size):
    """A .msh of the volume ``build(occ)`` makes, meshed with elements of at most ``size`` [m] and no
    cutting plane but those ``build`` makes: without them no nodes are placed on the axis y = z = 0
    or on the plane y = 0."""
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.add("body")
        build(gmsh.model.occ)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def half_cut_box(path):
    """The block's box cut by the plane z = 0 only, meshed without any constraint on y = 0."""
    def halves(occ):
        occ.fragment([(3, occ.addBox(-0.2, -0.02, -0.05, 0.2, 0.04, 0.05))],
                     [(3, occ.addBox(-0.2, -0.02, 0.0, 0.2, 0.04, 0.05))])

    return gmsh_body(path, halves, 0.02)


def bad_mesh(kind, tmp_path, block):
    """(mesh file, extra [mesh] keys, words the one line must contain) of a bad mesh of each kind."""
    path = tmp_path / f"{kind}.msh"
    groups, passive = block_regions(block), passive_cells(block)
    if kind == "millimetres":
        write_msh(path, 1000.0 * block.points, block.cells, groups, passive=passive)
        return path, "", ["200 m long along x", "scale = 0.001"]
    if kind == "surface groups only":
        write_msh(path, block.points, block.cells, groups, passive=passive, surface_group=True)
        return path, "", ["physical groups ('skin') are all surfaces", "add a volume physical group", "Mesh.SaveAll"]
    if kind == "no head group":
        write_msh(path, block.points, block.cells, {"left_muscle": groups["left_muscle"],
                                                    "right_muscle": groups["right_muscle"]},
                  passive=np.union1d(passive, groups["head"]))
        return path, "", ["no region 'head' ([regions] head)", "'left_muscle', 'right_muscle'"]
    if kind == "head at the other end":
        mirror = mirrored(block)
        write_msh(path, mirror.points, mirror.cells, groups, passive=passive)
        return path, 'head_end = "+x"', ["region 'head' lies at the -x end", 'head_end = "-x"']
    if kind == "half cut":
        half_cut_box(path)         # accepted by the stations, refused by the nodal model
        return path, 'head_end = "+x"\n[fluid]\nstations = "nodes"', [
            "the body axis y = 0, z = 0 is not a line of mesh edges", "cut by both planes y = 0 and z = 0",
            'needed by [fluid] stations = "nodes"']
    raise ValueError(kind)


BAD_MESHES = ["millimetres", "surface groups only", "no head group", "head at the other end", "half cut"]


@pytest.mark.parametrize("kind", BAD_MESHES)
@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"], ["shapes", "--dry-run"], ["simulate"]])
def test_a_bad_mesh_is_one_line_and_exit_code_2(kind, command, tmp_path, block, capfd):
    path, keys, words = bad_mesh(kind, tmp_path, block)
    scene = tmp_path / "scene.toml"
    scene.write_text(textwrap.dedent(f"""\
        [mesh]
        file = "{path.name}"
        {keys}
        [solver]
        duration = 0.2
        """) + ("[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n" if command[0] == "shapes" else ""))
    out_dir = tmp_path / "out"
    extra = ["--out", out_dir] if command == ["simulate"] else []
    code = main([command[0], str(scene), *command[1:], *map(str, extra)])
    out, err = capfd.readouterr()
    assert code == 2, (out, err)
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in out + err, err
    assert lines[0].startswith(f"aquarom {command[0]}: error: mesh "), lines[0]
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert not (out_dir / "trajectory.csv").exists()
    assert "plan for" not in out


@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
@pytest.mark.parametrize("length", [10.0, 5e-4])
def test_a_block_outside_1_mm_to_5_m_is_refused(command, length, tmp_path, capfd):
    scene = tmp_path / "scene.toml"
    scene.write_text(f"[mesh]\nlevel = 1\nlength = {length!r}\nwidth = {length / 5!r}\nheight = {length / 2!r}\n")
    code = main([command[0], str(scene), *command[1:]])
    out, err = capfd.readouterr()
    assert code == 2 and "plan for" not in out
    assert err.strip().splitlines() == [f"aquarom {command[0]}: error: mesh block: the body is {length:g} m long "
                                        "along x, outside 1 mm to 5 m; give [mesh] length, width and height in metres"]


@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
def test_level_with_a_mesh_file_is_refused(command, tmp_path, block, capfd):
    path = tmp_path / "block.msh"
    write_msh(path, block.points, block.cells, block_regions(block), passive=passive_cells(block))
    scene = tmp_path / "scene.toml"
    scene.write_text(f'[mesh]\nfile = "{path.name}"\nhead_end = "+x"\n')
    code = main([command[0], str(scene), *command[1:], "--level", "2"])
    out, err = capfd.readouterr()
    assert code == 2
    assert err.strip().splitlines() == [f"aquarom {command[0]}: error: --level 2: scene {scene} reads its mesh from "
                                        f"the file {path.name} ([mesh] file), and levels are those of the built-in "
                                        "block; refine the file's mesh instead, or drop --level"]
    assert main([command[0], str(scene), *command[1:], "--degree", "2"]) == 0


@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
def test_a_file_mesh_prints_its_body(command, tmp_path, block, capfd):
    path = tmp_path / "block.inp"
    write_inp(path, block.points, block.cells, block_regions(block))
    scene = tmp_path / "scene.toml"
    scene.write_text(f'[mesh]\nfile = "{path.name}"\n')
    assert main([command[0], str(scene), *command[1:]]) == 0
    out = capfd.readouterr().out
    assert f"length 0.2 m along x (head at the largest x), volume 0.0008 m³, {len(block.cells)} tetrahedra" in out
    assert ("head 0.00028 m³ (35.0 %), left_muscle 0.00024 m³ (30.0 %), right_muscle 0.00024 m³ (30.0 %) "
            "(tagged)" in out)
