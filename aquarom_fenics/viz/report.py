"""Figures of an optimization (SPEC §10): history, start against optimal fish, Pareto front.

Plain data in, PNG files out (matplotlib Agg, dpi 120). Distances are given in metres and drawn in
centimetres; design parameters ξ are dimensionless. Calling these on one rank only is the
caller's business.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from aquarom_fenics.viz import render

DPI = 120
"""Resolution [dots per inch] of every figure."""

PROM_MARKERS = {
    "built": dict(marker="o", markersize=7, color="tab:blue", label="new PROM built at the iterate"),
    "approximated": dict(marker="^", markersize=6, color="tab:orange", label="first-order estimate from the last PROM"),
    "surrogate": dict(marker="D", markersize=5, color="tab:green", label="last PROM simulated at the iterate"),
    "rejected": dict(marker="o", markersize=6, color="0.55", markerfacecolor="none", label="step rejected"),
}
"""Marker of an iteration by how its cost was obtained (the row's ``prom``)."""

PATH_COLOUR = "0.35"
BOUND_COLOUR = "black"
ACTIVE_COLOUR = "tab:red"
INFEASIBLE_COLOUR = "#f4c7c3"
START_MARKER = dict(marker="*", markersize=13, color="gold", markeredgecolor="black", linestyle="none",
                    label="start")

PARAMETER_PANEL_SIZE = (3.75, 2.25)
"""Width and height [inch] of one parameter's panel."""

MIN_FIGURE_WIDTH = 7.5
"""Width [inch] below which a figure of few panels widens them, so that its legend fits."""

LEGEND_HEIGHT = 0.5
"""Height [inch] kept free below the panels of a figure for its legend."""

VIEW_PANEL_SIZE = (720, 300)
"""Width and height [px] of one pyvista render of the start/optimal sheet."""

VIEW_FIGURE_WIDTH = 11.0
VIEW_FIGURE_FRAME = 1.6
"""Width [inch] of the start/optimal sheet, and the height [inch] of its title, labels and legend."""

VIEW_MARGIN = 0.08
"""Free border around the framed fish on every side, as a fraction of its largest extent."""

VIEWS = (
    ("from above", 1, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])),
    ("from the side", 2, np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])),
)
"""(label, index of the vertical screen axis, direction from the fish to the camera, up) per row.

Both views have x growing to the right: from above the camera looks down -z, from the side it
sits on the right flank (-y) like the design pictures of ``render``.
"""

AXIS_NAMES = "xyz"
OUTLINE_LABEL = "block outline (ξ = 0)"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_optimization_history(rows: list[dict], shape_names: list[str], bounds: list[tuple[float, float]],
                              out_dir: Path, active: list[str] = (), columns: list[str] | None = None) -> list[Path]:
    """Write cost.png (cost and distance [cm] per iteration) and parameters.png (ξ per iteration).

    Each row holds ``iteration``, ``xi_<name>`` for every shape name (or the row's column of each name in
    ``columns``, e.g. ``gait_frequency``), ``cost``, ``distance`` [m]
    and ``prom`` (one of PROM_MARKERS). ``bounds`` are the (lower, upper) box bounds of the
    parameters, in the order of ``shape_names``; ``active`` names the bounds active at the
    optimum (``"<name> = lower"`` / ``"<name> = upper"``), drawn solid and written in the panel
    title. Returns [cost.png, parameters.png].
    """
    if len(bounds) != len(shape_names):
        raise ValueError(f"{len(shape_names)} shape names but {len(bounds)} bounds")
    unknown = {row["prom"] for row in rows} - set(PROM_MARKERS)
    if unknown:
        raise ValueError(f"unknown prom value(s) {sorted(unknown)}; expected one of {list(PROM_MARKERS)}")
    rows = sorted(rows, key=lambda row: row["iteration"])
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cost_path, parameters_path = out_dir / "cost.png", out_dir / "parameters.png"
    _plot_cost_history(rows, cost_path)
    columns = columns or [f"xi_{name}" for name in shape_names]
    _plot_parameter_history(rows, list(zip(shape_names, columns)), bounds, parameters_path, set(active))
    return [cost_path, parameters_path]


