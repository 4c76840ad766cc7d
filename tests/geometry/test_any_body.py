"""Any elongated body (SPEC §3, §5): the stations need no nodes on the body axis, the virtual mass
takes the body's depth from its own skin, the body may lie along any axis of its mesh file, and its
head end is declared or inferred from the head region (refused when ambiguous)."""
import logging
import textwrap

import numpy as np
import pytest

from aquarom_fenics.api import simulate
from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry import gmsh_session
from aquarom_fenics.geometry.body import TO_SWIMMING_FRAME, in_swimming_frame
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.geometry.mesh import FishMesh, signed_cell_volumes
from aquarom_fenics.geometry.shapes import CATALOG, shape_displacement

from conftest import coarse_scene
from test_mesh_regions import block_regions, gmsh_body, mirrored, passive_cells, write_msh

L, W, H = 0.20, 0.04, 0.10
SHORT = {"duration": 0.2}


@pytest.fixture(scope="module")
def block():
    from aquarom_fenics.geometry.block import block_mesh

    return block_mesh(1)


@pytest.fixture(scope="module")
def block_run():
    """The built-in block's FOM over 0.2 s (level 1, degree 1, stations)."""
    scene = coarse_scene(solver=SHORT)
    result = simulate(scene)
    assert result.completed and abs(result.distance) > 1e-6 and result.tail_amplitude > 1e-4
    return scene, result


def uncut_block(path):
    return gmsh_body(path, lambda occ: occ.addBox(-L, -W / 2, -H / 2, L, W, H), 0.02)


def ellipsoid(path):
    """An ellipsoid of semi-axes L/2, W/2, H/2 along x, y, z (its tail and head are points): gmsh's mesh of
    the unit ball stretched along the axes (gmsh 4.8 meshes no dilated sphere), written without regions."""
    gmsh = gmsh_session.import_gmsh()
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25)
        gmsh.model.add("ball")
        gmsh.model.occ.addSphere(0.0, 0.0, 0.0, 1.0)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.generate(3)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        _, nodes = gmsh.model.mesh.getElementsByType(4)
    finally:
        gmsh.finalize()
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(tags.size)
    points = coordinates.reshape(-1, 3) * [L / 2, W / 2, H / 2] - [L / 2, 0.0, 0.0]
    cells = index[nodes.astype(np.int64)].reshape(-1, 4)
    used = np.unique(cells)
    renumber = np.zeros(points.shape[0], dtype=np.int64)
    renumber[used] = np.arange(used.size)
    write_msh(path, points[used], renumber[cells], {}, passive=np.arange(len(cells)))
    return path


# ---------------------------------------------------------------------------------------------
# The virtual mass's depth from the skin


def test_half_depths_on_the_block_are_todays_dorsal_heights():
    """On the block the station's half depth (z_top - z_bottom)/2 of the design is today's exact dorsal
    height H/2 + Σ ξ_k U_k,z(X, 0, H/2), and its ξ-gradient U_k,z(X, 0, H/2), for every catalogue field."""
    names = sorted(CATALOG)
    scene = coarse_scene(solver=SHORT, mesh={"degree": 2},
                         shapes={name: {"bounds": [-0.5, 0.5]} for name in names})
    fish = load_fish(scene)
    assert not fish.tags.box.z_axis                      # the block's axis is at z = 0
    xi = 0.04 * np.arange(1, len(names) + 1) / len(names)
    model = FullOrderModel(scene, fish, xi)
    try:
        thrust = model.thrust
        for sections, half_depth in ((thrust.rear_sections, thrust.dorsal_z),
                                     (thrust.front_sections, thrust.front_dorsal_z)):
            dorsal = sections.top.copy()
            dorsal[:, 2] = H / 2                             # (X_i - x_head, 0, H/2) on the dorsal skin
            gradient = np.column_stack([shape_displacement(name, dorsal, fish.tags.box)[:, 2] for name in names])
            assert np.any(np.abs(gradient) > 1e-3)
            np.testing.assert_allclose(thrust.half_depth_gradient(len(names), sections), gradient, rtol=0, atol=1e-12)
            np.testing.assert_allclose(half_depth, H / 2 + gradient @ xi, rtol=0, atol=1e-12)
    finally:
        model.destroy()


