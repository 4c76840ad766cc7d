"""Block meshes, mesh import and the tags of SPEC §3."""
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.spatial import cKDTree

from aquarom_fenics.geometry import block as block_module
from aquarom_fenics.geometry import gmsh_session
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import shipped_meshes
from aquarom_fenics.geometry.block import LEVEL_TARGET_CELLS, block_mesh, region_planes
from aquarom_fenics.geometry.mesh import FishMesh, cell_quality, signed_cell_volumes
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.geometry.tags import cell_centroids, head_cell_mask, muscle_cell_masks, tag_fish

L, W, H = 0.20, 0.04, 0.10
SHIPPED_MESHES = shipped_meshes()
ABAQUS_FISH = SHIPPED_MESHES / "3d_rectangle_1272el.inp"


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("mesh_cache")


@pytest.fixture(scope="module")
def coarse(cache_dir):
    return block_mesh(1, cache_dir=cache_dir)


@pytest.fixture(scope="module")
def coarse_tags(coarse):
    return tag_fish(coarse)


def gmsh_module():
    return gmsh_session.import_gmsh()


def mirror(points, axis):
    mirrored = np.array(points, dtype=float)
    mirrored[:, axis] *= -1.0
    return mirrored


def distance_to_nearest(points, candidates):
    distances, _ = cKDTree(candidates).query(points)
    return distances


def write_msh(path, points, cells, boundary_triangles=(), isolated_point=None):
    """A gmsh .msh file with the tetrahedra, optional boundary triangles and an isolated node."""
    gmsh = gmsh_module()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("written")
        volume = gmsh.model.addDiscreteEntity(3)
        node_tags = np.arange(1, len(points) + 1)
        gmsh.model.mesh.addNodes(3, volume, node_tags, np.asarray(points).ravel())
        gmsh.model.mesh.addElementsByType(volume, 4, [], (np.asarray(cells) + 1).ravel())
        if len(boundary_triangles):
            surface = gmsh.model.addDiscreteEntity(2)
            triangles = (np.asarray(boundary_triangles) + 1).ravel()
            gmsh.model.mesh.addElementsByType(surface, 2, [], triangles)
        if isolated_point is not None:
            point = gmsh.model.addDiscreteEntity(0)
            gmsh.model.mesh.addNodes(0, point, [len(points) + 1], list(isolated_point))
            gmsh.model.mesh.addElementsByType(point, 15, [], [len(points) + 1])
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def write_inp(path, points, cells, node_labels, element_labels, element_sets=None):
    """An Abaqus input file with C3D4 elements, a comment, an Nset and a continued element line;
    ``element_sets`` ({name: cell indices}) become *Elset sections."""
    lines = ["*Heading", "** written by the tests", "*Part, name=fish", "*Node"]
    lines += [f"{label}, {x!r}, {y!r}, {z!r}" for label, (x, y, z) in zip(node_labels, points)]
    lines.append("*Element, type=C3D4")
    element_lines = [
        f"{label}, " + ", ".join(str(node_labels[node]) for node in cell)
        for label, cell in zip(element_labels, cells)
    ]
    first_label, *first_nodes = element_lines[0].split(", ")
    element_lines[0] = f"{first_label}, {first_nodes[0]}, {first_nodes[1]},\n" + ", ".join(
        first_nodes[2:]
    )
    lines += element_lines
    lines += ["*Nset, nset=every_third, generate", f"{node_labels[0]}, {node_labels[-1]}, 3"]
    for name, indices in (element_sets or {}).items():
        labels = [str(element_labels[index]) for index in indices]
        lines.append(f"*Elset, elset={name}")
        lines += [", ".join(labels[start:start + 16]) for start in range(0, len(labels), 16)]
    lines.append("*End Part")
    path.write_text("\n".join(lines) + "\n")


