"""Design pictures and XDMF files, the shape sheet and the ``aquarom shapes`` command."""

import os
import shutil
import textwrap

import numpy as np
import pytest
from matplotlib.image import imread
from mpi4py import MPI

from aquarom_fenics.viz import render
from aquarom_fenics.cli import main
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.geometry.mesh import signed_cell_volumes
from aquarom_fenics.io.scene import scene_from_dict

pytestmark = pytest.mark.skipif(not os.environ.get("DISPLAY") and shutil.which("Xvfb") is None,
                                reason="rendering needs a display or Xvfb")

SHAPES = {"y_thin": {"bounds": [-0.15, 0.15]}, "z_tail": {"bounds": [-0.5, 0.5]}}
SCENE_TOML = textwrap.dedent("""\
    name = "render-test"

    [mesh]
    level = 1

    [shapes]
    y_thin = { bounds = [-0.15, 0.15] }
    z_tail = { bounds = [-0.5, 0.5] }
    """)


@pytest.fixture(scope="module")
def scene():
    return scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES}, source="render-test")


@pytest.fixture(scope="module")
def fish(scene):
    return load_fish(scene)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "render-test.toml"
    path.write_text(SCENE_TOML)
    return str(path)


def read_rgb(path) -> np.ndarray:
    """(height, width, 3) colours in [0, 1] of a PNG file."""
    return imread(str(path))[..., :3]


def panel(picture: np.ndarray, row: int, column: int) -> np.ndarray:
    width, height = render.PANEL_SIZE
    return picture[row * height:(row + 1) * height, column * width:(column + 1) * width]


def drawn_fraction(image: np.ndarray) -> float:
    """Fraction of the pixels that are not (nearly) white background."""
    return float((image < 0.9).any(axis=2).mean())


def test_tetra_grid_keeps_cells_and_volume(fish):
    grid = render.tetra_grid(fish.mesh.points, fish.mesh.cells)
    assert grid.n_cells == fish.mesh.cells.shape[0]
    assert set(np.unique(grid.celltypes)) == {10}  # VTK_TETRA
    expected = signed_cell_volumes(fish.mesh.points, fish.mesh.cells).sum()
    assert grid.volume == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.20 * 0.04 * 0.10, rel=1e-9)


def test_cell_regions_follow_the_tags(fish):
    regions = render.cell_regions(fish.tags, fish.mesh.cells.shape[0])
    counts = np.bincount(regions, minlength=len(render.REGION_NAMES))
    tags = fish.tags
    assert counts[1:].tolist() == [tags.head_cells.size, tags.left_muscle_cells.size, tags.right_muscle_cells.size]
    assert counts.sum() == fish.mesh.cells.shape[0] and counts[0] > 0


def test_render_design_writes_xdmf_and_a_picture_of_the_design(fish, tmp_path):
    from dolfinx import io

    xi = {"y_thin": 0.1, "z_tail": 0.4}
    design = fish.design(xi)
    xdmf, h5, png = render.render_design(fish, design, xi, tmp_path / "design")
    assert (xdmf.name, h5.name, png.name) == ("design.xdmf", "design.h5", "design.png")
    assert all(path.stat().st_size > 0 for path in (xdmf, h5, png))
    with io.XDMFFile(MPI.COMM_WORLD, str(xdmf), "r") as stream:
        mesh = stream.read_mesh(name="mesh")
    n_cells = mesh.topology.index_map(3).size_global
    assert n_cells == fish.mesh.cells.shape[0]
    assert mesh.geometry.x.min(axis=0) == pytest.approx(design.min(axis=0), abs=1e-12)
    assert mesh.geometry.x.max(axis=0) == pytest.approx(design.max(axis=0), abs=1e-12)
    picture = read_rgb(png)
    assert picture.shape == (render.DESIGN_SIZE[1], render.DESIGN_SIZE[0], 3)
    assert picture.std() > 0.05
    assert len(np.unique(picture.reshape(-1, 3), axis=0)) > 50