# ---------------------------------------------------------------------------------------------
# Bodies without nodes on their axis


def test_a_block_meshed_without_cutting_planes_swims_with_stations(tmp_path, block_run):
    scene, block = block_run
    path = uncut_block(tmp_path / "uncut.msh")
    uncut = scene.replace("mesh", file=str(path), head_end="+x")
    fish = load_fish(uncut)
    assert not fish.tags.has_spine and fish.tags.tail_node is None
    result = simulate(uncut)
    assert result.completed
    # another mesh (and regions by cell centroid): the same swimmer to within its discretisation
    assert result.tail_amplitude == pytest.approx(block.tail_amplitude, rel=0.25)
    assert abs(result.distance - block.distance) < 0.25 * block.tail_amplitude


def test_an_ellipsoid_without_axis_nodes_runs_and_its_depth_comes_from_its_skin(tmp_path, caplog):
    from aquarom_fenics.physics.stations import station_positions
    from aquarom_fenics.physics.thrust_full_order import station_sections

    path = ellipsoid(tmp_path / "ellipsoid.msh")
    scene = coarse_scene(solver=SHORT, mesh={"file": str(path), "head_end": "+x"})
    fish = load_fish(scene)
    box = fish.tags.box
    assert not fish.tags.has_spine
    sections = station_sections(fish, station_positions(box.length, box.x_tail, 40))
    depth = sections.top[:, 2] - sections.bottom[:, 2]
    x = sections.top[:, 0] + box.length / 2                  # from the centre
    exact = H * np.sqrt(np.clip(1 - (2 * x / box.length) ** 2, 0, None))
    assert depth.max() == pytest.approx(H, rel=0.03)
    assert depth[0] < 0.2 * H and depth[-1] < 0.2 * H      # pointed ends
    assert np.abs(depth - exact).max() < 0.1 * H            # the faceted ellipse
    with caplog.at_level(logging.INFO, logger="aquarom"):
        result = simulate(scene)
    assert result.completed and np.isfinite(result.distance) and result.tail_amplitude > 0
    assert "has no end face" in caplog.text and "the last slab's half-hat" in caplog.text


def test_the_nodal_model_refuses_a_body_without_axis_nodes_in_one_line(tmp_path, capfd):
    path = uncut_block(tmp_path / "uncut.msh")
    scene = tmp_path / "scene.toml"
    scene.write_text(f'[mesh]\nfile = "{path.name}"\nhead_end = "+x"\n[fluid]\nstations = "nodes"\n'
                     '[solver]\nduration = 0.2\n')
    for command in (["simulate", "--dry-run"], ["simulate", "--out", str(tmp_path / "run")]):
        assert main([command[0], str(scene), *command[1:]]) == 2
        lines = capfd.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and "no nodes on the body axis y = 0, z = 0" in lines[0], lines
        assert 'needed by [fluid] stations = "nodes"' in lines[0]
    assert not (tmp_path / "run" / "trajectory.csv").exists()


# ---------------------------------------------------------------------------------------------
# The body's axis and head end


@pytest.mark.parametrize("head_end", sorted(TO_SWIMMING_FRAME))
def test_a_body_along_any_axis_turns_back_into_the_swimming_frame(block, head_end):
    """The block placed with its head at ``head_end`` comes back exactly, positively oriented."""
    transform = TO_SWIMMING_FRAME[head_end]
    placed_points = block.points @ transform        # P⁻¹ = Pᵀ: x = Pᵀ x'
    cells = block.cells if np.linalg.det(transform) > 0 else block.cells[:, [0, 1, 3, 2]]
    placed = FishMesh(points=placed_points, cells=cells, source="placed", regions=block.regions)
    assert np.all(signed_cell_volumes(placed.points, placed.cells) > 0)
    axis = head_end[1]
    for declared in (head_end, ""):
        back = in_swimming_frame(placed, axis, declared, "head")
        np.testing.assert_array_equal(back.points, block.points)
        np.testing.assert_array_equal(back.cells, block.cells)


