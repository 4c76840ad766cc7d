"""The figure of a design sweep: the distance [cm] over the design space.

The parameters that vary across the sweep decide the view: one, a line of the distance over it;
two, a heat map (a filled grid when the designs form one, else coloured points); more, a scatter
matrix (a panel per pair of parameters, coloured by the distance, and the distance over each
parameter on the diagonal). Designs without a distance (refused, stopped, failed) are red crosses.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

DPI = 120
FAILED = dict(marker="x", color="tab:red", linestyle="none", label="no distance (refused, stopped, failed)")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def varying(rows: list[dict], names: list[str]) -> list[str]:
    """The parameters that take more than one value over the rows."""
    return [name for name in names if len({row[name] for row in rows}) > 1]


def _table(rows: list[dict], names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(designs × parameters) values and the distances [cm] (NaN without one)."""
    values = np.array([[row[name] for name in names] for row in rows], dtype=float).reshape(len(rows), len(names))
    distance = np.array([np.nan if row.get("distance_m") is None else 100 * row["distance_m"] for row in rows])
    return values, distance


def plot_sweep(rows: list[dict], names: list[str], path: Path, title: str) -> Path:
    """Write the sweep's figure to ``path`` (PNG)."""
    plt = _pyplot()
    axes_names = varying(rows, names) or names[:1]
    values, distance = _table(rows, axes_names)
    if len(axes_names) == 1:
        figure = _line(plt, values[:, 0], distance, axes_names[0])
    elif len(axes_names) == 2:
        figure = _heat_map(plt, values, distance, axes_names)
    else:
        figure = _scatter_matrix(plt, values, distance, axes_names)
    figure.suptitle(title)
    if not figure.get_constrained_layout():
        figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    plt.close(figure)
    return Path(path)


def _line(plt, x: np.ndarray, distance: np.ndarray, name: str):
    figure, axis = plt.subplots(figsize=(7, 4.5))
    order = np.argsort(x, kind="stable")
    ok = np.isfinite(distance[order])
    axis.plot(x[order][ok], distance[order][ok], "-o", color="tab:blue", label="completed")
    if not ok.all():
        floor = np.nanmin(distance) if ok.any() else 0.0
        axis.plot(x[order][~ok], np.full((~ok).sum(), floor), **FAILED)
    axis.set_xlabel(f"ξ {name}")
    axis.set_ylabel("distance [cm]")
    axis.grid(alpha=0.3)
    axis.legend(loc="best")
    return figure


def _is_grid(values: np.ndarray) -> bool:
    xs, ys = np.unique(values[:, 0]), np.unique(values[:, 1])
    pairs = {tuple(v) for v in values}
    return len(pairs) == len(values) == xs.size * ys.size


def _heat_map(plt, values: np.ndarray, distance: np.ndarray, names: list[str]):
    figure, axis = plt.subplots(figsize=(7, 5.5))
    ok = np.isfinite(distance)
    if _is_grid(values):
        xs, ys = np.unique(values[:, 0]), np.unique(values[:, 1])
        grid = np.full((ys.size, xs.size), np.nan)
        for (x, y), d in zip(values, distance):
            grid[np.searchsorted(ys, y), np.searchsorted(xs, x)] = d
        image = axis.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(grid), cmap="viridis", shading="flat")
    else:
        image = axis.scatter(values[ok, 0], values[ok, 1], c=distance[ok], cmap="viridis", s=60, edgecolors="k")
    figure.colorbar(image, ax=axis, label="distance [cm]")
    if not ok.all():
        axis.plot(values[~ok, 0], values[~ok, 1], **FAILED)
        axis.legend(loc="best")
    axis.set_xlabel(f"ξ {names[0]}")
    axis.set_ylabel(f"ξ {names[1]}")
    return figure


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres (half-way between them, half a spacing beyond the ends)."""
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])


def _scatter_matrix(plt, values: np.ndarray, distance: np.ndarray, names: list[str]):
    n = len(names)
    figure, axes = plt.subplots(n, n, figsize=(2.4 * n + 1.2, 2.4 * n), squeeze=False, constrained_layout=True)
    ok = np.isfinite(distance)
    limits = (np.nanmin(distance), np.nanmax(distance)) if ok.any() else (0.0, 1.0)
    image = None
    for i in range(n):
        for j in range(n):
            axis = axes[i, j]
            if i == j:       # the diagonal: distance over the parameter
                axis.plot(values[ok, j], distance[ok], "o", color="tab:blue", markersize=4)
                axis.set_title("distance [cm]", fontsize=8)
            else:
                image = axis.scatter(values[ok, j], values[ok, i], c=distance[ok], cmap="viridis", s=18,
                                     vmin=limits[0], vmax=limits[1])
                axis.plot(values[~ok, j], values[~ok, i], marker="x", color="tab:red", linestyle="none")
                axis.set_ylabel(f"ξ {names[i]}" if j == (1 if i == 0 else 0) else "")
            axis.set_xlabel(f"ξ {names[j]}" if i == n - 1 else "")
            axis.tick_params(labelsize=7)
    if image is not None:
        figure.colorbar(image, ax=axes.ravel().tolist(), label="distance [cm]", shrink=0.8)
    return figure
