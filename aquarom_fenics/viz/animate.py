"""Animations of a simulated swimmer and the picture sheet of a reduction basis (SPEC §7).

A simulation run directory holds ``displacement.npz``: the design's nodal positions x_0 + U ξ,
its tetrahedra, the stored sample times and the nodal displacement of every sample. From it
``animate_run`` renders the fish from above and from the side, coloured by the displacement
magnitude, with a camera fixed over the whole run so that forward swimming shows, and writes
an MP4 and a GIF preview. ``render_basis_sheet`` draws every vector of a reduction basis on
the fish. Lengths are in metres unless a name says cm, times in seconds, sizes in pixels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.run_outputs import DISPLACEMENT_FILE, DisplacementSeries, read_displacement_series
from aquarom_fenics.viz.render import EDGE_COLOUR, EDGE_OPACITY, _frame_camera, _plotter, _save, tetra_grid

ANIMATION_FILE = "animation.mp4"
"""Default animation name inside the run directory; the GIF preview has the same stem."""

BASIS_SHEET_FILE = "basis.png"

VIEW_SIZE = (640, 400)
"""Width and height [px] of each of the two views; multiples of 16 so H.264 needs no resizing."""

VIEW_TOP_SPACE = 0.2
VIEW_BOTTOM_SPACE = 0.14
"""Fractions of a view's height kept free above the fish (text) and below it (captions, colour bar)."""

VIEW_MARGIN = 0.06
"""Free border around the swept region of the fish, as a fraction of the view's half-size."""

GIF_DOWNSCALE = 2
"""The GIF preview is this many times smaller than the MP4 in each direction."""

GIF_PALETTE_SOURCES = 8
"""Number of evenly spaced frames whose colours make the GIF's shared palette."""

DEFAULT_FPS = 20
"""Frames per second of the animation (a 2 s run with h = 0.02 s plays in about 5 s)."""

BASIS_PANEL_SIZE = (420, 300)
BASIS_COLUMNS = 4
BASIS_LABEL_SPACE = 0.26
"""Panel size [px], panels per row and fraction of a panel's height kept for its label."""

BASIS_PEAK_FRACTION = 0.15
"""Every basis vector is drawn scaled to a largest nodal displacement of this fraction of the body length."""

COLOUR_MAP = "viridis"
REST_OUTLINE_COLOUR = "#8c8c8c"
OUTLINE_FEATURE_ANGLE = 30.0
"""Skin edges whose faces meet at a sharper angle [degrees] form the rest-shape outline."""

TITLE_FONT_SIZE = 10
CAPTION_FONT_SIZE = 8
BASIS_LABEL_FONT_SIZE = 7
"""Font sizes [pt]; a rendered line is about twice as many pixels high."""

COLOUR_BAR_FONT_SIZE = 12
"""Font size [px] of the colour bars' title and labels."""


@dataclass(frozen=True)
class _View:
    """One view of the animation: parallel projection, x to the right."""

    caption: str
    towards_camera: tuple[float, float, float]   # unit vector from the fish to the camera
    up: tuple[float, float, float]               # unit vector pointing up in the picture


