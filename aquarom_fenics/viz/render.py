"""Pictures of designs x_0 + U ξ (SPEC §4): XDMF for ParaView and headless pyvista renders.

Every picture looks at the fish along one oblique direction (from the tail, the right flank and
above) with a parallel projection, so that changes of width (y) and of height (z) both show and
panels of one sheet share a scale. Lengths are in metres, picture sizes in pixels.
"""
from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.stop_signals import stop_between_steps, stop_for
from aquarom_fenics.io.xdmf import REGION_TAG_NAMES
from aquarom_fenics.viz.display import ensure_display

PANEL_SIZE = (350, 250)
"""Width and height [px] of one panel of the shape sheet."""

PANEL_LABEL_SPACE = 0.16
"""Fraction of a panel's height kept free above the fish for its label."""

DESIGN_SIZE = (1000, 600)
"""Width and height [px] of the design picture."""

TITLE_FONT_SIZE = 11
LABEL_FONT_SIZE = 6
REFUSAL_FONT_SIZE = 6
REFUSAL_LINE_LENGTH = 48
"""Font sizes [pt] (a line is about twice as many pixels high) and characters per refusal line."""

VIEW_DIRECTION = np.array([-0.4, -1.0, 1.0])
"""From the fish towards the camera: behind the tail (-x), on the right flank (-y), above (+z)."""

FRAME_MARGIN = 0.12
"""Free border around the framed fish, as a fraction of the picture's half-size."""

REGION_NAMES = REGION_TAG_NAMES
REGION_COLOURS = ("#e6d5ac", "#9a9a9a", "#d1495b", "#2e86c1")
"""Colour of each region, in the order of ``REGION_NAMES``."""

NOMINAL_OUTLINE_COLOUR = "#a0a0a0"
OUTLINE_FEATURE_ANGLE = 30.0
"""Skin edges whose faces meet at a sharper angle [degrees] are drawn as the nominal outline."""
EDGE_COLOUR = "#3c3c3c"
EDGE_OPACITY = 0.4
"""Colour and opacity of the design's skin edges."""
REFUSED_COLOUR = "#b03030"
"""Colour of the text of a panel whose design is refused."""


@dataclass(frozen=True)
class _Panel:
    """One picture of a sheet: its label and the design's nodal positions [m], or why not."""

    label: str
    points: np.ndarray | None
    refusal: str = ""


def render_design(fish, design_points: np.ndarray, xi: dict[str, float], out_dir: Path) -> list[Path]:
    """Write the design mesh with its region tags (design.xdmf + design.h5) and a picture of it (design.png).

    ``design_points`` are the checked nodal positions x_0 + U ξ [m] (``fish.design(xi)``). Rank 0
    writes the XDMF and renders the picture. Returns the
    paths of the three files on every rank, once they are all written.
    """
    from aquarom_fenics.io.xdmf import write_design_xdmf

    comm = MPI.COMM_WORLD
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    xdmf_path, picture_path = out_dir / "design.xdmf", out_dir / "design.png"
    vertices = design_points[:fish.mesh.points.shape[0]]   # a quadratic mesh's edge midpoints follow them
    if comm.rank == 0:
        write_design_xdmf(xdmf_path, vertices, fish.mesh.cells, cell_regions(fish.tags, fish.mesh.cells.shape[0]))
        _render_design_picture(fish, design_points, _design_title(fish, xi), picture_path)
    comm.barrier()
    return [xdmf_path, xdmf_path.with_suffix(".h5"), picture_path]


def render_shape_sheet(fish, scene, out_dir: Path) -> list[Path]:
    """Write shapes.png: one row per shape variation of the scene at ξ = lower, 0, upper.

    Every panel is PANEL_SIZE pixels; a bound that ``fish.design`` refuses shows the reason
    instead of a fish. Rank 0 renders; returns [path] on every rank once it is written.
    """
    if not scene.shapes:
        raise InputError(f"scene {scene.name} has no shape variations to show")
    comm = MPI.COMM_WORLD
    out_dir = Path(out_dir)
    picture_path = out_dir / "shapes.png"
    if comm.rank == 0:
        out_dir.mkdir(parents=True, exist_ok=True)
        panels = [[_sheet_panel(fish, shape.name, value, role) for value, role in _sheet_columns(shape)]
                  for shape in scene.shapes]
        _render_sheet(fish, panels, picture_path)
    comm.barrier()
    return [picture_path]