def _plot_cost_history(rows: list[dict], path: Path) -> None:
    plt = _pyplot()
    figure, (cost_axis, distance_axis) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    _plot_iterates(cost_axis, rows, [row["cost"] for row in rows])
    _plot_iterates(distance_axis, rows, [100 * row["distance"] for row in rows])
    cost_axis.set_ylabel("cost L [m]")
    distance_axis.set_ylabel("distance d [cm]")
    distance_axis.set_xlabel("iteration")
    _integer_ticks(distance_axis)
    cost_axis.legend(loc="best", fontsize=8)
    cost_axis.set_title("optimization history")
    figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def _plot_parameter_history(rows: list[dict], named_columns: list[tuple[str, str]], bounds: list[tuple[float, float]],
                            path: Path, active: set[str]) -> None:
    plt = _pyplot()
    n_rows, n_columns = _grid_shape(len(named_columns))
    width, height = PARAMETER_PANEL_SIZE
    figure_height = n_rows * height + LEGEND_HEIGHT
    figure_width = max(MIN_FIGURE_WIDTH, n_columns * width)
    figure, axes = plt.subplots(n_rows, n_columns, figsize=(figure_width, figure_height), sharex=True, squeeze=False)
    for axis, (name, column), (lower, upper) in zip(axes.flat, named_columns, bounds):
        _plot_parameter_panel(axis, rows, name, lower, upper,
                              [side for side in ("lower", "upper") if f"{name} = {side}" in active], column)
    for axis in axes.flat[len(named_columns):]:
        axis.set_visible(False)
    for axis in _lowest_visible(axes):
        axis.set_xlabel("iteration")
        axis.xaxis.set_tick_params(labelbottom=True)
    _integer_ticks(axes.flat[0])
    handles, labels = axes.flat[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, frameon=False)
    figure.tight_layout(rect=(0, LEGEND_HEIGHT / figure_height, 1, 1))
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def _grid_shape(n_panels: int) -> tuple[int, int]:
    """(rows, columns) of a grid of ``n_panels``: one row up to 3 panels, 2 × 2 for 4, then three columns."""
    n_columns = 2 if n_panels == 4 else max(1, min(n_panels, 3))
    return max(1, math.ceil(n_panels / n_columns)), n_columns


def _lowest_visible(axes: np.ndarray) -> list:
    """The lowest visible panel of every column of a grid of axes."""
    return [next(axis for axis in column[::-1] if axis.get_visible()) for column in axes.T]


def _plot_parameter_panel(axis, rows: list[dict], name: str, lower: float, upper: float,
                          active_sides: list[str] = (), column: str | None = None) -> None:
    """Path of ξ_name (the rows' ``column``, ``xi_<name>`` unless given) over the iterations between its bounds,
    the outside shaded, the start starred, a bound active at the optimum drawn solid and named in the title."""
    column = column or f"xi_{name}"
    values = [row[column] for row in rows]
    low, high = min(lower, *values), max(upper, *values)
    pad = 0.12 * (high - low or 1.0)
    axis.axhspan(low - pad, lower, color=INFEASIBLE_COLOUR, label="outside the bounds")
    axis.axhspan(upper, high + pad, color=INFEASIBLE_COLOUR)
    axis.axhline(lower, color=BOUND_COLOUR, linewidth=1, linestyle="--", label="bounds")
    axis.axhline(upper, color=BOUND_COLOUR, linewidth=1, linestyle="--")
    _plot_iterates(axis, rows, values)
    axis.plot([rows[0]["iteration"]], [values[0]], zorder=4, **START_MARKER)
    for side in active_sides:
        axis.axhline(lower if side == "lower" else upper, color=ACTIVE_COLOUR, linewidth=2.5,
                     label="active at the optimum")
    axis.set_ylim(low - pad, high + pad)
    axis.set_title(f"{'g' if column.startswith('gait_') else 'ξ'}  {name}" + "".join(f"  ({side} bound active)" for side in active_sides), fontsize=10)


