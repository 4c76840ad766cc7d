"""The meshio formats (.vtu, .med, Exodus): the block written by meshio reads back with its regions
and swims as the built-in block; a bad file is one line (SPEC §3)."""
import importlib.util
import sys

import meshio
import numpy as np
import pytest

from aquarom_fenics.api import simulate
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.geometry.mesh_files import read_mesh

REGIONS = ("head", "left_muscle", "right_muscle")


@pytest.fixture(scope="module")
def block():
    return block_mesh(1)


def region_numbers(mesh) -> np.ndarray:
    """One integer per cell: 1, 2, 3 for the head and the muscles (REGIONS order), 0 elsewhere."""
    values = np.zeros(len(mesh.cells), dtype=np.int64)
    for number, name in enumerate(REGIONS, start=1):
        values[mesh.regions[name]] = number
    return values


def write_vtu(path, mesh, array="gmsh:physical", named=True):
    """The mesh as a binary .vtu with its regions as the integer cell data ``array``; ``named``: with
    the field data ``name: [number, 3]`` that names them (as gmsh and ParaView write it: meshio's
    writer leaves field data out, so it is added to the XML)."""
    meshio.Mesh(mesh.points, [("tetra", mesh.cells)], cell_data={array: [region_numbers(mesh)]}).write(str(path))
    if named:
        arrays = "".join(f'<DataArray type="Int64" Name="{name}" NumberOfTuples="1" NumberOfComponents="2" '
                         f'format="ascii">{number} 3</DataArray>\n' for number, name in enumerate(REGIONS, start=1))
        text = path.read_text()
        path.write_text(text.replace("<UnstructuredGrid>", f"<UnstructuredGrid>\n<FieldData>\n{arrays}</FieldData>", 1))


def write_med(path, mesh):
    """The mesh as a .med file: one family per region (-1, -2, -3), each in the group of its name."""
    written = meshio.Mesh(mesh.points, [("tetra", mesh.cells)], cell_data={"cell_tags": [-region_numbers(mesh)]})
    written.cell_tags = {-number: [name] for number, name in enumerate(REGIONS, start=1)}
    written.write(str(path))


def assert_same_block(read, block, names=REGIONS):
    np.testing.assert_array_equal(read.points, block.points)
    np.testing.assert_array_equal(read.cells, block.cells)
    for name, block_name in zip(names, REGIONS):
        np.testing.assert_array_equal(read.regions[name], block.regions[block_name])


def test_vtu_regions_are_named_by_the_field_data(tmp_path, block):
    path = tmp_path / "block.vtu"
    write_vtu(path, block)
    read = read_mesh(path)
    assert_same_block(read, block)
    assert sorted(read.regions) == sorted(REGIONS)        # 0: the passive cells, in no region


@pytest.mark.parametrize("array", ["CellEntityIds", "region", "my_tags"])
def test_vtu_regions_without_names_are_their_numbers(tmp_path, block, array):
    path = tmp_path / "block.vtu"
    write_vtu(path, block, array=array, named=False)
    read = read_mesh(path)
    assert_same_block(read, block, names=("1", "2", "3"))
    assert sorted(read.regions) == ["1", "2", "3"]


def test_vtu_with_two_unnamed_integer_arrays_is_refused(tmp_path, block):
    path = tmp_path / "block.vtu"
    meshio.Mesh(block.points, [("tetra", block.cells)],
                cell_data={"a": [region_numbers(block)], "b": [region_numbers(block)]}).write(str(path))
    with pytest.raises(InputError, match=r"block.vtu: several integer cell-data arrays \(a, b\) .* name the "
                                         r"regions' array one of gmsh:physical, CellEntityIds"):
        read_mesh(path)


def test_med_regions_are_the_groups_of_the_families(tmp_path, block):
    path = tmp_path / "block.med"
    write_med(path, block)
    read = read_mesh(path)
    assert_same_block(read, block)
    assert sorted(read.regions) == sorted(REGIONS)      # family 0 (the passive cells) is no region


def test_a_vtu_of_triangles_only_is_refused(tmp_path, block):
    path = tmp_path / "skin.vtu"
    meshio.Mesh(block.points, [("triangle", block.cells[:, :3])]).write(str(path))
    with pytest.raises(InputError, match=r"skin.vtu: contains no first-order tetrahedra \(cells found: triangle\)"):
        read_mesh(path)


@pytest.mark.parametrize("suffix", [".vtu", ".med"])
def test_a_file_meshio_cannot_read_is_one_error(tmp_path, suffix):
    path = tmp_path / f"garbage{suffix}"
    path.write_text("not a mesh\n")
    with pytest.raises(InputError, match=rf"garbage\{suffix}: meshio cannot read it as "):
        read_mesh(path)


def test_exodus_without_netcdf4_is_one_line(tmp_path, block, monkeypatch):
    """meshio reads and writes Exodus II with netCDF4, which Debian 12 does not install with meshio
    (the set-up installs python3-netcdf4; here its import fails as on a machine without it)."""
    monkeypatch.setitem(sys.modules, "netCDF4", None)      # `import netCDF4` raises ImportError
    path = tmp_path / "block.exo"
    path.write_bytes(b"CDF\x01" + bytes(60))
    with pytest.raises(InputError, match=r"block.exo: reading an Exodus II file with meshio needs the Python "
                                         r"package netCDF4, which is not installed \(Debian: python3-netcdf4\)$"):
        read_mesh(path)


@pytest.mark.skipif(importlib.util.find_spec("netCDF4") is None, reason="meshio needs netCDF4 for Exodus")
def test_exodus_regions_are_its_element_blocks(tmp_path, block):
    path = tmp_path / "block.exo"
    order = np.argsort(region_numbers(block), kind="stable")
    blocks = [("tetra", block.cells[order][region_numbers(block)[order] == number]) for number in range(4)]
    meshio.Mesh(block.points, blocks).write(str(path))
    read = read_mesh(path)
    assert sorted(read.regions) == ["1", "2", "3", "4"]
    for number, name in enumerate(REGIONS, start=2):
        np.testing.assert_array_equal(np.sort(order[read.regions[str(number)]]), block.regions[name])


# ---------------------------------------------------------------------------------------------
# The FOM on the block read from a meshio file is the FOM on the block


@pytest.fixture(scope="module")
def block_distance():
    from conftest import coarse_scene

    scene = coarse_scene(solver={"duration": 0.1})
    result = simulate(scene)
    assert result.completed and abs(result.distance) > 1e-8
    return scene, result.distance


@pytest.mark.parametrize("suffix, write", [(".vtu", write_vtu), (".med", write_med)])
def test_fom_on_the_block_from_a_meshio_file_equals_the_block(tmp_path, block, block_distance, suffix, write):
    scene, distance = block_distance
    path = tmp_path / f"block{suffix}"
    write(path, block)
    result = simulate(scene.replace("mesh", file=str(path)))
    assert result.completed
    assert result.distance == pytest.approx(distance, rel=0, abs=1e-10)