def write_uncut_box_msh(path):
    """A structured tetrahedral box mesh with 3 divisions in y and z: no node on the axis."""
    gmsh = gmsh_module()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("uncut")
        gmsh.model.occ.addBox(-L, -W / 2, -H / 2, L, W, H)
        gmsh.model.occ.synchronize()
        for _, curve in gmsh.model.getEntities(1):
            low = np.array(gmsh.model.getBoundingBox(1, curve)[:3])
            high = np.array(gmsh.model.getBoundingBox(1, curve)[3:])
            along_x = high[0] - low[0] > 0.5 * L
            gmsh.model.mesh.setTransfiniteCurve(curve, 9 if along_x else 4)
        for _, surface in gmsh.model.getEntities(2):
            gmsh.model.mesh.setTransfiniteSurface(surface)
        gmsh.model.mesh.setTransfiniteVolume(1)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


# ---------------------------------------------------------------------------------------------
# Block meshes


def test_five_levels_land_near_their_targets(tmp_path):
    for level, target in LEVEL_TARGET_CELLS.items():
        fish = block_mesh(level, cache_dir=tmp_path)
        assert abs(len(fish.cells) / target - 1.0) <= 0.15, (level, len(fish.cells))
        assert np.all(signed_cell_volumes(fish.points, fish.cells) > 0.0)
        assert cell_quality(fish.points, fish.cells).min() > 0.2


@pytest.mark.parametrize("level", [1, 3])
def test_block_is_mirror_symmetric_about_y_and_z(level, cache_dir):
    fish = block_mesh(level, cache_dir=cache_dir)
    for axis in (1, 2):
        assert distance_to_nearest(mirror(fish.points, axis), fish.points).max() <= 1e-12


def test_block_cells_are_positive_and_fill_the_box(coarse):
    volumes = signed_cell_volumes(coarse.points, coarse.cells)
    assert np.all(volumes > 0.0)
    assert volumes.sum() == pytest.approx(L * W * H, rel=1e-12)
    np.testing.assert_array_equal(coarse.points.min(axis=0), [-L, -W / 2, -H / 2])
    np.testing.assert_array_equal(coarse.points.max(axis=0), [0.0, W / 2, H / 2])
    assert coarse.points.dtype == np.float64 and coarse.cells.dtype == np.int64
    assert len(np.unique(coarse.cells)) == len(coarse.points)


def test_spine_nodes_are_equally_spaced_between_the_interface_planes(coarse, coarse_tags):
    spine = coarse.points[coarse_tags.spine_nodes]
    np.testing.assert_array_equal(spine[:, 1:], 0.0)
    ends = np.concatenate([[-L], region_planes(L, 0.35, (-0.95, -0.35)), [0.0]])
    assert np.isin(ends, spine[:, 0]).all()           # a node where each interface plane cuts the axis
    for rear, front in zip(ends[:-1], ends[1:]):
        inside = spine[(spine[:, 0] >= rear) & (spine[:, 0] <= front), 0]
        assert len(inside) >= 2
        np.testing.assert_allclose(np.diff(inside), (front - rear) / (len(inside) - 1), rtol=1e-9)
    assert coarse.points[coarse_tags.tail_node, 0] == -L
    assert coarse.points[coarse_tags.head_spine_node, 0] == 0.0
    np.testing.assert_array_equal(coarse_tags.spine_segments[:, 0], coarse_tags.spine_nodes[:-1])
    np.testing.assert_array_equal(coarse_tags.spine_segments[:, 1], coarse_tags.spine_nodes[1:])