def _plot_iterates(axis, rows: list[dict], values: list[float]) -> None:
    """Accepted iterates joined by a line, each marked by how its cost was obtained."""
    iterations = np.array([row["iteration"] for row in rows])
    values = np.asarray(values, dtype=float)
    kinds = np.array([row["prom"] for row in rows])
    accepted = kinds != "rejected"
    axis.plot(iterations[accepted], values[accepted], color=PATH_COLOUR, linewidth=1.2, zorder=2)
    for kind, style in PROM_MARKERS.items():
        chosen = kinds == kind
        if chosen.any():
            axis.plot(iterations[chosen], values[chosen], linestyle="none", zorder=3, **style)
    axis.grid(alpha=0.3)


def _integer_ticks(axis) -> None:
    from matplotlib.ticker import MaxNLocator

    axis.xaxis.set_major_locator(MaxNLocator(integer=True))


def render_start_and_optimal(fish, start_points: np.ndarray, optimal_points: np.ndarray, out_path: Path,
                               title: str) -> Path:
    """Write one PNG: start | optimal fish seen from above (y along x) and from the side (z along x).

    ``start_points`` and ``optimal_points`` are nodal positions [m] on ``fish.mesh.cells``. All
    four renders share one parallel projection scale, so lengths compare across panels; the axes
    are in centimetres and the optimal panels show the outline of the block (ξ = 0) in grey.
    """
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    framed = np.vstack([start_points, optimal_points])
    low, high = _framed_box(framed)
    scale = _parallel_scale(low, high, VIEW_PANEL_SIZE)
    designs = (("start", start_points, False), ("optimal", optimal_points, True))
    images = _render_views(fish, designs, low, high, scale)
    _compose_views(images, [name for name, _, _ in designs], low, high, scale, out_path, title)
    return out_path