def _sheet_columns(shape) -> tuple[tuple[float, str], ...]:
    """(ξ, role) of the three panels of a shape's row: lower bound, nominal (ξ = 0), upper bound."""
    return (shape.lower, "lower bound"), (0.0, "nominal"), (shape.upper, "upper bound")


def _sheet_panel(fish, name: str, value: float, role: str) -> _Panel:
    label = f"{name} = {value:g}  ({role})"
    try:
        return _Panel(label, fish.design({name: value}))
    except InputError as error:
        return _Panel(label, None, str(error))


def _design_title(fish, xi: dict[str, float], per_line: int = 3) -> str:
    """``name = value`` of every parameter of the fish (0 where ``xi`` does not give one)."""
    values = fish.parameter_vector(xi)
    terms = [f"{name} = {value:g}" for name, value in zip(fish.shape_names, values)] or ["nominal"]
    lines = [",  ".join(terms[start:start + per_line]) for start in range(0, len(terms), per_line)]
    return "design: " + "\n".join(lines)


def _render_design_picture(fish, design_points: np.ndarray, title: str, path: Path) -> None:
    plotter = _plotter((1, 1), DESIGN_SIZE)
    _add_nominal_outline(plotter, fish)
    _add_design(plotter, fish, design_points, legend=True)
    _add_text(plotter, title, (0.5, 0.98), TITLE_FONT_SIZE, "black", centred=True)
    plotter.add_axes(color="black")
    title_height = (title.count("\n") + 1) * 2.4 * TITLE_FONT_SIZE + 12
    _frame_camera(plotter, np.vstack([fish.mesh.points, design_points]), DESIGN_SIZE, title_height / DESIGN_SIZE[1])
    _save(plotter, path)


def _render_sheet(fish, panels: list[list[_Panel]], path: Path) -> None:
    shape = (len(panels), len(panels[0]))
    plotter = _plotter(shape, PANEL_SIZE)
    framed = np.vstack([fish.mesh.points] + [p.points for row in panels for p in row if p.points is not None])
    for row, row_panels in enumerate(panels):
        for column, panel in enumerate(row_panels):
            plotter.subplot(row, column)
            _draw_panel(plotter, fish, panel)
            _frame_camera(plotter, framed, PANEL_SIZE, PANEL_LABEL_SPACE)
    _save(plotter, path)


def _draw_panel(plotter, fish, panel: _Panel) -> None:
    if panel.points is None:
        reason = textwrap.fill(f"refused: {panel.refusal}", width=REFUSAL_LINE_LENGTH)
        _add_text(plotter, f"{panel.label}\n{reason}", (0.02, 0.97), REFUSAL_FONT_SIZE, REFUSED_COLOUR)
        return
    _add_nominal_outline(plotter, fish)
    _add_design(plotter, fish, panel.points)
    _add_text(plotter, panel.label, (0.02, 0.97), LABEL_FONT_SIZE, "black")


def _add_text(plotter, text: str, anchor: tuple[float, float], font_size: int, colour: str,
              centred: bool = False) -> None:
    """Text hanging below ``anchor`` (fractions of the current view's width and height).

    ``font_size`` is in points; the rendered line height is about twice as many pixels.
    """
    actor = plotter.add_text(text, position=anchor, viewport=True, font_size=font_size, color=colour)
    actor.prop.SetVerticalJustificationToTop()
    if centred:
        actor.prop.SetJustificationToCentered()


def _add_nominal_outline(plotter, fish) -> None:
    """The feature edges of the nominal skin as a faint wireframe."""
    skin = tetra_grid(fish.mesh.points, fish.mesh.cells).extract_surface()
    outline = skin.extract_feature_edges(OUTLINE_FEATURE_ANGLE, boundary_edges=False, non_manifold_edges=False,
                                         manifold_edges=False)
    plotter.add_mesh(outline, color=NOMINAL_OUTLINE_COLOUR, line_width=1.5, lighting=False)