def test_shape_sheet_has_one_row_of_three_panels_per_shape(fish, scene, tmp_path):
    (png,) = render.render_shape_sheet(fish, scene, tmp_path)
    assert png == tmp_path / "shapes.png"
    picture = read_rgb(png)
    width, height = render.PANEL_SIZE
    assert picture.shape == (len(scene.shapes) * height, 3 * width, 3)
    for row in range(len(scene.shapes)):
        for column in range(3):
            assert 0.1 < drawn_fraction(panel(picture, row, column)) < 0.6, (row, column)


def test_shape_sheet_is_deterministic(fish, scene, tmp_path):
    first = render.render_shape_sheet(fish, scene, tmp_path / "first")[0].read_bytes()
    second = render.render_shape_sheet(fish, scene, tmp_path / "second")[0].read_bytes()
    assert first == second


def test_refused_bound_shows_its_reason_instead_of_a_fish(tmp_path):
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": {"y_thin": {"bounds": [-0.15, 1.0]}}})
    fish = load_fish(scene)
    picture = read_rgb(render.render_shape_sheet(fish, scene, tmp_path)[0])
    refused, nominal = panel(picture, 0, 2), panel(picture, 0, 1)
    assert drawn_fraction(refused) < 0.1 < drawn_fraction(nominal)
    red_text = (refused[..., 0] > 0.5) & (refused[..., 1] < 0.4) & (refused[..., 2] < 0.4)
    assert red_text.sum() > 100


def test_cli_shapes_writes_the_sheet(scene_file, tmp_path, capsys):
    out = tmp_path / "sheet"
    assert main(["shapes", scene_file, "--out", str(out)]) == 0
    assert (out / "shapes.png").stat().st_size > 0
    assert f"wrote {out / 'shapes.png'}" in capsys.readouterr().out


def test_cli_shapes_with_xi_writes_the_design(scene_file, tmp_path):
    out = tmp_path / "design"
    assert main(["shapes", scene_file, "--xi", "y_thin=0.1", "--xi", "z_tail=-0.3", "--out", str(out)]) == 0
    assert all((out / name).stat().st_size > 0 for name in ("design.xdmf", "design.h5", "design.png"))


def test_cli_shapes_refuses_an_inverting_design_in_one_line(scene_file, tmp_path, capsys):
    out = tmp_path / "refused"
    assert main(["shapes", scene_file, "--xi", "y_thin=2.0", "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("warning: --xi y_thin=2.0 is outside")     # y_thin's bounds are ±0.15
    error = "\n".join(lines[1:])
    assert len(error.splitlines()) == 1
    assert "y_thin" in error
    assert not (out / "design.png").exists()


def test_cli_shapes_refuses_an_unknown_parameter(scene_file, tmp_path, capsys):
    assert main(["shapes", scene_file, "--xi", "bogus=0.1", "--out", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1
    assert "bogus" in error


@pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb")
def test_the_virtual_display_holds_no_pipe_of_its_caller_and_stops_with_the_process(tmp_path):
    """A process without DISPLAY starts its own Xvfb; whoever reads the process's output sees it end
    when the process ends (the server inherits no pipe: MPI's singleton daemon otherwise holds the
    output open while the server lives), and the server does not outlive the process."""
    import subprocess
    import sys
    from pathlib import Path

    child = textwrap.dedent("""\
        import os
        from mpi4py import MPI
        from aquarom_fenics.viz.display import ensure_display
        ensure_display()
        print(os.environ["DISPLAY"])
        """)
    environment = {key: value for key, value in os.environ.items() if key != "DISPLAY"}
    finished = subprocess.run([sys.executable, "-c", child], env=environment, capture_output=True, text=True,
                              timeout=60, cwd=tmp_path)
    assert finished.returncode == 0, finished.stderr
    display = finished.stdout.strip()
    assert display.startswith(":")
    assert not (Path("/tmp/.X11-unix") / f"X{display[1:]}").exists()