def test_the_block_along_y_swims_as_the_block(tmp_path, block, block_run):
    scene, block_result = block_run
    path = tmp_path / "along_y.msh"
    write_msh(path, block.points @ TO_SWIMMING_FRAME["+y"], block.cells, block_regions(block),
              passive=passive_cells(block))
    result = simulate(scene.replace("mesh", file=str(path), axis="y"))
    assert result.completed
    assert result.distance == pytest.approx(block_result.distance, rel=0, abs=1e-10)
    assert result.tail_amplitude == pytest.approx(block_result.tail_amplitude, rel=0, abs=1e-10)


def test_an_undeclared_head_end_is_inferred_from_the_head_region_in_one_line(tmp_path, block, block_run, capfd):
    """The block mirrored in x without [mesh] head_end: its head region is at -x, said once; it swims as
    the block."""
    scene, block_result = block_run
    path = tmp_path / "mirrored.msh"
    mirror = mirrored(block)
    write_msh(path, mirror.points, mirror.cells, block_regions(block), passive=passive_cells(block))
    toml = tmp_path / "scene.toml"
    toml.write_text(f'[mesh]\nfile = "{path.name}"\n')
    assert main(["mesh", str(toml)]) == 0
    err = capfd.readouterr().err.strip().splitlines()
    assert err == [f"mesh {path}: the head is at its -x end, where the region 'head' lies ([mesh] head_end not "
                   "given; set it to say so)"]
    result = simulate(scene.replace("mesh", file=str(path)))
    assert result.distance == pytest.approx(block_result.distance, rel=0, abs=1e-10)
    with pytest.raises(InputError, match=r"region 'head' lies at the -x end of the body, but \[mesh\] head_end = \"\+x\""):
        load_fish(scene.replace("mesh", file=str(path), head_end="+x"))


def ambiguous_head(kind, block):
    """Regions whose head does not tell the head end: in the middle, over the whole body, or none."""
    x = block.points[block.cells].mean(axis=1)[:, 0]
    if kind == "middle":
        head = np.flatnonzero(np.abs(x + L / 2) < 0.1 * L)
    elif kind == "whole body":
        head = np.arange(len(block.cells))
    else:
        return {name: block.regions[name] for name in ("left_muscle", "right_muscle")}
    rest = np.setdiff1d(np.arange(len(block.cells)), head)
    left = np.intersect1d(block.regions["left_muscle"], rest)
    right = np.intersect1d(block.regions["right_muscle"], rest)
    return {"head": head, "left_muscle": left, "right_muscle": right}


@pytest.mark.parametrize("kind, words", [
    ("middle", ["the region 'head' ([regions] head) reaches neither end of the body along x",
                "the head region must reach exactly one end"]),
    ("whole body", ["the region 'head' ([regions] head) reaches both ends of the body along x",
                    "the head region must reach exactly one end"]),
    ("no head", ["[mesh] head_end is not given and there is no region 'head' ([regions] head)",
                 "its regions are 'left_muscle', 'right_muscle'", 'set [mesh] head_end = "+x" or "-x"']),
])
@pytest.mark.parametrize("command", [["mesh"], ["simulate", "--dry-run"]])
def test_an_ambiguous_head_end_is_refused_in_one_line(kind, words, command, tmp_path, block, capfd):
    path = tmp_path / "ambiguous.msh"
    regions = {name: cells for name, cells in ambiguous_head(kind, block).items() if len(cells)}
    passive = np.setdiff1d(np.arange(len(block.cells)), np.concatenate(list(regions.values())))
    write_msh(path, block.points, block.cells, regions, passive=passive if passive.size else None)
    scene = tmp_path / "scene.toml"
    scene.write_text(textwrap.dedent(f"""\
        [mesh]
        file = "{path.name}"
        """))
    assert main([command[0], str(scene), *command[1:]]) == 2
    out, err = capfd.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "plan for" not in out, err
    for word in words:
        assert word in lines[0], (word, lines[0])


def test_axis_and_head_end_must_agree_and_the_block_lies_along_x(tmp_path, block):
    with pytest.raises(InputError, match=r"\[mesh\] head_end = '\+x' is not an end along \[mesh\] axis = \"y\""):
        in_swimming_frame(block, "y", "+x", "head")
    with pytest.raises(InputError, match=r"the built-in block lies along x with its head at \+x"):
        load_fish(coarse_scene(mesh={"axis": "z", "head_end": "+z"}))
