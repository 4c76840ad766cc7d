"""``aquarom export``: the design's body as a binary STL (read back here with numpy), one STL per
region, the tagged volume mesh (.msh, .vtu), units, and the refusals (one line, nothing written)."""
import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.geometry.export import read_stl
from tests.conftest import one_line

LEVEL = ["--level", "1"]
SO1_OPTIMUM = ["--xi", "y_thin=0.15", "--xi", "z_head=0.5", "--xi", "z_tail=-0.5"]


def stl_surface(path):
    """(vertices (n, 3), triangles (m, 3)) of a binary STL, its corners merged by their coordinates."""
    header, _, corners = read_stl(path.read_bytes())
    assert header.startswith("aquarom export")
    points, triangles = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return points, triangles.reshape(-1, 3)


def closed_volume(points, triangles) -> float:
    """The enclosed volume, after checking every edge is shared by two triangles running it oppositely."""
    directed = triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    forward = {tuple(edge) for edge in directed.tolist()}
    assert len(forward) == len(directed)                                    # no edge twice in one direction
    assert all((b, a) in forward for a, b in directed.tolist())             # each has its opposite: closed
    centre = points.mean(axis=0)
    x = points[triangles] - centre
    return float(np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0)


def design_volume(scene_name, xi):
    from aquarom_fenics.geometry.export import design_body
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load(scene_name).replace("mesh", level=1)
    starts = {shape.name: shape.start for shape in scene.shapes}
    return design_body(scene, load_fish(scene), starts | xi).volume


def test_nominal_block_in_metres_and_millimetres(tmp_path, capsys):
    assert main(["export", "nominal", *LEVEL, "--units", "m", "--out", str(tmp_path / "m.stl")]) == 0
    printed = capsys.readouterr().out
    assert "volume 8.000000e-04 m³" in printed and "x -0.2 to 0, y -0.02 to 0.02, z -0.05 to 0.05 m" in printed
    assert main(["export", "nominal", *LEVEL, "--out", str(tmp_path / "mm.stl")]) == 0
    assert "volume 8.000000e+05 mm³" in capsys.readouterr().out
    metres, millimetres = stl_surface(tmp_path / "m.stl"), stl_surface(tmp_path / "mm.stl")
    assert np.array_equal(metres[1], millimetres[1])
    assert np.allclose(millimetres[0], 1000.0 * metres[0], rtol=1e-6)
    assert closed_volume(*metres) == pytest.approx(8.0e-4, rel=1e-6)              # float32 coordinates
    assert closed_volume(*millimetres) == pytest.approx(8.0e-4 * 1e9, rel=1e-6)


def test_so1_optimum_encloses_the_volume_of_its_design_mesh(tmp_path, capsys):
    xi = {"y_thin": 0.15, "z_head": 0.5, "z_tail": -0.5}
    assert main(["export", "so1", *LEVEL, *SO1_OPTIMUM, "--units", "m", "--out", str(tmp_path / "so1.stl")]) == 0
    expected = design_volume("so1", xi)
    assert abs(expected / 8.0e-4 - 1) > 1e-3                 # the design changes the volume
    assert f"volume {expected:.6e} m³" in capsys.readouterr().out
    assert closed_volume(*stl_surface(tmp_path / "so1.stl")) == pytest.approx(expected, rel=1e-6)


def test_regions_are_closed_surfaces_summing_to_the_body(tmp_path, capsys):
    out = tmp_path / "parts"
    assert main(["export", "so1", *LEVEL, *SO1_OPTIMUM, "--units", "m", "--regions", "--out", str(out)]) == 0
    names = sorted(path.name for path in out.glob("*.stl"))
    assert names == ["head.stl", "left_muscle.stl", "passive.stl", "right_muscle.stl"]
    assert (out / "manifest.json").exists()
    volumes = [closed_volume(*stl_surface(out / name)) for name in names]
    expected = design_volume("so1", {"y_thin": 0.15, "z_head": 0.5, "z_tail": -0.5})
    assert sum(volumes) == pytest.approx(expected, rel=1e-6)
    assert "(head.stl, left_muscle.stl, right_muscle.stl, passive.stl)" in capsys.readouterr().out


