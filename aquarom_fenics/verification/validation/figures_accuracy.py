"""Figures of the accuracy and cost studies (a, b, c): heat maps, cost against cells, run time against error."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from aquarom_fenics.verification.validation.report_format import (FIGURES, TOLERANCE_LIST, grid_and_legend,
                                                                   model_order, pyplot, saved)

def _grid(study: dict):
    levels, stiffnesses = study["levels"], study["stiffnesses"]
    rows = {(row["level"], row["stiffness"]): row for row in study["rows"]}
    return levels, stiffnesses, rows


def _amplitude_range(study, stiffness) -> str:
    values = [row["fom"].get("tail_amplitude") for row in study["rows"]
              if row["stiffness"] == stiffness and row["fom"].get("tail_amplitude")]
    if not values:
        return ""
    return f"\nA {100 * min(values):.1f}–{100 * max(values):.1f} cm"


def _stop_time(record: dict) -> str:
    """"\nat t = … s" from the solver's message (else the last converged sample)."""
    found = re.search(r"at t = ([-+0-9.eE]+) s", record.get("message") or "")
    if found:
        return f"\nat t = {float(found.group(1)):.3g} s"
    stop = record.get("stopped_at")
    return f"\nafter t = {stop:.3g} s" if stop is not None else ""


def heatmaps(study: dict, out: Path) -> list[Path]:
    """Distance error of each reduced model against the FOM over (cells, stiffness/tail amplitude)."""
    written = []
    for kind, key, scale, unit, file_key in (
            ("relative", "distance_error_relative", 100.0, "%", "heatmap_relative"),
            ("absolute", "distance_error_absolute", 1000.0, "mm", "heatmap_absolute")):
        written.append(_heatmap_figure(study, kind, key, scale, unit, out / FIGURES[file_key]))
    return written


def _heatmap_figure(study, kind, key, scale, unit, path) -> Path:
    from matplotlib.patches import Rectangle

    plt = pyplot()
    levels, stiffnesses, rows = _grid(study)
    models = model_order(study["models"])
    panels = models + ["fom"]
    columns = 3
    lines = math.ceil(len(panels) / columns)
    figure, axes = plt.subplots(lines, columns, figsize=(5.2 * columns, 1.0 + 0.75 * len(stiffnesses) * lines + 1.2 * lines),
                                squeeze=False)
    cells = study.get("cells", {})
    x_labels = [f"L{level}\n{cells.get(str(level), '?')} cells" for level in levels]
    y_labels = [f"k = {k / 1e3:g} kPa{_amplitude_range(study, k)}" for k in stiffnesses]
    errors = [abs(row["models"][m].get(key)) * scale for row in study["rows"] for m in models
              if row["models"].get(m, {}).get(key) is not None]
    limit = max(errors) if errors else 1.0
    limit = max(limit, 1e-12)
    for axis, panel in zip(axes.ravel(), panels):
        values = np.full((len(stiffnesses), len(levels)), np.nan)
        for j, k in enumerate(stiffnesses):
            for i, level in enumerate(levels):
                row = rows.get((level, k))
                if row is None:
                    continue
                if panel == "fom":
                    value = row["fom"].get("distance")
                    values[j, i] = np.nan if value is None else 100 * value
                else:
                    value = row["models"].get(panel, {}).get(key)
                    values[j, i] = np.nan if value is None else scale * value
        if panel == "fom":
            image = axis.imshow(np.ma.masked_invalid(values), origin="lower", cmap="viridis", aspect="auto")
            bar_label, title = "FOM distance [cm]", "FOM distance (the reference)"
        else:
            image = axis.imshow(np.ma.masked_invalid(values), origin="lower", cmap="RdBu_r", vmin=-limit,
                                vmax=limit, aspect="auto")
            bar_label = f"{'relative' if kind == 'relative' else 'absolute'} distance error [{unit}]"
            title = study["models"].get(panel, panel) + " − FOM"
        figure.colorbar(image, ax=axis, label=bar_label, fraction=0.05, pad=0.03)
        axis.set_facecolor("0.93")
        for j, k in enumerate(stiffnesses):
            for i, level in enumerate(levels):
                row = rows.get((level, k))
                if row is None:
                    axis.text(i, j, "not run", ha="center", va="center", fontsize=7, color="0.4")
                    continue
                fom = row["fom"]
                model = row["models"].get(panel, {}) if panel != "fom" else fom
                if fom.get("status") != "completed":
                    axis.add_patch(Rectangle((i - 0.5, j - 0.5), 1, 1, facecolor="0.8", edgecolor="black",
                                             hatch="///", linewidth=0.8))
                    axis.text(i, j, f"FOM {fom.get('status')}" + _stop_time(fom),
                              ha="center", va="center", fontsize=7, color="black",
                              bbox=dict(facecolor="white", alpha=0.8, linewidth=0))
                    continue
                if model.get("status") != "completed":
                    axis.add_patch(Rectangle((i - 0.5, j - 0.5), 1, 1, facecolor="0.85", edgecolor="black",
                                             hatch="xx", linewidth=0.8))
                    axis.text(i, j, f"model {model.get('status')}", ha="center", va="center", fontsize=7)
                    continue
                amplitude = fom.get("tail_amplitude")
                if panel == "fom":
                    text = f"{values[j, i]:.3g} cm\nA {100 * amplitude:.2f} cm"
                else:
                    text = f"{values[j, i]:+.{1 if kind == 'relative' else 2}f} {unit}\nA {100 * amplitude:.2f} cm"
                    relative = model.get("distance_error_relative")
                    if relative is not None and abs(relative) > TOLERANCE_LIST:
                        axis.add_patch(Rectangle((i - 0.5, j - 0.5), 1, 1, fill=False, edgecolor="black", linewidth=2.5))
                if panel == "fom":
                    low, high = np.nanmin(values), np.nanmax(values)
                    dark = high > low and (values[j, i] - low) / (high - low) < 0.5
                else:
                    dark = abs(values[j, i]) / limit > 0.6
                axis.text(i, j, text, ha="center", va="center", fontsize=7, color="white" if dark else "black")
        axis.set_xticks(range(len(levels)), x_labels, fontsize=7)
        axis.set_yticks(range(len(stiffnesses)), y_labels, fontsize=7)
        axis.set_xlabel("mesh level (cells)", fontsize=8)
        axis.set_ylabel("actuation stiffness (FOM tail amplitude)", fontsize=8)
        axis.set_title(title, fontsize=9)
    for axis in axes.ravel()[len(panels):]:
        axis.axis("off")
    figure.suptitle(f"Swimming distance error against the FOM ({kind}); cell text: error and FOM tail amplitude A; "
                    f"hatched: run stopped; thick frame: |relative error| > {100 * TOLERANCE_LIST:g}%", fontsize=10)
    return saved(figure, path)