@pytest.mark.parametrize("level", sorted(LEVEL_TARGET_CELLS))
def test_regions_are_tagged_cells_that_fill_their_boxes_exactly(level, cache_dir):
    """SPEC §3: the head (x ≥ -0.35 L) and the muscles (-0.95 L < x < -0.35 L, either side of
    y = 0) are tagged cell sets of a mesh that conforms to them: their volumes are the boxes'
    volumes to rounding, and no cell has vertices on both sides of an interface."""
    mesh = block_mesh(level, cache_dir=cache_dir)
    tags = tag_fish(mesh)
    volumes = signed_cell_volumes(mesh.points, mesh.cells)
    assert volumes[tags.head_cells].sum() == pytest.approx(0.35 * L * W * H, rel=1e-12)
    for cells in (tags.left_muscle_cells, tags.right_muscle_cells):
        assert volumes[cells].sum() == pytest.approx(0.6 * L * (W / 2) * H, rel=1e-12)
    x, y = mesh.points[mesh.cells, 0], mesh.points[mesh.cells, 1]      # (cells, 4) vertex coordinates
    tolerance = 1e-12 * L
    for plane in region_planes(L, 0.35, (-0.95, -0.35)):
        behind, ahead = (x < plane - tolerance).any(axis=1), (x > plane + tolerance).any(axis=1)
        assert not np.any(behind & ahead), f"cells straddle the plane x = {plane}"
    assert not np.any((y < -tolerance).any(axis=1) & (y > tolerance).any(axis=1))
    head = np.zeros(len(mesh.cells), bool)
    head[tags.head_cells] = True
    assert np.all(x[head] >= -0.35 * L - tolerance) and np.all(x[~head].min(axis=1) < -0.35 * L)
    for cells, side in ((tags.left_muscle_cells, 1.0), (tags.right_muscle_cells, -1.0)):
        assert np.all(x[cells] >= -0.95 * L - tolerance) and np.all(x[cells] <= -0.35 * L + tolerance)
        assert np.all(side * y[cells] >= -tolerance)
    outside = np.setdiff1d(np.arange(len(mesh.cells)),
                           np.concatenate([tags.head_cells, tags.left_muscle_cells, tags.right_muscle_cells]))
    in_muscle_slab = (x[outside] > -0.95 * L + tolerance).any(axis=1) & (x[outside] < -0.35 * L - tolerance).any(axis=1)
    assert not np.any(in_muscle_slab)                   # every cell of the muscle slab belongs to a muscle


def test_regions_follow_the_scenes_fractions(tmp_path):
    mesh = block_mesh(1, cache_dir=tmp_path, head_fraction=0.3, muscle_range=(-0.9, -0.4))
    volumes = signed_cell_volumes(mesh.points, mesh.cells)
    assert volumes[mesh.regions["head"]].sum() == pytest.approx(0.3 * L * W * H, rel=1e-12)
    assert volumes[mesh.regions["left_muscle"]].sum() == pytest.approx(0.5 * L * (W / 2) * H, rel=1e-12)
    assert len(list(tmp_path.glob("*head0.3_muscles-0.9_-0.4*.npz"))) == 1


def test_an_untagged_mesh_falls_back_to_centroids_with_a_warning(coarse, coarse_tags, caplog):
    untagged = FishMesh(points=coarse.points, cells=coarse.cells, source="untagged block")
    with caplog.at_level("WARNING", logger="aquarom"):
        tags = tag_fish(untagged)
    assert "untagged block has no tagged regions" in caplog.text and "cell centroid" in caplog.text
    # on a mesh that conforms to the regions, the centroid rule finds the tagged cells
    np.testing.assert_array_equal(tags.head_cells, coarse_tags.head_cells)
    np.testing.assert_array_equal(tags.left_muscle_cells, coarse_tags.left_muscle_cells)


def test_a_mesh_missing_a_tagged_region_is_an_input_error(coarse):
    partial = FishMesh(points=coarse.points, cells=coarse.cells, source="partial",
                       regions={"head": coarse.regions["head"]})
    with pytest.raises(InputError, match=r"^mesh partial: no region 'left_muscle' \(\[regions\] muscles\); its regions "
                                         r"are 'head'$"):
        tag_fish(partial)
    with pytest.raises(InputError, match=r"^mesh block level 1 .*: no region 'nose' \(\[regions\] head\); its regions "
                                         r"are 'head', 'left_muscle', 'right_muscle'$"):
        tag_fish(coarse, head="nose")


