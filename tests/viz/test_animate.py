"""Animations of a simulation run, the basis sheet and their commands (`aquarom animate`, `aquarom basis`)."""
import math
import os
import shutil
import textwrap

import imageio.v2 as imageio
import numpy as np
import pytest
from matplotlib.image import imread
from PIL import Image

from aquarom_fenics.io import run_outputs
from aquarom_fenics.viz import animate
from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.dynamics.simulate import simulate_fom

pytestmark = pytest.mark.skipif(not os.environ.get("DISPLAY") and shutil.which("Xvfb") is None,
                                reason="rendering needs a display or Xvfb")

N_SAMPLES = 11
"""Stored samples of the short run: t = 0, 0.02, …, 0.2 s."""

SHAPES = {"z_tail": {"bounds": [-0.5, 0.5]}, "y_thin": {"bounds": [-0.15, 0.15]}}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A short FOM run (level 1, 0.2 s) with its displacement.npz."""
    out = tmp_path_factory.mktemp("nominal-fom")
    scene = Scene.load("nominal").replace("mesh", level=1).replace("solver", duration=0.2)
    result = simulate_fom(scene, out_dir=out, progress=False, keep_states=True)
    model = result.model
    run_outputs.write_displacement_series(out / run_outputs.DISPLACEMENT_FILE, model.fish.design(None),
                                      model.fish.mesh.cells, result.trajectory.arrays()["time"],
                                      [model.nodal_displacement(u) for u, *_ in result.states])
    return out


@pytest.fixture(scope="module")
def so1_like():
    """A level-1 scene with two shape variations, its fish and its PROM."""
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES}, source="basis-test")
    fish = load_fish(scene)
    return scene, fish, build_prom(scene, fish=fish)


def drawn_fraction(image: np.ndarray) -> float:
    """Fraction of the pixels that are not (nearly) white background."""
    return float((image[..., :3] < 0.9).any(axis=2).mean())


def test_displacement_series_round_trip(run_dir):
    series = run_outputs.read_displacement_series(run_dir / run_outputs.DISPLACEMENT_FILE)
    n_nodes = series.points.shape[0]
    assert series.time.shape == (N_SAMPLES,) and series.time[-1] == pytest.approx(0.2)
    assert series.displacement.shape == (N_SAMPLES, n_nodes, 3) and series.cells.shape[1] == 4
    assert np.all(series.displacement[0] == 0.0) and np.abs(series.displacement[-1]).max() > 1e-5
    copy = run_outputs.write_displacement_series(run_dir.parent / "copy.npz", series.points, series.cells,
                                             series.time, series.displacement)
    again = run_outputs.read_displacement_series(copy)
    for name in ("points", "cells", "time", "displacement"):
        assert np.array_equal(getattr(again, name), getattr(series, name)), name


def test_inconsistent_series_are_refused(tmp_path):
    points, cells = np.zeros((4, 3)), np.array([[0, 1, 2, 3]])
    with pytest.raises(ValueError, match="displacement must be"):
        run_outputs.write_displacement_series(tmp_path / "bad.npz", points, cells, [0.0, 0.1], np.zeros((1, 4, 3)))
    np.savez(tmp_path / "other.npz", points=points)
    with pytest.raises(InputError, match="not a displacement series"):
        run_outputs.read_displacement_series(tmp_path / "other.npz")


def test_animate_writes_an_mp4_and_a_gif_with_one_frame_per_sample(run_dir, tmp_path, capsys):
    movie = tmp_path / "swim.mp4"
    assert main(["animate", str(run_dir), "--out", str(movie), "--gif", str(movie.with_suffix(".gif")), "--fps", "10"]) == 0
    assert f"wrote {movie}" in capsys.readouterr().out
    reader = imageio.get_reader(movie)
    frames = [frame for frame in reader]
    metadata = reader.get_meta_data()
    reader.close()
    width, height = animate.VIEW_SIZE
    assert len(frames) == N_SAMPLES and metadata["fps"] == 10 and metadata["codec"] == "h264"
    assert frames[0].shape == (height, 2 * width, 3)
    first, last = (frame / 255.0 for frame in (frames[0], frames[-1]))
    assert 0.1 < drawn_fraction(first) < 0.6
    assert np.abs(last - first).mean() > 1e-3
    with Image.open(movie.with_suffix(".gif")) as preview:
        assert preview.n_frames == N_SAMPLES
        assert preview.size == (2 * width // animate.GIF_DOWNSCALE, height // animate.GIF_DOWNSCALE)


def test_animate_stride_keeps_every_kth_sample(run_dir):
    movie, _ = animate.animate_run(run_dir, fps=5, stride=3)
    assert movie == run_dir / animate.ANIMATION_FILE
    with imageio.get_reader(movie) as reader:
        assert reader.count_frames() == math.ceil(N_SAMPLES / 3)


def test_basis_sheet_has_one_panel_per_basis_vector(so1_like, tmp_path):
    _, fish, prom = so1_like
    path, = animate.render_basis_sheet(prom, fish, tmp_path)
    rows, columns = animate.basis_sheet_shape(prom.size)
    width, height = animate.BASIS_PANEL_SIZE
    picture = imread(str(path))
    assert picture.shape[:2] == (rows * height, columns * width)
    for index in range(rows * columns):
        row, column = divmod(index, columns)
        panel = picture[row * height:(row + 1) * height, column * width:(column + 1) * width]
        assert (drawn_fraction(panel) > 0.05) == (index < prom.size), index


def test_basis_vectors_are_named_by_what_they_are():
    names = ("z_tail", "y_thin")
    meaning = animate.basis_vector_meaning
    assert meaning("rigid_x", [6.41], names) == "rigid translation in x"
    assert meaning("mode_1", [6.41], names) == "vibration mode 1 (6.41 Hz)"
    assert meaning("theta_1_1", [6.41], names) == "modal derivative θ11"
    assert meaning("xi_1_2", [6.41], names) == "shape sensitivity Ξ12 of mode 1 for y_thin"
    assert meaning("psi", [6.41], names) == "actuation mode ψ"
    assert "θψ" in meaning("theta_psi", [6.41], names)


def test_basis_command_writes_the_sheet(tmp_path, capsys):
    scene_file = tmp_path / "basis-test.toml"
    scene_file.write_text(textwrap.dedent("""\
        [mesh]
        level = 3
        [shapes]
        z_tail = { bounds = [-0.5, 0.5] }
        """))
    out = tmp_path / "sheet"
    assert main(["basis", str(scene_file), "--level", "1", "--out", str(out)]) == 0
    assert "psi" in capsys.readouterr().out
    assert (out / animate.BASIS_SHEET_FILE).stat().st_size > 10_000


def test_animate_without_a_run_directory_exits_2(tmp_path, capsys):
    assert main(["animate", str(tmp_path / "missing")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "missing" in error and "does not exist" in error


def test_animate_without_displacements_names_the_file_and_how_to_get_it(run_dir, tmp_path, capsys):
    for name in ("summary.json", "trajectory.csv"):
        shutil.copy(run_dir / name, tmp_path / name)
    assert main(["animate", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert run_outputs.DISPLACEMENT_FILE in error and "aquarom simulate" in error
    assert not (tmp_path / animate.ANIMATION_FILE).exists()