MODEL_STYLES = {"FOM": ("black", "s"), "rom": ("tab:blue", "o"), "rom-paper": ("tab:cyan", "v"),
                "prom3": ("tab:orange", "^"), "prom5": ("tab:green", "D"), "prom8": ("tab:red", "P")}


def _fit_of(study, model, quantity):
    return next((f for f in study["fits"] if f["model"] == model and f["quantity"] == quantity), None)


def sorted_fits(study: dict) -> list[dict]:
    order = ["FOM"] + model_order({m: None for m in study["models"] if m != "FOM"})
    return sorted(study["fits"], key=lambda f: order.index(f["model"]) if f["model"] in order else len(order))


def _cost_series(axis, points, style, colour, marker, label):
    """Every timing as a small marker, the per-level median as a line."""
    cells = np.array([point[0] for point in points], dtype=float)
    times = np.array([point[1] for point in points], dtype=float)
    levels = np.unique(cells)
    medians = [np.median(times[cells == value]) for value in levels]
    axis.loglog(cells, times, linestyle="none", marker=marker, color=colour, markersize=3, alpha=0.45)
    axis.loglog(levels, medians, style, color=colour, marker=marker, label=label)


def cost_figure(study: dict, path: Path) -> Path:
    plt = pyplot()
    figure, axes = plt.subplots(1, 3, figsize=(16, 5))
    names = study["models"]
    horizon = study.get("settings", {}).get("duration")
    for axis, quantities, title in ((axes[0], ("build",), "build (FOM: set-up)"),
                                    (axes[1], ("solve", "solve with sensitivities"),
                                     f"solve ({horizon:g} s horizon)" if horizon else "solve")):
        for model in ["FOM"] + model_order({m: None for m in study["series"] if m != "FOM"}):
            series = study["series"].get(model, {})
            colour, marker = MODEL_STYLES.get(model, ("0.4", "x"))
            for quantity, style in zip(quantities, ("-", ":")):
                points = series.get(quantity)
                if not points:
                    continue
                fit = _fit_of(study, model, quantity)
                exponent = f" (exponent {fit['exponent']:.2f})" if fit and fit.get("exponent") is not None else ""
                label = names.get(model, model) + ("" if quantity in ("build", "solve") else ", with sensitivities")
                _cost_series(axis, points, style, colour, marker, label + exponent)
        axis.set_title(title)
    for model, style in (("prom8", "-"), ("rom", "--")):
        series = study["series"].get(model, {})
        for quantity, colour in (("build: basis", "tab:purple"), ("build: tensors", "tab:brown"),
                                 ("build: rest", "tab:gray")):
            points = series.get(quantity)
            if not points:
                continue
            fit = _fit_of(study, model, quantity)
            exponent = f" (exponent {fit['exponent']:.2f})" if fit and fit.get("exponent") is not None else ""
            _cost_series(axes[2], points, style, colour, "o",
                         f"{names.get(model, model)}: {quantity.split(': ')[1]}{exponent}")
    axes[2].set_title("build split: basis / tensors / rest")
    for axis in axes:
        axis.set_xlabel("cells")
        axis.set_ylabel("wall time [s]")
    grid_and_legend(axes, fontsize=7)
    figure.suptitle("Cost against mesh size (log-log; dots: every case, lines: per-level median; least-squares "
                    "exponents over all cases)")
    return saved(figure, path)