def test_every_segment_has_a_dorsal_node_above_its_rear_node(coarse, coarse_tags):
    dorsal = coarse.points[coarse_tags.dorsal_nodes]
    rear = coarse.points[coarse_tags.spine_segments[:, 0]]
    assert len(dorsal) == len(coarse_tags.spine_segments)
    np.testing.assert_array_equal(dorsal[:, 2], H / 2)
    np.testing.assert_array_equal(dorsal[:, 1], 0.0)
    np.testing.assert_allclose(dorsal[:, 0], rear[:, 0], atol=1e-15)
    assert np.all(np.isin(coarse_tags.dorsal_nodes, coarse_tags.skin_nodes))


def test_head_and_muscles_mirror_left_and_right(coarse, coarse_tags):
    centroids = cell_centroids(coarse.points, coarse.cells)
    left = centroids[coarse_tags.left_muscle_cells]
    right = centroids[coarse_tags.right_muscle_cells]
    head = centroids[coarse_tags.head_cells]
    assert len(left) == len(right) > 0
    assert distance_to_nearest(mirror(left, 1), right).max() <= 1e-12
    assert np.all(left[:, 1] > 0.0) and np.all(left[:, 0] > -0.95 * L)
    assert np.all(left[:, 0] < -0.35 * L)
    assert distance_to_nearest(mirror(head, 1), head).max() <= 1e-12
    assert np.all(head[:, 0] >= -0.35 * L)
    assert not set(coarse_tags.head_cells) & set(coarse_tags.left_muscle_cells)
    head_nodes = np.unique(coarse.cells[coarse_tags.head_cells])
    np.testing.assert_array_equal(coarse_tags.head_nodes, head_nodes)


def test_region_masks_are_functions_of_coordinates_only(coarse, coarse_tags):
    centroids = cell_centroids(coarse.points, coarse.cells)
    order = np.random.default_rng(0).permutation(len(centroids))
    box, tolerance = coarse_tags.box, coarse_tags.tolerance
    head = head_cell_mask(centroids[order], box, tolerance)
    left, right = muscle_cell_masks(centroids[order], box, tolerance)
    np.testing.assert_array_equal(np.sort(order[head]), coarse_tags.head_cells)
    np.testing.assert_array_equal(np.sort(order[left]), coarse_tags.left_muscle_cells)
    np.testing.assert_array_equal(np.sort(order[right]), coarse_tags.right_muscle_cells)


def test_skin_facets_close_the_box_with_outward_normals(coarse, coarse_tags):
    triangles = coarse.points[coarse_tags.skin_facets]
    edges = triangles[:, 1:] - triangles[:, :1]
    area_normals = 0.5 * np.cross(edges[:, 0], edges[:, 1])
    centres = triangles.mean(axis=1)
    assert np.abs(area_normals.sum(axis=0)).max() <= 1e-15
    enclosed_volume = np.sum(centres * area_normals) / 3.0
    assert enclosed_volume == pytest.approx(L * W * H, rel=1e-12)
    areas = np.linalg.norm(area_normals, axis=1)
    assert areas.sum() == pytest.approx(2 * (L * W + L * H + W * H), rel=1e-12)
    on_surface = np.isclose(np.abs(coarse.points[coarse_tags.skin_nodes]), [L, W / 2, H / 2])
    on_surface[:, 0] |= np.isclose(coarse.points[coarse_tags.skin_nodes, 0], 0.0)
    assert np.all(on_surface.any(axis=1))