@pytest.mark.parametrize("suffix", [".msh", ".vtu"])
def test_volume_mesh_targets_keep_the_region_tags(tmp_path, suffix):
    import meshio

    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.geometry.mesh import signed_cell_volumes
    from aquarom_fenics.geometry.mesh_files import read_mesh
    from aquarom_fenics.io.scene import Scene

    path = tmp_path / f"body{suffix}"
    assert main(["export", "nominal", *LEVEL, "--out", str(path)]) == 0
    fish = load_fish(Scene.load("nominal").replace("mesh", level=1))
    mesh = read_mesh(path, scale=1e-3)                        # the toolkit's own reader, millimetres to metres
    assert len(mesh.cells) == len(fish.mesh.cells)
    assert signed_cell_volumes(mesh.points, mesh.cells).sum() == pytest.approx(8.0e-4, rel=1e-9)
    counts = {name: len(cells) for name, cells in mesh.regions.items()}
    assert counts == {"head": len(fish.tags.head_cells), "left_muscle": len(fish.tags.left_muscle_cells),
                      "right_muscle": len(fish.tags.right_muscle_cells),
                      "passive": len(fish.mesh.cells) - len(fish.tags.head_cells) - len(fish.tags.left_muscle_cells)
                      - len(fish.tags.right_muscle_cells)}
    read = meshio.read(path)
    assert set(read.field_data) == {"head", "left_muscle", "right_muscle", "passive"}


def test_force_replaces_an_export_and_never_a_foreign_file(tmp_path, capsys):
    out = tmp_path / "body.stl"
    assert main(["export", "nominal", *LEVEL, "--out", str(out)]) == 0
    assert main(["export", "nominal", *LEVEL, "--out", str(out)]) == 2
    assert one_line(capsys).endswith("exists; pass --force to replace it or choose another --out")
    assert main(["export", "nominal", *LEVEL, "--out", str(out), "--force"]) == 0
    foreign = tmp_path / "mine.stl"
    foreign.write_bytes(b"solid mine\nendsolid mine\n")
    assert main(["export", "nominal", *LEVEL, "--out", str(foreign), "--force"]) == 2
    assert "was not written by the toolkit" in one_line(capsys)
    assert foreign.read_bytes() == b"solid mine\nendsolid mine\n"


@pytest.mark.parametrize("arguments, message", [
    (["--out", "{tmp}/body.obj"], "give a file ending in .stl, .msh, .vtu"),
    (["--regions", "--out", "{tmp}/parts.stl"], "with --regions the output is a folder"),
    ([], "--out is required"),
    (["--xi", "fins=0.1", "--out", "{tmp}/body.stl"], "fins"),
])
def test_bad_inputs_are_one_line_and_write_nothing(tmp_path, capsys, arguments, message):
    arguments = [argument.format(tmp=tmp_path) for argument in arguments]
    assert main(["export", "so1", *LEVEL, *arguments]) == 2
    assert message in one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_design_whose_straight_sided_cells_fold_is_refused(tmp_path, capsys):
    # on level 2 the SO1 optimum (z_head at its bound) folds four tetrahedra at the head's corners
    # between their vertices, though det F of the exact shape field is positive at every quadrature point
    assert main(["export", "so1", "--level", "2", *SO1_OPTIMUM, "--out", str(tmp_path / "so1.stl")]) == 2
    line = one_line(capsys)
    assert "design: 4 tetrahedra of the design mesh x_0 + U ξ are inverted or flat" in line
    assert list(tmp_path.iterdir()) == []


def test_an_exported_mesh_is_a_scene_mesh_and_regions_need_tags(tmp_path, capsys):
    import meshio

    assert main(["export", "nominal", *LEVEL, "--out", str(tmp_path / "body.msh")]) == 0
    (tmp_path / "tagged.toml").write_text('[mesh]\nfile = "body.msh"\nscale = 0.001\nhead_end = "+x"\n')
    assert main(["export", str(tmp_path / "tagged.toml"), "--units", "m", "--regions",
                 "--out", str(tmp_path / "again")]) == 0
    assert "volume 8.000000e-04 m³" in capsys.readouterr().out
    assert len(list((tmp_path / "again").glob("*.stl"))) == 4
    read = meshio.read(tmp_path / "body.msh")
    meshio.write(tmp_path / "plain.vtu", meshio.Mesh(read.points, [("tetra", read.cells_dict["tetra"])]))
    (tmp_path / "plain.toml").write_text('[mesh]\nfile = "plain.vtu"\nscale = 0.001\nhead_end = "+x"\n')
    assert main(["export", str(tmp_path / "plain.toml"), "--regions", "--out", str(tmp_path / "parts")]) == 2
    error = capsys.readouterr().err.strip().splitlines()      # after the warning of a mesh without tags
    assert error[-1].startswith("aquarom export: error: --regions:") and "has no tagged regions" in error[-1]
    assert not (tmp_path / "parts").exists()