FAMILY_STYLES = {"FOM": ("black", "s"), "basis": ("tab:blue", "o"), "time step": ("tab:orange", "^"),
                 "Taylor order": ("tab:green", "D")}
FAMILY_LABELS = {"FOM": "FOM, time step h", "basis": "ROM basis variants (h = 0.02 s)",
                 "time step": "default ROM, time step h",
                 "Taylor order": "PROM p = 3, Taylor order (at ξ = radius, against the FOM there)"}


def pareto_points(study: dict) -> list[dict]:
    points = []
    for point in study["points"]:
        error = point.get("distance_error_relative")
        if point.get("status") == "completed" and error is not None and point.get("wall_time"):
            points.append(point | {"abs_error": max(abs(error), 1e-7)})
    return points


def pareto_front(points: list[dict]) -> list[dict]:
    """Points no other point beats in both wall time and error, among those at ξ = 0.

    The Taylor-order points are the PROM at another design against another FOM run: shown, but
    not part of the front.
    """
    front, best = [], math.inf
    candidates = [p for p in points if p["family"] != "Taylor order"]
    for point in sorted(candidates, key=lambda p: (p["wall_time"], p["abs_error"])):
        if point["abs_error"] < best:
            front.append(point)
            best = point["abs_error"]
    return front


def pareto_figure(study: dict, path: Path) -> Path:
    plt = pyplot()
    figure, axis = plt.subplots(figsize=(10, 7.5))
    points = pareto_points(study)
    for family, (colour, marker) in FAMILY_STYLES.items():
        members = [p for p in points if p["family"] == family]
        if members:
            axis.scatter([p["wall_time"] for p in members], [100 * p["abs_error"] for p in members], color=colour,
                         marker=marker, s=45, label=FAMILY_LABELS[family], zorder=3)
    for index, point in enumerate(sorted(points, key=lambda p: p["wall_time"])):
        axis.annotate(point.get("short") or point["label"], (point["wall_time"], 100 * point["abs_error"]),
                      fontsize=7, xytext=(5, 3 if index % 2 == 0 else -10), textcoords="offset points")
    front = pareto_front(points)
    if len(front) > 1:
        axis.step([p["wall_time"] for p in front], [100 * p["abs_error"] for p in front], where="post",
                  color="0.5", linestyle="--", label="Pareto front (ξ = 0 variants)", zorder=2)
    default = next((p for p in points if p.get("default")), None)
    if default:
        axis.scatter([default["wall_time"]], [100 * default["abs_error"]], marker="*", s=400, facecolor="none",
                     edgecolor="crimson", linewidth=1.8, label="default (ROM, h = 0.02 s)", zorder=4)
    for point in study["points"]:
        if point.get("status") != "completed":
            axis.annotate(f"{point['label']}: {point.get('status')}", (0.01, 0.02), xycoords="axes fraction",
                          fontsize=7, color="crimson")
    axis.set_xscale("log")
    axis.set_yscale("log")
    axis.margins(x=0.25, y=0.15)
    axis.set_xlabel("wall time [s] (reduced models: build + solve)")
    axis.set_ylabel(f"|distance error| against the FOM at h = {study['reference_time_step']} s [%]")
    axis.set_title(f"Run time against error, reference case (level {study['level']}, "
                   f"k = {study['stiffness'] / 1e3:g} kPa)")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, frameon=False)
    return saved(figure, path)