def test_cell_quality_is_one_for_regular_and_zero_for_flat_tetrahedra():
    regular = np.array([[1, 1, 1], [-1, 1, -1], [1, -1, -1], [-1, -1, 1]], dtype=float)
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    cell = np.array([[0, 1, 2, 3]])
    assert cell_quality(regular, cell)[0] == pytest.approx(1.0, rel=1e-12)
    assert cell_quality(flat, cell)[0] == pytest.approx(0.0, abs=1e-15)
    assert cell_quality(regular, cell[:, [0, 1, 3, 2]])[0] == pytest.approx(-1.0, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# Cache and gmsh state


def test_second_call_reads_the_cache(tmp_path, monkeypatch):
    first = block_mesh(1, cache_dir=tmp_path)
    cached = list(tmp_path.glob("*.npz"))
    assert len(cached) == 1 and (tmp_path / f"{cached[0].name}.sha256").is_file()
    assert f"gmsh{gmsh_module().__version__}" in cached[0].name

    def no_meshing(*args):
        raise AssertionError("block_mesh meshed again instead of reading the cache")

    monkeypatch.setattr(block_module, "_generate_block", no_meshing)
    second = block_mesh(1, cache_dir=tmp_path)
    np.testing.assert_array_equal(second.points, first.points)
    np.testing.assert_array_equal(second.cells, first.cells)


def test_corrupt_cache_file_is_regenerated(tmp_path, monkeypatch):
    first = block_mesh(1, cache_dir=tmp_path)
    (cache_file,) = tmp_path.glob("*.npz")
    cache_file.write_bytes(b"not a zip archive")
    generate = block_module._generate_block
    calls = []
    monkeypatch.setattr(
        block_module, "_generate_block", lambda *args: calls.append(args) or generate(*args)
    )
    again = block_mesh(1, cache_dir=tmp_path)
    assert len(calls) == 1
    np.testing.assert_array_equal(again.points, first.points)
    np.testing.assert_array_equal(again.cells, first.cells)
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        cache_file.name, f"{cache_file.name}.lock", f"{cache_file.name}.sha256"]
    block_mesh(1, cache_dir=tmp_path)
    assert len(calls) == 1


def test_unwritable_cache_still_gives_the_mesh(tmp_path, coarse):
    blocking_file = tmp_path / "not_a_directory"
    blocking_file.write_text("")
    with pytest.warns(UserWarning, match="block mesh not cached"):
        fish = block_mesh(1, cache_dir=blocking_file / "cache")
    np.testing.assert_array_equal(fish.cells, coarse.cells)


def test_gmsh_is_left_as_found(tmp_path):
    gmsh = gmsh_module()
    block_mesh(1, cache_dir=tmp_path / "first")
    assert not gmsh_session.gmsh_is_initialized(gmsh)
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("caller")
        gmsh.model.occ.addSphere(0, 0, 0, 1)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm3D", 4)
        block_mesh(1, cache_dir=tmp_path / "second")
        assert gmsh_session.gmsh_is_initialized(gmsh)
        assert gmsh.model.getCurrent() == "caller"
        assert gmsh.model.getEntities(3) == [(3, 1)]
        assert gmsh.option.getNumber("Mesh.Algorithm3D") == 4
    finally:
        gmsh.finalize()


# ---------------------------------------------------------------------------------------------
# Imported meshes


def test_abaqus_fish_in_centimetres_imports_and_tags():
    fish = read_mesh(ABAQUS_FISH, scale=0.01)
    assert len(fish.cells) == 1272
    assert fish.source == str(ABAQUS_FISH)
    np.testing.assert_allclose(fish.points.min(axis=0), [-0.35, -0.05, -0.10], atol=1e-12)
    np.testing.assert_allclose(fish.points.max(axis=0), [0.0, 0.05, 0.10], atol=1e-12)
    volumes = signed_cell_volumes(fish.points, fish.cells)
    assert np.all(volumes > 0.0)
    assert volumes.sum() == pytest.approx(0.35 * 0.10 * 0.20, rel=1e-6)

    tags = tag_fish(fish)
    length = tags.box.length
    assert fish.points[tags.tail_node, 0] == pytest.approx(-length, abs=1e-12)
    assert fish.points[tags.head_spine_node, 0] == pytest.approx(0.0, abs=1e-12)
    assert len(tags.spine_nodes) >= 2
    np.testing.assert_allclose(fish.points[tags.spine_nodes, 1:], 0.0, atol=1e-12)
    assert len(tags.head_cells) > 0
    centroids = cell_centroids(fish.points, fish.cells)
    assert np.all(centroids[tags.left_muscle_cells, 1] > 0.0)
    assert np.all(centroids[tags.right_muscle_cells, 1] < 0.0)
    left_volume = volumes[tags.left_muscle_cells].sum()
    right_volume = volumes[tags.right_muscle_cells].sum()
    assert left_volume == pytest.approx(right_volume, rel=0.02)
    assert left_volume == pytest.approx(0.6 * length * 0.05 * 0.20, rel=0.05)
    np.testing.assert_allclose(fish.points[tags.dorsal_nodes, 2], 0.10, atol=1e-12)


