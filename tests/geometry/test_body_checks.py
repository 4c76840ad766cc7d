"""A body mesh of the user's own is refused (one line, exit code 2) with the real cause named: pieces that
share no faces, inverted or tangled tetrahedra, cells other than tetrahedra, absurd coordinates, and a head
region or axis that do not tell where the head is (SPEC §3)."""
import textwrap

import meshio
import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry import gmsh_session
from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.geometry.body import in_swimming_frame
from aquarom_fenics.geometry.mesh import FishMesh, cell_quality
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.geometry.tags import skin_facets

from test_mesh_regions import block_regions, passive_cells, write_msh

L, W, H = 0.20, 0.04, 0.10


@pytest.fixture(scope="module")
def block():
    return block_mesh(1)


def pieces_body(path, fragment):
    """The block's box as two gmsh boxes, the head (x ≥ -0.35 L, group "head") and the rest (group "body"),
    fragmented so that they share their interface, or not (each meshed with its own nodes there)."""
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.02)
        gmsh.model.add("pieces")
        occ = gmsh.model.occ
        head = occ.addBox(-0.35 * L, -W / 2, -H / 2, 0.35 * L, W, H)
        rest = occ.addBox(-L, -W / 2, -H / 2, 0.65 * L, W, H)
        if fragment:
            occ.fragment([(3, head)], [(3, rest)])
        occ.synchronize()
        volumes = [tag for _, tag in gmsh.model.getEntities(3)]
        front = [tag for tag in volumes if gmsh.model.occ.getCenterOfMass(3, tag)[0] > -0.35 * L]
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, front), "head")
        gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, sorted(set(volumes) - set(front))), "body")
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    return path


def one_error_line(capfd, argv) -> str:
    """The single stderr line of ``aquarom`` run with ``argv``, which must exit with code 2."""
    code = main([str(arg) for arg in argv])
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in out + err, (code, out, err)
    return lines[0]


def scene_file(directory, mesh_path, keys=""):
    scene = directory / "scene.toml"
    scene.write_text(f'[mesh]\nfile = "{mesh_path.name}"\n{keys}\n[solver]\nduration = 0.2\n')
    return scene


# ---------------------------------------------------------------------------------------------
# One connected solid


def test_pieces_not_fragmented_are_refused_as_separate_solids(tmp_path, capfd):
    joined = read_mesh(pieces_body(tmp_path / "fragmented.msh", fragment=True))
    assert len(joined.cells) > 100
    path = pieces_body(tmp_path / "pieces.msh", fragment=False)
    line = one_error_line(capfd, ["mesh", scene_file(tmp_path, path)])
    assert line.startswith(f"aquarom mesh: error: mesh file {path}: the body is 2 separate solids"), line
    for words in ("share no face", "gmsh.model.occ.fragment", "so that they share faces"):
        assert words in line, (words, line)


# ---------------------------------------------------------------------------------------------
# Inverted and tangled tetrahedra