def _framed_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners [m] of the bounding box of ``points`` widened by VIEW_MARGIN."""
    low, high = points.min(axis=0), points.max(axis=0)
    margin = VIEW_MARGIN * (high - low).max()
    return low - margin, high + margin


def _parallel_scale(low: np.ndarray, high: np.ndarray, panel_size: tuple[int, int]) -> float:
    """Half the visible height [m] of a panel of ``panel_size`` [px] that shows the box in every view."""
    width, height = panel_size
    half = (high - low) / 2
    return float(max(half[0] * height / width, *(half[vertical] for _, vertical, _, _ in VIEWS)))


def _render_views(fish, designs, low: np.ndarray, high: np.ndarray, scale: float) -> np.ndarray:
    """(rows, columns, height, width, 3) RGB renders: one row per view, one column per design."""
    plotter = render._plotter((len(VIEWS), len(designs)), VIEW_PANEL_SIZE)
    centre = (low + high) / 2
    for row, (_, _, towards_camera, up) in enumerate(VIEWS):
        for column, (_, points, with_outline) in enumerate(designs):
            plotter.subplot(row, column)
            if with_outline:
                render._add_nominal_outline(plotter, fish)
            render._add_design(plotter, fish, points)
            _look_at(plotter, centre, towards_camera, up, scale, distance=10 * (high - low).max())
    picture = plotter.screenshot(return_img=True)[..., :3]
    plotter.close()
    width, height = VIEW_PANEL_SIZE
    return picture.reshape(len(VIEWS), height, len(designs), width, 3).transpose(0, 2, 1, 3, 4)


def _look_at(plotter, centre: np.ndarray, towards_camera: np.ndarray, up: np.ndarray, scale: float,
             distance: float) -> None:
    """Parallel projection of half-height ``scale`` [m] centred on ``centre`` [m] from ``towards_camera``."""
    plotter.camera_position = [tuple(centre + distance * towards_camera), tuple(centre), tuple(up)]
    plotter.camera.parallel_projection = True
    plotter.camera.parallel_scale = scale
    plotter.renderer.reset_camera_clipping_range()


def _compose_views(images: np.ndarray, design_names: list[str], low: np.ndarray, high: np.ndarray, scale: float,
                   path: Path, title: str) -> None:
    """Lay the renders out on centimetre axes cropped to the framed box, with a legend of the regions."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    plt = _pyplot()
    centre = (low + high) / 2
    axes_width = 0.85 * VIEW_FIGURE_WIDTH / len(design_names)
    axes_heights = [axes_width * (high[vertical] - low[vertical]) / (high[0] - low[0]) for _, vertical, _, _ in VIEWS]
    figure_height = sum(axes_heights) + VIEW_FIGURE_FRAME
    figure, axes = plt.subplots(len(VIEWS), len(design_names), figsize=(VIEW_FIGURE_WIDTH, figure_height),
                                sharex=True, sharey="row", squeeze=False, gridspec_kw=dict(height_ratios=axes_heights))
    width, height = VIEW_PANEL_SIZE
    half_width = scale * width / height
    for row, (view_name, vertical, _, _) in enumerate(VIEWS):
        extent = 100 * np.array([centre[0] - half_width, centre[0] + half_width,
                                 centre[vertical] - scale, centre[vertical] + scale])
        for column, design_name in enumerate(design_names):
            axis = axes[row, column]
            axis.imshow(images[row, column], extent=extent, interpolation="antialiased")
            axis.set_xlim(100 * low[0], 100 * high[0])
            axis.set_ylim(100 * low[vertical], 100 * high[vertical])
            axis.set_title(f"{design_name}, {view_name}", fontsize=10)
        axes[row, 0].set_ylabel(f"{AXIS_NAMES[vertical]} [cm]")
    for axis in axes[-1]:
        axis.set_xlabel("x [cm]")
    handles = [Patch(facecolor=colour, edgecolor=render.EDGE_COLOUR, label=name)
               for name, colour in zip(render.REGION_NAMES, render.REGION_COLOURS)]
    handles.append(Line2D([], [], color=render.NOMINAL_OUTLINE_COLOUR, linewidth=1.5, label=OUTLINE_LABEL))
    figure.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    figure.suptitle(title)
    figure.tight_layout(rect=(0, LEGEND_HEIGHT / figure_height, 1, 1), h_pad=2.5)
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def plot_pareto(points: list[dict], out_path: Path) -> Path:
    """Write the distance [cm] against the energy term α A² of co-optimized designs, front joined.

    Each point holds ``w1`` (weight of -d), ``distance_m`` [m], ``energy`` (α A², the cost's units)
    and ``amplitude`` A. A design is on the front when no other one swims as far or farther for
    as little energy or less (and is better in one of the two). A point without a FOM distance
    (its FOM check stopped: NaN) is drawn as a cross at its ``prom_distance_m``, off the front; a
    point whose optimiser did not reach a first-order point (``converged`` false) as a grey
    square, off the front too.
    """
    plt = _pyplot()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    energy = np.array([point["energy"] for point in points], dtype=float)
    distance = 100 * np.array([point["distance_m"] for point in points], dtype=float)
    feasible = np.isfinite(distance)
    converged = np.array([_true(point.get("converged", True)) for point in points], dtype=bool)
    candidates = feasible & converged
    on_front = np.zeros(len(points), dtype=bool)
    on_front[candidates] = _non_dominated(energy[candidates], distance[candidates])
    order = np.argsort(energy)
    front = order[on_front[order]]
    figure, axis = plt.subplots(figsize=(7, 5))
    axis.plot(energy[front], distance[front], "-o", color="tab:blue", label="non-dominated front", zorder=3)
    dominated = candidates & ~on_front
    axis.plot(energy[dominated], distance[dominated], "o", color="0.55", markerfacecolor="none",
              label="dominated", zorder=3)
    stalled = feasible & ~converged
    if stalled.any():
        axis.plot(energy[stalled], distance[stalled], "s", color="0.4", markerfacecolor="none", zorder=3,
                  label="not converged (no first-order point): off the front")
    if not feasible.all():
        distance[~feasible] = [100 * point.get("prom_distance_m", np.nan) for point, ok in zip(points, feasible) if not ok]
        axis.plot(energy[~feasible], distance[~feasible], "x", color="tab:red", zorder=3,
                  label="infeasible: FOM check stops (PROM distance)")
    for x, y, label in _pareto_labels(points, energy, distance):
        axis.annotate(label, (x, y), xytext=(7, -3), textcoords="offset points", va="top", fontsize=8)
    axis.margins(x=0.15, y=0.1)
    axis.set_xlabel("energy term α A²")
    axis.set_ylabel("distance d [cm]")
    axis.set_title("co-optimization: distance against actuation energy")
    axis.grid(alpha=0.3)
    axis.legend(loc="lower right", fontsize=8)      # a front rises to the right: that corner stays empty
    figure.tight_layout()
    figure.savefig(out_path, dpi=DPI)
    plt.close(figure)
    return out_path