VIEWS = (_View("from above; grey outline at t = 0", (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
         _View("from the right side; grey outline at t = 0", (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)))
"""The two views side by side: from above (+z, left of the fish up) and from its right flank (-y, z up)."""


# ---------------------------------------------------------------------------------- animation
ANIMATION_MARK = "written by aquarom animate"
"""Comment stored in every MP4 and GIF the toolkit writes (how --force knows its own files)."""


def animate_run(run_dir: Path, out: Path | None = None, fps: int = DEFAULT_FPS, stride: int = 1,
                gif: Path | None | bool = True, before_writing=None) -> list[Path]:
    """Write the animation of a simulation run (MP4) and its GIF preview (half size).

    One frame per ``stride``-th stored sample, played at ``fps`` frames per second. ``out``
    defaults to RUN_DIR/animation.mp4; ``gif`` is the preview's path (True: the MP4's with .gif,
    None or False: no preview). ``before_writing(paths)`` is called once the run is read and
    before anything is written (the command line claims its outputs there). Rank 0 renders;
    returns the files written on every rank.
    """
    run_dir = Path(run_dir)
    mp4_path = Path(out) if out is not None else run_dir / ANIMATION_FILE
    check_animation_options(mp4_path, fps, stride)
    series, com_x, title = _load_run(run_dir)
    gif_path = mp4_path.with_suffix(".gif") if gif is True else (Path(gif) if gif else None)
    if before_writing is not None:
        before_writing([mp4_path] + ([gif_path] if gif_path else []))
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        samples = range(0, series.time.size, stride)
        frames = _render_frames(series, samples, com_x, title)
        _write_movies(frames, mp4_path, gif_path, fps)
    comm.barrier()
    return [mp4_path] + ([gif_path] if gif_path else [])


def is_animation_file(path: Path) -> bool:
    """An MP4 or GIF written by :func:`animate_run` (it carries :data:`ANIMATION_MARK`)."""
    try:
        return ANIMATION_MARK.encode() in Path(path).read_bytes()
    except OSError:
        return False


def check_animation_options(mp4_path: Path, fps: int, stride: int, gif_path: Path | None = None) -> None:
    """Refuse an output name that is not .mp4 (.gif for the preview), fps < 1 or stride < 1."""
    if mp4_path.suffix.lower() != ".mp4":
        raise InputError(f"--out {mp4_path}: the animation is written as MP4, give a file name ending in .mp4")
    if gif_path is not None and Path(gif_path).suffix.lower() != ".gif":
        raise InputError(f"--gif {gif_path}: the preview is written as GIF, give a file name ending in .gif")
    if fps < 1:
        raise InputError(f"--fps {fps}: must be a whole number of frames per second >= 1")
    if stride < 1:
        raise InputError(f"--stride {stride}: must be >= 1 (1 renders every stored sample)")


def _load_run(run_dir: Path) -> tuple[DisplacementSeries, np.ndarray, str]:
    """The run's displacement series, centre-of-mass x [m] at its samples, and a title."""
    from aquarom_fenics.io.readback import load_run_summary, load_trajectory

    if not run_dir.is_dir():
        raise InputError(f"run directory {run_dir} does not exist (give the --out directory of `aquarom simulate`)")
    for name in ("summary.json", "trajectory.csv"):
        if not (run_dir / name).is_file():
            raise InputError(f"{run_dir} has no {name}: not an output directory of `aquarom simulate`")
    displacement_path = run_dir / DISPLACEMENT_FILE
    if not displacement_path.is_file():
        raise InputError(f"{displacement_path} is missing: the run did not store nodal displacements; "
                         f"rerun `aquarom simulate SCENE --out {run_dir}` to write it")
    series = read_displacement_series(displacement_path)
    trajectory = load_trajectory(run_dir / "trajectory.csv")
    com_x = np.interp(series.time, trajectory["time"], trajectory["com_x"])
    summary = load_run_summary(run_dir / "summary.json")
    return series, com_x, _run_title(summary)


def _run_title(summary: dict) -> str:
    """``scene (MODEL), mesh, design`` of a run's summary.json."""
    mesh = summary.get("scene_values", {}).get("mesh", {})
    mesh_text = f"mesh {Path(str(mesh['file'])).name}" if mesh.get("file") else f"level {mesh.get('level', '?')}"
    xi = {name: value for name, value in summary.get("xi", {}).items() if value != 0.0}
    design = ", ".join(f"{name} = {value:g}" for name, value in xi.items()) or "nominal design"
    return f"{summary.get('scene', '?')} ({str(summary.get('model', '?')).upper()}), {mesh_text}, {design}"


def _write_movies(frames, mp4_path: Path, gif_path: Path | None, fps: int) -> None:
    """Stream RGB frames into the MP4 and collect the downscaled GIF preview (both marked with
    :data:`ANIMATION_MARK`)."""
    import imageio.v2 as imageio
    from PIL import Image

    mp4_path.parent.mkdir(parents=True, exist_ok=True)
    previews = []
    with imageio.get_writer(mp4_path, format="FFMPEG", fps=fps, codec="libx264", pixelformat="yuv420p",
                            quality=8, macro_block_size=16,
                            output_params=["-metadata", f"comment={ANIMATION_MARK}"]) as writer:
        for frame in frames:
            writer.append_data(frame)
            if gif_path is None:
                continue
            height, width = frame.shape[:2]
            size = (width // GIF_DOWNSCALE, height // GIF_DOWNSCALE)
            previews.append(Image.fromarray(frame).resize(size, Image.Resampling.LANCZOS))
    if gif_path is None:
        return
    palette = _shared_palette(previews)
    indexed = [preview.quantize(palette=palette, dither=Image.Dither.NONE) for preview in previews]
    indexed[0].save(gif_path, save_all=True, append_images=indexed[1:], duration=round(1000 / fps), loop=0,
                    comment=ANIMATION_MARK.encode())


def _shared_palette(images):
    """A 256-colour palette image for all ``images`` (PIL RGB), from a few evenly spaced ones.

    One palette for every frame keeps the colours steady and the GIF small.
    """
    from PIL import Image

    picked = np.linspace(0, len(images) - 1, min(len(images), GIF_PALETTE_SOURCES)).round().astype(int)
    montage = Image.fromarray(np.vstack([np.asarray(images[index]) for index in picked]))
    return montage.quantize(colors=256, method=Image.Quantize.MEDIANCUT)


def _render_frames(series: DisplacementSeries, samples, com_x: np.ndarray, title: str):
    """RGB images (height, width, 3) of the fish at ``samples``, both views side by side.

    The outline of the design at rest is drawn in front of the fish, so that the distance swum
    shows against it.
    """
    plotter = _plotter((1, len(VIEWS)), VIEW_SIZE)
    grid = tetra_grid(series.deformed(0), series.cells)
    magnitude_cm = 100 * np.linalg.norm(series.displacement[list(samples)], axis=2)
    grid.point_data["displacement"] = magnitude_cm[0]
    colour_range = (0.0, max(float(magnitude_cm.max()), 1e-6))
    swept = np.vstack([series.deformed(sample) for sample in samples])
    rest_outline = _feature_edges(tetra_grid(series.points, series.cells))
    scale = max(_view_half_height(swept, np.array(view.up)) for view in VIEWS)
    for column, view in enumerate(VIEWS):
        plotter.subplot(0, column)
        _add_view(plotter, view, grid, rest_outline, colour_range, swept, scale)
    plotter.subplot(0, 0)
    _add_text(plotter, title, (0.02, 0.97), TITLE_FONT_SIZE)
    clock = _add_text(plotter, "", (0.02, 0.87), TITLE_FONT_SIZE)
    plotter.subplot(0, 1)
    _add_colour_bar(plotter, "displacement magnitude [cm]", (0.55, 0.0), (0.42, 0.14))
    try:
        for index, sample in enumerate(samples):
            grid.points = series.deformed(sample)
            grid.point_data["displacement"] = magnitude_cm[index]
            clock.SetInput(f"t = {series.time[sample]:.2f} s    distance (centre of mass x) "
                           f"{100 * com_x[sample]:+.2f} cm")
            plotter.render()
            yield plotter.screenshot(return_img=True)[..., :3].copy()
    finally:
        plotter.close()


def _add_view(plotter, view: _View, grid, rest_outline, colour_range: tuple[float, float], swept: np.ndarray,
              scale: float) -> None:
    """The fish ``grid`` coloured by its displacement [cm], the rest outline in front of it and
    the caption, seen along ``view`` with a camera that frames the ``swept`` positions [m].
    """
    towards_camera, up = np.array(view.towards_camera), np.array(view.up)
    in_front = rest_outline.translate(np.ptp(swept, axis=0).max() * towards_camera, inplace=False)
    plotter.add_mesh(in_front, color=REST_OUTLINE_COLOUR, line_width=1.5, lighting=False)
    plotter.add_mesh(grid, scalars="displacement", cmap=COLOUR_MAP, clim=colour_range, show_edges=True,
                     edge_color=EDGE_COLOUR, edge_opacity=EDGE_OPACITY, ambient=0.45, diffuse=0.65,
                     show_scalar_bar=False)
    _add_text(plotter, view.caption, (0.02, VIEW_BOTTOM_SPACE * 0.8), CAPTION_FONT_SIZE)
    _fix_axis_camera(plotter, swept, towards_camera, up, scale)


def _view_half_height(points: np.ndarray, up: np.ndarray) -> float:
    """Parallel scale [m] (half the view's height) that fits ``points`` with x across and ``up`` upwards.

    Every view shows x horizontally at the same scale, so the largest of the views' scales is
    used for all of them.
    """
    width, height = VIEW_SIZE
    half_across = np.ptp(points[:, 0]) / 2 * (1 + VIEW_MARGIN)
    half_up = np.ptp(points @ up) / 2 * (1 + VIEW_MARGIN)
    free = 1 - VIEW_TOP_SPACE - VIEW_BOTTOM_SPACE
    return max(half_up / free, half_across * height / width)


def _fix_axis_camera(plotter, points: np.ndarray, towards_camera: np.ndarray, up: np.ndarray, scale: float) -> None:
    """Parallel projection along ``-towards_camera``, x to the right, fish between the text bands."""
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    centre_up = centre @ up + scale * (VIEW_TOP_SPACE - VIEW_BOTTOM_SPACE)
    focal = centre - (centre @ up) * up + centre_up * up
    distance = 10 * np.ptp(points, axis=0).max()
    plotter.camera_position = [tuple(focal + distance * towards_camera), tuple(focal), tuple(up)]
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = scale
    plotter.renderer.reset_camera_clipping_range()


def _add_text(plotter, text: str, anchor: tuple[float, float], font_size: int):
    """Black text hanging below ``anchor`` (fractions of the current view's width and height)."""
    actor = plotter.add_text(text, position=anchor, viewport=True, font_size=font_size, color="black",
                             font_file=str(_font_file()))
    actor.prop.SetVerticalJustificationToTop()
    return actor


def _add_colour_bar(plotter, title: str, corner: tuple[float, float], size: tuple[float, float]) -> None:
    """Horizontal colour bar of the last added mesh: three labels below it, then the title.

    ``corner`` (lower left) and ``size`` are fractions of the current view's width and height.
    """
    from vtkmodules.vtkCommonCore import VTK_FONT_FILE

    bar = plotter.add_scalar_bar(title, n_labels=3, fmt="%.2f", color="black", vertical=False,
                                 position_x=corner[0], position_y=corner[1], width=size[0], height=size[1],
                                 title_font_size=COLOUR_BAR_FONT_SIZE, label_font_size=COLOUR_BAR_FONT_SIZE,
                                 unconstrained_font_size=True)
    bar.SetTextPositionToPrecedeScalarBar()
    for text in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
        text.SetFontFamily(VTK_FONT_FILE)
        text.SetFontFile(str(_font_file()))
        text.SetBold(False)
        text.SetItalic(False)


def _font_file() -> Path:
    """DejaVu Sans, shipped with matplotlib: it has the Greek letters of the basis labels."""
    import matplotlib

    return Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"


def _feature_edges(grid):
    """The skin edges of a tetrahedral grid whose faces meet at a sharp angle (the body's outline)."""
    return grid.extract_surface().extract_feature_edges(OUTLINE_FEATURE_ANGLE, boundary_edges=False,
                                                        non_manifold_edges=False, manifold_edges=False)


# ---------------------------------------------------------------------------------- basis sheet
def render_basis_sheet(prom, fish, out_dir: Path) -> list[Path]:
    """Write basis.png: every basis vector of ``prom`` on the fish at its building point.

    Each panel shows the design x_0 + U ξ_c deformed by one vector, scaled so that its largest
    nodal displacement is BASIS_PEAK_FRACTION of the body length, coloured by the displacement
    magnitude [cm] on a scale shared by all panels, over the outline of the undeformed design.
    Panels are BASIS_PANEL_SIZE pixels, BASIS_COLUMNS per row. Rank 0 renders; returns [path]
    on every rank once it is written.
    """
    out_dir = Path(out_dir)
    picture_path = out_dir / BASIS_SHEET_FILE
    comm = MPI.COMM_WORLD
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
        rest = fish.design(prom.design_point)
        peak = BASIS_PEAK_FRACTION * np.ptp(rest[:, 0])
        displacements = [_scaled_to_peak(prom.basis[:, :, k], peak) for k in range(prom.size)]
        labels = [f"{label}: {basis_vector_meaning(label, prom.frequencies, prom.shape_names)}"
                  for label in prom.labels]
        _render_basis_panels(rest, fish.mesh.cells, displacements, labels, peak, picture_path)
    comm.barrier()
    return [picture_path]


def basis_sheet_shape(n_vectors: int) -> tuple[int, int]:
    """(rows, columns) of the basis sheet for ``n_vectors`` panels."""
    columns = min(BASIS_COLUMNS, n_vectors)
    return math.ceil(n_vectors / columns), columns


def basis_vector_meaning(label: str, frequencies, shape_names) -> str:
    """What a basis vector named ``label`` (SPEC §7) is, e.g. 'vibration mode 1 (6.41 Hz)'.

    ``frequencies`` [Hz] are those of the vibration modes, ``shape_names`` the PROM's parameters.
    """
    kind, *numbers = label.split("_")
    if label == "rigid_x":
        return "rigid translation in x"
    if label == "psi":
        return "actuation mode ψ"
    if label == "theta_psi":
        return "modal derivative θψ of the actuation mode"
    if kind == "psi" and len(numbers) == 1 and numbers[0].isdigit():
        return f"actuation mode ψ of activation pattern {numbers[0]}"
    if label.startswith("theta_psi_") and all(number.isdigit() for number in numbers[1:]):
        return f"modal derivative θψ of activation pattern{'s' if len(numbers) > 2 else ''} {' and '.join(numbers[1:])}"
    if label.startswith("psi_mass_"):
        return f"inertia vector K⁻¹Mψ of activation pattern {numbers[-1]}"
    if kind == "mode" and len(numbers) == 1:
        mode = int(numbers[0])
        return f"vibration mode {mode} ({frequencies[mode - 1]:.2f} Hz)"
    if kind == "theta" and len(numbers) == 2:
        return f"modal derivative θ{_indices(numbers)}"
    if kind == "xi" and len(numbers) == 2:
        mode, parameter = int(numbers[0]), int(numbers[1])
        return f"shape sensitivity Ξ{_indices(numbers)} of mode {mode} for {shape_names[parameter - 1]}"
    return label


def _indices(numbers: list[str]) -> str:
    """Subscript-like index pair: '11', or '1,12' when an index has two digits."""
    return ("," if any(len(number) > 1 for number in numbers) else "").join(numbers)


def _scaled_to_peak(vector: np.ndarray, peak: float) -> np.ndarray:
    """(n_nodes, 3) ``vector`` scaled so that its largest nodal displacement is ``peak`` [m]."""
    largest = np.linalg.norm(vector, axis=1).max()
    return vector * (peak / largest) if largest > 0 else vector


def _render_basis_panels(rest: np.ndarray, cells: np.ndarray, displacements: list[np.ndarray],
                         labels: list[str], peak: float, path: Path) -> None:
    rows, columns = basis_sheet_shape(len(displacements))
    plotter = _plotter((rows, columns), BASIS_PANEL_SIZE)
    framed = np.vstack([rest] + [rest + displacement for displacement in displacements])
    rest_outline = _feature_edges(tetra_grid(rest, cells))
    colour_range = (0.0, 100 * peak)
    for index, (displacement, label) in enumerate(zip(displacements, labels)):
        plotter.subplot(*divmod(index, columns))
        grid = tetra_grid(rest + displacement, cells)
        grid.point_data["displacement"] = 100 * np.linalg.norm(displacement, axis=1)
        plotter.add_mesh(rest_outline, color=REST_OUTLINE_COLOUR, line_width=1.5, lighting=False)
        plotter.add_mesh(grid, scalars="displacement", cmap=COLOUR_MAP, clim=colour_range, show_edges=True,
                         edge_color=EDGE_COLOUR, edge_opacity=EDGE_OPACITY, ambient=0.35, diffuse=0.75,
                         show_scalar_bar=False)
        _add_text(plotter, label, (0.02, 0.97), BASIS_LABEL_FONT_SIZE)
        if index == 0:
            _add_colour_bar(plotter, f"|u| [cm], peak {BASIS_PEAK_FRACTION:.0%} of length", (0.55, 0.74), (0.42, 0.2))
        _frame_camera(plotter, framed, BASIS_PANEL_SIZE, BASIS_LABEL_SPACE)
    _save(plotter, path)