def swapped_interior_nodes(block):
    """The block's points with two interior nodes (on no skin facet) swapped: the cells around both fold."""
    interior = np.setdiff1d(np.arange(len(block.points)), skin_facets(block.cells))
    first, second = interior[0], interior[len(interior) // 2]
    points = block.points.copy()
    points[[first, second]] = points[[second, first]]
    return points


def test_swapped_nodes_are_refused_as_inverted_cells_with_the_quality(tmp_path, block, capfd):
    points = swapped_interior_nodes(block)
    path = tmp_path / "swapped.msh"
    write_msh(path, points, block.cells, block_regions(block), passive=passive_cells(block))
    line = one_error_line(capfd, ["mesh", scene_file(tmp_path, path, 'head_end = "+x"')])
    assert f"mesh file {path}: " in line and "tetrahedra are inverted or tangled" in line, line
    count = int(line.split(f"{path}: ")[1].split()[0])
    assert 0 < count < 40, line
    assert "tetrahedron number " in line and "minimum cell quality -" in line, line


def test_a_face_of_three_tetrahedra_is_refused_as_overlapping_cells(tmp_path, block):
    """A tetrahedron added on an interior face, its apex inside one of the two cells already there."""
    face = np.sort(block.cells[0, 1:])
    owners = np.flatnonzero([set(face) <= set(cell) for cell in block.cells.tolist()])
    assert len(owners) == 2                      # an interior face
    points = np.vstack([block.points, block.points[block.cells[owners[1]]].mean(axis=0)])
    cells = np.vstack([block.cells, [[*face, len(block.points)]]])
    path = tmp_path / "overlap.msh"
    write_msh(path, points, cells, {}, passive=np.arange(len(cells)))
    with pytest.raises(InputError, match=rf"^mesh file {path}: 1 faces are shared by three tetrahedra or more "
                                         r"\(overlapping cells\)"):
        read_mesh(path)


def test_cells_written_with_either_orientation_are_not_inverted(tmp_path, block):
    """A valid mesh whose tetrahedra are listed half one way round, half the other (a mirrored half written
    without reordering) reads as the block: orientation alone is no inversion."""
    cells = block.cells.copy()
    cells[::2] = cells[::2][:, [0, 1, 3, 2]]
    path = tmp_path / "mixed.msh"
    write_msh(path, block.points, cells, block_regions(block), passive=passive_cells(block))
    read = read_mesh(path)
    assert cell_quality(read.points, read.cells).min() > 0.0
    np.testing.assert_array_equal(np.sort(read.cells, axis=1), np.sort(block.cells, axis=1))


# ---------------------------------------------------------------------------------------------
# Cells other than tetrahedra


def hexahedra_behind(block, count=3):
    """(points, hexahedra): ``count`` cubes of side H/5 behind the block's tail, sharing no node with it."""
    side = H / 5
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    points = np.vstack([(corners + [-(k + 1), 0, 0]) * side + [-L, 0, 0] for k in range(count)])
    hexahedra = len(block.points) + np.arange(8 * count).reshape(count, 8)
    return np.vstack([block.points, points]), hexahedra


def test_a_vtu_with_hexahedra_beside_its_tetrahedra_is_refused_naming_them(tmp_path, block, capfd):
    points, hexahedra = hexahedra_behind(block)
    path = tmp_path / "mixed.vtu"
    meshio.Mesh(points, [("tetra", block.cells), ("hexahedron", hexahedra)]).write(str(path))
    with pytest.raises(InputError, match=rf"^mesh file {path}: besides its {len(block.cells)} tetrahedra it holds "
                                         r"3 hexahedron cells; .*would leave holes"):
        read_mesh(path)


def test_a_msh_with_hexahedra_beside_its_tetrahedra_is_refused_naming_them(tmp_path, block):
    points, hexahedra = hexahedra_behind(block, count=2)
    path = tmp_path / "mixed.msh"
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mixed")
        volume = gmsh.model.addDiscreteEntity(3)
        gmsh.model.mesh.addNodes(3, volume, np.arange(1, len(points) + 1), points.ravel())
        gmsh.model.mesh.addElementsByType(volume, 4, np.arange(1, len(block.cells) + 1), (block.cells + 1).ravel())
        gmsh.model.mesh.addElementsByType(volume, 5, len(block.cells) + 1 + np.arange(2), (hexahedra + 1).ravel())
        gmsh.model.addPhysicalGroup(3, [volume])
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
    with pytest.raises(InputError, match=rf"^mesh file {path}: besides its {len(block.cells)} tetrahedra it holds "
                                         r"2 Hexahedron 8 cells; .*would leave holes"):
        read_mesh(path)


# ---------------------------------------------------------------------------------------------
# Absurd coordinates: named before any volume is computed


@pytest.mark.parametrize("kind, keys, words", [
    ("times 1e200", "", ["the body is 2e+199 m long along x", "check its coordinates and [mesh] scale"]),
    ("one node far away", "", ["lies far from the rest of the body",
                               "the node at (-0.11, 0, 1e+30) (of tetrahedron number "]),
    ("translated far", "translate = [1e16, 0, 0]", ["translate = [1e+16, 0, 0] moves the body 1e+16 m from the origin",
                                                    "lose their precision"]),
    ("not a number", "", ["non-finite node coordinates", "the node at (-0.11, 0, nan)"]),
])
def test_absurd_coordinates_are_named_before_the_volumes(kind, keys, words, tmp_path, block, capfd):
    points = block.points.copy()
    node = int(np.argmin(np.linalg.norm(points - [-0.11, 0.0, 0.0], axis=1)))      # a node on the axis
    np.testing.assert_allclose(points[node], [-0.11, 0.0, 0.0], rtol=0, atol=1e-12)
    if kind == "times 1e200":
        points *= 1e200
    elif kind == "one node far away":
        points[node, 2] = 1e30
    elif kind == "not a number":
        points[node, 2] = np.nan
    path = tmp_path / "absurd.msh"
    write_msh(path, points, block.cells, block_regions(block), passive=passive_cells(block))
    line = one_error_line(capfd, ["mesh", scene_file(tmp_path, path, keys)])
    assert "zero volume" not in line, line
    for word in words:
        assert word in line, (word, line)


# ---------------------------------------------------------------------------------------------
# The head region and the axis


def with_head(block, head):
    regions = {name: np.setdiff1d(cells, head) for name, cells in block.regions.items()} | {"head": head}
    return FishMesh(points=block.points, cells=block.cells, source="regions", regions=regions)


def test_a_head_region_reaching_both_ends_is_refused_whatever_the_declared_end(block):
    """The head group of the head and the tail pieces: its centroid lies at +x, but it reaches both ends."""
    x = block.points[block.cells].mean(axis=1)[:, 0]
    mesh = with_head(block, np.union1d(block.regions["head"], np.flatnonzero(x < -0.9 * L)))
    for declared in ("-x", "+x", ""):
        with pytest.raises(InputError, match=r"^mesh regions: the region 'head' \(\[regions\] head\) reaches both ends "
                                             r"of the body along x \(it spans -0.2 to 0 m, the body -0.2 to 0 m\)"):
            in_swimming_frame(mesh, "x", declared, "head")


@pytest.mark.parametrize("offset", [0.0, 0.005 * L])
def test_a_head_region_in_the_middle_is_refused_whatever_the_declared_end(block, offset):
    """A head group around the middle (exactly, or a little towards +x) reaches neither end."""
    x = block.points[block.cells].mean(axis=1)[:, 0]
    mesh = with_head(block, np.flatnonzero(np.abs(x + L / 2 - offset) < 0.1 * L))
    for declared in ("-x", "+x", ""):
        with pytest.raises(InputError, match=r"^mesh regions: the region 'head' \(\[regions\] head\) reaches neither "
                                             r"end of the body along x"):
            in_swimming_frame(mesh, "x", declared, "head")


@pytest.mark.parametrize("declared", ["+z", "-z", ""])
def test_an_axis_along_which_the_body_is_not_longest_is_refused(block, declared):
    with pytest.raises(InputError, match=r"^mesh block level 1 \(.*\): \[mesh\] axis = \"z\", but the body is 0.1 m "
                                         r"long along z and 0.2 m along x; .*set \[mesh\] axis = \"x\""):
        in_swimming_frame(block, "z", declared, "head")


@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
def test_a_block_taller_than_long_is_refused_as_a_block(command, tmp_path, capfd):
    """The block lies along x: its own message, not the mesh file's advice to change [mesh] axis."""
    scene = tmp_path / "scene.toml"
    scene.write_text("[mesh]\nlevel = 1\nlength = 0.2\nwidth = 0.04\nheight = 0.3\n")
    line = one_error_line(capfd, [command[0], scene, *command[1:]])
    assert line == (f"aquarom {command[0]}: error: mesh block: [mesh] height = 0.3 m is over its length = 0.2 m; the "
                    "block swims along x, its longest side: give [mesh] length, width and height so that length is "
                    "the longest"), line


def test_the_head_region_and_axis_messages_reach_the_command_line(tmp_path, block, capfd):
    x = block.points[block.cells].mean(axis=1)[:, 0]
    head = np.union1d(block.regions["head"], np.flatnonzero(x < -0.9 * L))
    regions = {name: np.setdiff1d(cells, head) for name, cells in block_regions(block).items()} | {"head": head}
    path = tmp_path / "head_and_tail.msh"
    write_msh(path, block.points, block.cells, regions,
              passive=np.setdiff1d(np.arange(len(block.cells)), np.concatenate(list(regions.values()))))
    line = one_error_line(capfd, ["simulate", scene_file(tmp_path, path, 'head_end = "-x"'), "--dry-run"])
    assert "the region 'head' ([regions] head) reaches both ends of the body along x" in line, line
    line = one_error_line(capfd, ["mesh", scene_file(tmp_path, path, 'axis = "z"\nhead_end = "+z"')])
    assert '[mesh] axis = "z", but the body is 0.1 m long along z and 0.2 m along x' in line, line