def plot_budget_front(points: list[dict], out_path: Path) -> Path:
    """The front traced by budgets: left, the distance [cm] against the budget A_k, from the PROM
    (dashed) and the FOM (solid) at each optimum, the FOM front through the converged points only
    (a point not converged: grey square; a FOM run that stopped: red cross at the PROM distance);
    right, the optimal shape parameters ξ (``xi_<name>``) along the front.

    Each point holds ``budget``, ``amplitude``, ``distance_m`` (FOM, NaN when it stopped),
    ``prom_distance_m`` and ``converged``."""
    plt = _pyplot()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    budget = np.array([float(point["budget"]) for point in points])
    fom = 100 * np.array([float(point["distance_m"]) for point in points])
    prom = 100 * np.array([float(point["prom_distance_m"]) for point in points])
    converged = np.array([_true(point.get("converged", True)) for point in points], dtype=bool)
    checked = np.isfinite(fom)
    figure, (front, shapes) = plt.subplots(1, 2, figsize=(11, 4.5))
    front.plot(budget[converged], prom[converged], "--^", color="tab:orange", label="PROM at the optimum")
    on_front = converged & checked
    front.plot(budget[on_front], fom[on_front], "-o", color="tab:blue", label="FOM at the optimum (the front)")
    if (checked & ~converged).any():
        front.plot(budget[checked & ~converged], fom[checked & ~converged], "s", color="0.4", markerfacecolor="none",
                   label="not converged: off the front")
    if (~checked).any():
        front.plot(budget[~checked], prom[~checked], "x", color="tab:red", label="FOM run stopped (PROM distance)")
    front.set_xlabel("budget: amplitude A ≤ A_k")
    front.set_ylabel("distance d [cm]")
    front.set_title("max d subject to A ≤ A_k")
    front.grid(alpha=0.3)
    front.legend(loc="upper left", fontsize=8)
    names = [key for key in points[0] if key.startswith("xi_")]
    for name in names:
        shapes.plot(budget, [float(point[name]) for point in points], "-o", markersize=4, label=name[3:])
    shapes.set_xlabel("budget: amplitude A ≤ A_k")
    shapes.set_ylabel("shape parameter ξ at the optimum")
    shapes.set_title("optimal shapes along the front")
    shapes.grid(alpha=0.3)
    if names:
        shapes.legend(loc="best", fontsize=8)
    figure.tight_layout()
    figure.savefig(out_path, dpi=DPI)
    plt.close(figure)
    return out_path


def _true(value) -> bool:
    """A CSV or JSON truth value: True, "True", "true" are true."""
    return value is True or str(value).strip().lower() == "true"


def _pareto_labels(points, energy: np.ndarray, distance: np.ndarray, resolution: float = 0.02):
    """(x, y, "w₁ …, A …") per group of points with the same amplitude (3 digits) that lie within
    ``resolution`` of the plotted ranges of the group's first point: one label for the weights
    that end at one design."""
    finite = np.isfinite(distance)
    spans = np.array([max(float(np.ptp(values[finite])), 1e-12) if finite.any() else 1.0
                      for values in (energy, distance)])
    groups = []                                     # [x, y, amplitude, weights]
    for point, x, y in zip(points, energy, distance):
        amplitude = f"{point['amplitude']:.3g}"
        near = [group for group in groups if group[2] == amplitude and np.isfinite(y)
                and np.all(np.abs(np.array([x - group[0], y - group[1]])) <= resolution * spans)]
        if near:
            near[0][3].append(f"{point['w1']:g}")
        else:
            groups.append([x, y, amplitude, [f"{point['w1']:g}"]])
    return [(x, y, f"w₁ {', '.join(weights)}, A {amplitude}") for x, y, amplitude, weights in groups]


def _non_dominated(energy: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """Mask of the points no other point beats: energy ≤ and distance ≥, one of them strictly."""
    no_worse = (energy[None, :] <= energy[:, None]) & (distance[None, :] >= distance[:, None])
    better = (energy[None, :] < energy[:, None]) | (distance[None, :] > distance[:, None])
    return ~(no_worse & better).any(axis=1)