def test_msh_round_trip_keeps_tetrahedra_and_their_nodes_only(tmp_path, coarse, coarse_tags):
    path = tmp_path / "fish.msh"
    write_msh(
        path,
        coarse.points,
        coarse.cells,
        boundary_triangles=coarse_tags.skin_facets,
        isolated_point=(5.0, 5.0, 5.0),
    )
    fish = read_mesh(path)
    assert fish.source == str(path)
    np.testing.assert_allclose(fish.points, coarse.points, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(fish.cells, coarse.cells)


def test_inp_round_trip_with_sparse_labels_scale_and_translate(tmp_path, coarse, coarse_tags):
    path = tmp_path / "fish.inp"
    node_labels = 7 + 3 * np.arange(len(coarse.points))
    element_labels = 1000 + 2 * np.arange(len(coarse.cells))
    inverted = coarse.cells.copy()
    inverted[::2] = inverted[::2][:, [1, 0, 2, 3]]
    write_inp(path, coarse.points * 100.0, inverted, node_labels, element_labels)
    fish = read_mesh(path, scale=0.01, translate=(1.0, 2.0, 3.0))
    np.testing.assert_allclose(fish.points, coarse.points + [1.0, 2.0, 3.0], atol=1e-14)
    assert np.all(signed_cell_volumes(fish.points, fish.cells) > 0.0)
    np.testing.assert_array_equal(np.sort(fish.cells, axis=1), np.sort(coarse.cells, axis=1))
    tags = tag_fish(fish)
    np.testing.assert_allclose(fish.points[tags.spine_nodes] - [1.0, 2.0, 3.0],
                               coarse.points[coarse_tags.spine_nodes], atol=1e-14)


# ---------------------------------------------------------------------------------------------
# Bad input


def test_missing_file_is_an_input_error(tmp_path):
    for name in ("absent.inp", "absent.msh"):
        with pytest.raises(InputError, match=f"{name}: not found"):
            read_mesh(tmp_path / name)


def test_corrupt_inp_is_an_input_error(tmp_path):
    path = tmp_path / "garbage.inp"
    path.write_text("this is not\nan Abaqus file\n")
    with pytest.raises(InputError, match="garbage.inp: no \\*Node section"):
        read_mesh(path)
    path.write_text("*Node\n1, 0., 0., zero\n*Element, type=C3D4\n1, 1, 1, 1, 1\n")
    with pytest.raises(InputError, match="garbage.inp: meshio cannot read it .*float: ' zero'"):
        read_mesh(path)
    path.write_text("*Node\n1, 0., 0., 0.\n*Element, type=C3D4\n1, 1, 1, 1\n")
    with pytest.raises(InputError, match="garbage.inp: meshio cannot read it .*number of data items"):
        read_mesh(path)
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match="garbage.inp: meshio cannot read it"):
        read_mesh(path)


def test_inp_without_tetrahedra_or_with_undefined_nodes_is_an_input_error(tmp_path):
    path = tmp_path / "bricks.inp"
    path.write_text("*Node\n1, 0., 0., 0.\n*Element, type=C3D8\n1, 1, 1, 1, 1, 1, 1, 1, 1\n")
    with pytest.raises(InputError, match="bricks.inp: no \\*Element, type=C3D4 section \\(elements found: hexahedron"):
        read_mesh(path)
    path.write_text("*Node\n1, 0., 0., 0.\n*Element, type=C3D4\n1, 1, 2, 3, 4\n")
    with pytest.raises(InputError, match="bricks.inp: .* refers to the undefined label 2"):
        read_mesh(path)