def _add_design(plotter, fish, design_points: np.ndarray, legend: bool = False) -> None:
    """The design, every cell coloured by its region, with the skin's edges drawn."""
    grid = tetra_grid(design_points, fish.mesh.cells)
    grid.cell_data["region"] = cell_regions(fish.tags, fish.mesh.cells.shape[0])
    legend_bar = dict(title="", n_labels=0, color="black", vertical=True, label_font_size=16,
                      position_x=0.86, position_y=0.05, width=0.03, height=0.3)
    plotter.add_mesh(grid, scalars="region", cmap=list(REGION_COLOURS), clim=(-0.5, len(REGION_NAMES) - 0.5),
                     n_colors=len(REGION_NAMES), annotations=dict(enumerate(REGION_NAMES)),
                     show_scalar_bar=legend, scalar_bar_args=legend_bar, show_edges=True, edge_color=EDGE_COLOUR,
                     edge_opacity=EDGE_OPACITY, ambient=0.35, diffuse=0.75)


def cell_regions(tags, n_cells: int) -> np.ndarray:
    """Index into REGION_NAMES of every cell: passive, head, left or right muscle."""
    from aquarom_fenics.io.xdmf import cell_regions as regions_of_cells

    return regions_of_cells(tags, n_cells)


def tetra_grid(points: np.ndarray, cells: np.ndarray):
    """pyvista UnstructuredGrid of linear tetrahedra from (n_nodes, 3) points [m] and (n_cells, 4) cells."""
    pyvista = import_pyvista()
    cells = np.asarray(cells, dtype=np.int64)
    return pyvista.UnstructuredGrid({pyvista.CellType.TETRA: cells}, np.asarray(points, dtype=np.float64))


def _frame_camera(plotter, points: np.ndarray, size: tuple[int, int], top_space: float) -> None:
    """Parallel projection along VIEW_DIRECTION that frames ``points`` [m] in a ``size`` [px] view.

    ``top_space`` is the fraction of the view's height kept free above the fish for text.
    """
    towards_camera = VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)
    right = np.cross(-towards_camera, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -towards_camera)
    screen = points @ np.column_stack([right, up])
    low, high = screen.min(axis=0), screen.max(axis=0)
    half_width, half_height = (high - low) / 2 * (1 + FRAME_MARGIN)
    scale = max(half_height / (1 - top_space), half_width * size[1] / size[0])
    centre_right, centre_up = (low + high) / 2
    depth = points.mean(axis=0) @ towards_camera
    focal = depth * towards_camera + centre_right * right + (centre_up + scale * top_space) * up
    distance = 10 * np.ptp(points, axis=0).max()
    plotter.camera_position = [tuple(focal + distance * towards_camera), tuple(focal), tuple(up)]
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = scale
    plotter.renderer.reset_camera_clipping_range()


def import_pyvista():
    """pyvista, imported with Ctrl-C and SIGTERM held back until the import is complete: VTK's module
    loader turns an interrupt inside its imports into an ImportError (a traceback and exit 1 instead
    of the stop's one line); a stop asked for meanwhile is raised afterwards."""
    import sys

    if "pyvista" in sys.modules:
        return sys.modules["pyvista"]
    with stop_between_steps() as stop_requested:
        import pyvista
        stop = stop_requested()
    if stop is not None:
        raise stop_for(stop, "while the renderer was loading")
    return pyvista


def _plotter(shape: tuple[int, int], panel_size: tuple[int, int] = PANEL_SIZE):
    """Off-screen pyvista Plotter with ``shape`` (rows, columns) panels of ``panel_size`` pixels."""
    pyvista = import_pyvista()
    ensure_display()
    rows, columns = shape
    plotter = pyvista.Plotter(off_screen=True, shape=shape, border=False,
                              window_size=(columns * panel_size[0], rows * panel_size[1]))
    plotter.set_background("white")
    return plotter


def _save(plotter, path: Path) -> None:
    plotter.screenshot(str(path))
    plotter.close()