def test_corrupt_msh_is_an_input_error(tmp_path):
    path = tmp_path / "garbage.msh"
    path.write_text("this is not\na gmsh file\n")
    with pytest.raises(InputError, match="garbage.msh: gmsh cannot read it"):
        read_mesh(path)
    assert not gmsh_session.gmsh_is_initialized(gmsh_module())


def test_unsupported_suffix_is_an_input_error(tmp_path):
    path = tmp_path / "fish.stl"
    path.write_text("solid fish\nendsolid fish\n")
    with pytest.raises(InputError, match="fish.stl: unsupported suffix '.stl'"):
        read_mesh(path)


def test_bad_transform_and_level_are_input_errors(tmp_path):
    path = tmp_path / "fish.inp"
    with pytest.raises(InputError, match="fish.inp: scale = -1.0"):
        read_mesh(path, scale=-1.0)
    with pytest.raises(InputError, match="fish.inp: translate"):
        read_mesh(path, translate=(0.0, 1.0))
    with pytest.raises(InputError, match="level 6 does not exist"):
        block_mesh(6, cache_dir=tmp_path)
    with pytest.raises(InputError, match="width = 0.0 m"):
        block_mesh(1, width=0.0, cache_dir=tmp_path)


def test_mesh_without_nodes_on_the_axis_has_no_spine_and_the_nodal_model_refuses_it(tmp_path):
    """The stations need no nodes on the axis; the nodal model (stations = "nodes") acts on them."""
    path = tmp_path / "uncut.msh"
    write_uncut_box_msh(path)
    fish = read_mesh(path)
    assert len(fish.cells) > 0
    tags = tag_fish(fish)
    assert not tags.has_spine and tags.tail_node is None and tags.head_spine_node is None
    assert tags.spine_nodes.size == tags.dorsal_nodes.size == 0 and tags.spine_segments.shape == (0, 2)
    with pytest.raises(InputError, match=r"uncut.msh: no nodes on the body axis y = 0, z = 0 .* \(needed by \[fluid\] "
                                         r"stations = \"nodes\", the nodal thrust model; the default stations need no "
                                         r"nodes on the axis\)$"):
        tag_fish(fish, require_axis=True)


def test_empty_regions_are_input_errors(coarse):
    untagged = FishMesh(points=coarse.points, cells=coarse.cells, source="untagged")
    with pytest.raises(InputError, match="the head is empty"):
        tag_fish(untagged, head_fraction=0.001)
    with pytest.raises(InputError, match="the left muscle is empty"):
        tag_fish(untagged, muscle_range=(-1.0, -0.995))
    with pytest.raises(InputError, match="head_fraction = 1.5"):
        tag_fish(coarse, head_fraction=1.5)


def test_tail_without_axis_node_is_an_input_error(coarse, coarse_tags):
    points = coarse.points.copy()
    points[coarse_tags.tail_node, 1] += W / 8
    moved = FishMesh(points=points, cells=coarse.cells, source="moved")
    with pytest.raises(InputError, match="moved: no node on the body axis .* at the tail face"):
        tag_fish(moved, require_axis=True)
    assert not tag_fish(moved).has_spine


def test_a_gmsh_session_leaves_the_callers_sigint_handler_in_place():
    """gmsh.finalize() reinstalls the SIGINT handler of gmsh's import time; when that was a
    temporary one (here a stand-in for a simulation's Ctrl-C catcher), every later Ctrl-C would be
    swallowed. Run in a fresh interpreter, so that gmsh is imported under the temporary handler."""
    script = textwrap.dedent("""
        import signal
        from aquarom_fenics.geometry import gmsh_session
        temporary = lambda number, frame: None
        signal.signal(signal.SIGINT, temporary)
        gmsh_session.import_gmsh()
        signal.signal(signal.SIGINT, signal.default_int_handler)
        with gmsh_session.gmsh_model("probe", {}):
            pass
        print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)
    """)
    completed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.split()[-1] == "True"
