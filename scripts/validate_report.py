"""Figures and results/REPORT.md of `make validate`, from the study files <out>/<study>.json.

Plain JSON in, PNG and Markdown out: no FEniCS import, so that the report can be rewritten
(``validate.py --report-only``) and tested without running a model. A study that has not been run
yet appears as such; every figure and table comes with one sentence saying what it shows,
computed from the numbers.
"""
from __future__ import annotations

import json
import math
import os
import re
import time
from pathlib import Path

import numpy as np

DPI = 120
TOLERANCE_REFERENCE = 0.05     # default ROM at the reference case: |distance error| within 5%
TOLERANCE_LIST = 0.10          # cases listed above 10%
RATIO_RANGE = (3.0, 5.0)       # successive-difference ratio of head x
SOLVE_EXPONENT_MAX = 0.1
BUILD_EXPONENT_MAX = 1.2
RUN_LIMITS = {"from empty": 3600.0, "all cached": 60.0}

FIGURES = {
    "heatmap_relative": "heatmap_distance_relative.png",
    "heatmap_absolute": "heatmap_distance_absolute.png",
    "cost": "cost_vs_cells.png",
    "pareto": "pareto_time_error.png",
    "convergence": "timestep_convergence.png",
    "energy": "stress_energy.png",
    "mesh": "mesh_convergence.png",
}
REDUCED_MODELS = ("rom", "rom-paper", "prom3", "prom5", "prom8")


def model_order(models: dict) -> list[str]:
    """Model ids in the order ROM, ROM (source's basis), PROM p = 3, 5, 8, then any other."""
    return [m for m in REDUCED_MODELS if m in models] + sorted(m for m in models if m not in REDUCED_MODELS)


def load_studies(out: Path) -> dict:
    studies = {}
    for name in ("a", "b", "c", "d", "e", "stress", "mesh_convergence", "run"):
        path = Path(out) / f"{name}.json"
        if path.exists():
            studies[name] = json.loads(path.read_text())
    history = Path(out) / "run_history.json"
    if history.exists():
        studies["history"] = json.loads(history.read_text())
    return studies


# ---------------------------------------------------------------------------------------------
# Formatting


def fmt(value, spec: str = ".3g", scale: float = 1.0, signed: bool = False) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    value = value * scale
    return f"{value:+{spec}}" if signed else f"{value:{spec}}"


def percent(value, digits: int = 2) -> str:
    return fmt(value, f".{digits}f", 100.0, signed=True) + ("%" if value is not None else "")


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(cell).replace("|", "/") for cell in row) + " |" for row in rows]
    return lines


def short(message: str | None, length: int = 110) -> str:
    if not message:
        return ""
    message = " ".join(str(message).split())
    return message if len(message) <= length else message[: length - 1] + "…"


# ---------------------------------------------------------------------------------------------
# Figures


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _saved(figure, path: Path, rect=(0, 0, 1, 1)) -> Path:
    """Lay out ``figure`` within ``rect``, write it to ``path`` at DPI and close it."""
    figure.tight_layout(rect=rect)
    figure.savefig(path, dpi=DPI)
    _pyplot().close(figure)
    return path


def _grid_and_legend(axes, fontsize: int) -> None:
    """Major and minor grid on every axis, and a legend where something is labelled."""
    for axis in axes:
        axis.grid(alpha=0.3, which="both")
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=fontsize)


def make_figures(out: Path) -> list[Path]:
    """Every figure whose study file exists; returns the files written."""
    out = Path(out)
    studies = load_studies(out)
    written = []
    if "a" in studies:
        written += heatmaps(studies["a"], out)
    if "b" in studies:
        written += [cost_figure(studies["b"], out / FIGURES["cost"])]
    if "c" in studies:
        written += [pareto_figure(studies["c"], out / FIGURES["pareto"])]
    if "d" in studies:
        written += [convergence_figure(studies["d"], out / FIGURES["convergence"])]
    if "stress" in studies:
        figure = energy_figure(studies["stress"], out / FIGURES["energy"])
        written += [figure] if figure else []
    if studies.get("mesh_convergence", {}).get("rows"):
        written += [mesh_figure(studies["mesh_convergence"], out / FIGURES["mesh"])]
    return written


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

    plt = _pyplot()
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
    return _saved(figure, path)


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
    plt = _pyplot()
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
    _grid_and_legend(axes, fontsize=7)
    figure.suptitle("Cost against mesh size (log-log; dots: every case, lines: per-level median; least-squares "
                    "exponents over all cases)")
    return _saved(figure, path)


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
    plt = _pyplot()
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
    return _saved(figure, path)


def convergence_figure(study: dict, path: Path) -> Path:
    plt = _pyplot()
    figure, axes = plt.subplots(1, 2, figsize=(14, 6))
    for quantity in study["quantities"]:
        if "difference_series" not in quantity:
            continue
        axis = axes[1] if "ξ" in quantity["name"] else axes[0]
        colour = None
        for pair, series, style in zip(quantity["pairs"], quantity["difference_series"], ("-", "--", ":")):
            values = np.asarray(series, dtype=float)
            values = np.where(values > 0, values, np.nan)     # t = 0: identical initial state
            line, = axis.semilogy(quantity["time"], values, style, color=colour, linewidth=1,
                                  label=f"{quantity['name']}, h = {pair} s")
            colour = line.get_color()
    axes[0].set_ylabel("|head x(h) − head x(h/2)| [m]")
    axes[1].set_ylabel("|S(h) − S(h/2)| of head x [m per unit ξ]")
    axes[0].set_title("head x: successive differences")
    axes[1].set_title("sensitivities d head x / d ξ: successive differences")
    for axis in axes:
        axis.set_xlabel("time [s]")
    _grid_and_legend(axes, fontsize=6)
    figure.suptitle("Time-step convergence (second order: each halving of h divides the difference by ≈ 4; "
                    "α_N > 0 tends to first order, ≈ 2)")
    return _saved(figure, path)


MESH_QUANTITIES = (("distance", "swimming distance"), ("static_tail_deflection", "static tail deflection"),
                   ("first_frequency", "first frequency"), ("tail_amplitude", "tail amplitude"))


def mesh_figure(study: dict, path: Path) -> Path:
    """FOM wall time against the relative error of each quantity, one line per element degree."""
    plt = _pyplot()
    figure, axes = plt.subplots(1, len(MESH_QUANTITIES), figsize=(18, 5), sharey=True)
    for axis, (name, label) in zip(axes, MESH_QUANTITIES):
        for degree, marker in ((1, "o"), (2, "s")):
            # The case that is its own reference (an oscillating series) has no error to draw.
            rows = [row for row in study["rows"] if row["degree"] == degree and row[f"{name}_error"] != 0.0]
            if not rows:
                continue
            errors = [abs(row[f"{name}_error"]) for row in rows]
            axis.loglog(errors, [row["wall_time"] for row in rows], marker=marker, label=f"degree {degree}")
            for row, error in zip(rows, errors):
                axis.annotate(f"L{row['level']}", (error, row["wall_time"]), fontsize=7)
        axis.axvline(0.03, color="grey", linestyle=":", linewidth=1)
        axis.set_xlabel(f"|relative error| of the {label}")
        axis.set_title(label)
    axes[0].set_ylabel("FOM wall time [s]")
    _grid_and_legend(axes, fontsize=8)
    figure.suptitle("Mesh convergence: FOM cost against error w.r.t. the Richardson reference (dotted: 3 %)")
    return _saved(figure, path)


def energy_figure(study: dict, path: Path) -> Path | None:
    rows = [row for row in study["rows"] if row.get("energy")]
    if not rows:
        return None
    plt = _pyplot()
    columns = min(4, len(rows))
    lines = math.ceil(len(rows) / columns)
    figure, axes = plt.subplots(lines, columns, figsize=(4.2 * columns, 3.3 * lines), squeeze=False)
    for axis, row in zip(axes.ravel(), rows):
        series = {key: 1e3 * np.asarray(value) for key, value in row["energy"]["series"].items()}
        time_values = series["time"] / 1e3
        midpoint = series.get("dissipated_midpoint", series["dissipated"])
        axis.plot(time_values, series["work"], label="work in (actuation + thrust + drag)")
        axis.plot(time_values, midpoint, "--", label="dissipated (D_mid)")
        axis.plot(time_values, series["stored"], ":", label="stored (kinetic + elastic)")
        right = axis.twinx()
        right.plot(time_values, series["work"] - series["dissipated"] - series["stored"], color="crimson",
                   linewidth=0.9, linestyle="--", label="imbalance with D")
        right.plot(time_values, series["work"] - midpoint - series["stored"], color="crimson", linewidth=1.2,
                   label="imbalance with D_mid")
        right.set_ylabel("imbalance [mJ]", color="crimson", fontsize=8)
        right.tick_params(axis="y", colors="crimson", labelsize=7)
        if row is rows[0]:
            handles = axis.get_legend_handles_labels()
            extra = right.get_legend_handles_labels()
            figure.legend(handles[0] + extra[0], handles[1] + extra[1], fontsize=8, loc="lower center", ncol=5,
                          frameon=False)
        energy = row["energy"]
        axis.set_title(f"{row['id']}: {row['status']}; imbalance {percent(energy['imbalance_relative'], 2)} "
                       f"(with D_mid {percent(energy.get('imbalance_midpoint_relative'), 3)})", fontsize=8)
        axis.set_xlabel("time [s]")
        axis.set_ylabel("energy [mJ]")
        axis.grid(alpha=0.3)
    for axis in axes.ravel()[len(rows):]:
        axis.axis("off")
    figure.suptitle("Energy balance of the FOM stress cases (imbalance relative to the energy throughput)")
    return _saved(figure, path, rect=(0, 0.06, 1, 1))


# ---------------------------------------------------------------------------------------------
# Checks


def reference_row(study_a: dict) -> dict | None:
    return next((row for row in study_a["rows"] if row["level"] == study_a["reference_level"]
                 and row["stiffness"] == study_a["reference_stiffness"]), None)


def cases_above(study_a: dict, tolerance: float = TOLERANCE_LIST) -> list[dict]:
    listed = []
    for row in study_a["rows"]:
        for model, values in row["models"].items():
            error = values.get("distance_error_relative")
            if error is not None and abs(error) > tolerance:
                listed.append({"model": study_a["models"].get(model, model), "level": row["level"],
                               "cells": row["cells"], "stiffness": row["stiffness"],
                               "tail_amplitude": row["fom"].get("tail_amplitude"), "error": error,
                               "tail_amplitude_error": values.get("tail_amplitude_error_relative")})
    return listed


def checks(studies: dict, out: Path) -> list[list[str]]:
    """The issue's "must show" items: [check, measured, required, verdict]."""
    rows = []

    def verdict(ok):
        return "—" if ok is None else ("pass" if ok else "**FAIL**")

    present = all((out / FIGURES[name]).exists() for name in ("heatmap_relative", "heatmap_absolute", "pareto"))
    rows.append(["heat maps and Pareto plot written", "yes" if present else "missing", "exist", verdict(present)])
    a = studies.get("a")
    row = reference_row(a) if a else None
    if row:
        rom, paper = row["models"].get("rom", {}), row["models"].get("rom-paper", {})
        error = rom.get("distance_error_relative")
        ok = None if error is None else abs(error) <= TOLERANCE_REFERENCE
        rows.append([f"default ROM distance error, {row['cells']} cells, k = {row['stiffness'] / 1e3:g} kPa",
                     f"{percent(error)} (source's basis: {percent(paper.get('distance_error_relative'))})",
                     f"within ±{100 * TOLERANCE_REFERENCE:g}%", verdict(ok)])
        listed = cases_above(a)
        rows.append([f"cases above ±{100 * TOLERANCE_LIST:g}% (all models)", str(len(listed)), "listed in §a", "—"])
    else:
        rows.append(["default ROM distance error at the reference case", "not run", f"within ±{100 * TOLERANCE_REFERENCE:g}%", "—"])
    d = studies.get("d")
    if d:
        for quantity in d["quantities"]:
            if "head x," not in quantity["name"]:
                continue
            second_order = quantity.get("second_order", quantity.get("newmark_alpha", 0.0) == 0.0)
            required = f"{RATIO_RANGE[0]:g}–{RATIO_RANGE[1]:g}" if second_order else "→ 2 (first order: γ = ½ + α_N)"
            if quantity.get("ratio") is None:
                rows.append([f"time-step ratio, {quantity['name']}", quantity.get("status", "—"), required,
                             verdict(False) if second_order else "—"])
                continue
            ok = RATIO_RANGE[0] <= quantity["ratio"] <= RATIO_RANGE[1]
            rows.append([f"time-step ratio, {quantity['name']}", fmt(quantity["ratio"], ".2f"), required,
                         verdict(ok) if second_order else "—"])
    b = studies.get("b")
    if b:
        for fit in sorted_fits(b):
            if fit["model"] == "FOM" or fit["quantity"] not in ("solve", "build"):
                continue
            limit = SOLVE_EXPONENT_MAX if fit["quantity"] == "solve" else BUILD_EXPONENT_MAX
            exponent = fit.get("exponent")
            ok = None if exponent is None else (exponent < limit if fit["quantity"] == "solve" else exponent <= limit)
            rows.append([f"{b['models'].get(fit['model'], fit['model'])} {fit['quantity']} time ∝ cells^e",
                         fmt(exponent, ".3f"), ("< " if fit["quantity"] == "solve" else "≤ ") + f"{limit:g}",
                         verdict(ok)])
    for run in (studies.get("history") or [])[-3:]:
        if run.get("quick"):
            continue
        kind = "all cached" if run["cases"].get("computed", 0) == 0 else "from empty" if run.get("from_empty") else None
        limit = RUN_LIMITS.get(kind)
        rows.append([f"`make validate` run of {run['date']} ({run['cases'].get('computed', 0)} computed, "
                     f"{run['cases'].get('cached', 0)} cached, {run.get('cores')} cores)",
                     f"{run['wall_time'] / 60:.1f} min", f"≤ {limit / 60:g} min ({kind})" if limit else
                     "(partial rerun)", verdict(run["wall_time"] <= limit) if limit else "—"])
    return rows


# ---------------------------------------------------------------------------------------------
# Report


def _link(path: Path, report: Path) -> str:
    return Path(os.path.relpath(path, report.parent)).as_posix()


def _figure(lines, out, report, key, caption, sentence):
    path = out / FIGURES[key]
    if path.exists():
        lines += [f"![{caption}]({_link(path, report)})", "", f"*{caption}.* {sentence}", ""]
    else:
        lines += [f"*{caption}: not drawn yet.*", ""]


def write_report(out: Path, report: Path, studies_summary: Path | None = None) -> Path:
    """REPORT.md from the study files in ``out`` (and the optimisation summary when present)."""
    out, report = Path(out), Path(report)
    studies = load_studies(out)
    run = studies.get("run", {})
    lines = ["# Validation report", "",
             f"Generated {time.strftime('%Y-%m-%d %H:%M:%S')} from `{_link(out, report)}/` by "
             "`scripts/validate.py` (`make validate`)."]
    if run:
        machine = run.get("machine", {})
        versions = ", ".join(f"{name} {value}" for name, value in run.get("versions", {}).items())
        lines += ["", f"- Last run: {run.get('date')}, {run.get('wall_time', 0) / 60:.1f} min, cases "
                  + ", ".join(f"{n} {what}" for what, n in run.get("cases", {}).items())
                  + f"; studies {', '.join(run.get('studies', []))}" + (" (**quick mode**)" if run.get("quick") else ""),
                  f"- Machine: {machine.get('cores')} cores, {machine.get('cpu')}, "
                  f"{fmt(machine.get('memory_gib'), '.1f')} GiB, {machine.get('platform')}",
                  f"- Versions: {versions}"]
    lines += ["", "## Checks", "",
              "The acceptance items of the validation issue, computed from the results below."
              + (" Quick mode: levels 1–2 and a 0.4 s horizon, so the exponent fits rest on two levels and on solves "
                 "of a few hundredths of a second; they are smoke tests, not measurements." if run.get("quick") else ""),
              ""]
    lines += table(["check", "measured", "required", "verdict"], checks(studies, out))
    lines += [""]
    _section_a(lines, studies.get("a"), out, report)
    _section_b(lines, studies.get("b"), out, report)
    _section_c(lines, studies.get("c"), out, report)
    _section_d(lines, studies.get("d"), out, report)
    _section_e(lines, studies.get("e"))
    _section_stress(lines, studies.get("stress"), out, report)
    _section_mesh(lines, studies.get("mesh_convergence"), out, report)
    _section_validity(lines, out / "prom_validity.md", report)
    _section_optimisation(lines, studies_summary or report.parent / "studies" / "summary.md", report)
    lines += ["## Reproduce", "", "    make validate                                   # every study, cached per case",
              "    .venv/bin/python scripts/validate.py --quick    # smoke run: levels 1–2, 0.4 s horizon",
              "    .venv/bin/python scripts/validate.py --only c,d # selected studies",
              "    .venv/bin/python scripts/validate.py --report-only", "",
              f"Cases are cached in `{_link(out / 'cases', report)}/` (one JSON file per case, keyed by the scene "
              "hash, the model settings and the toolkit version); delete a file to recompute that case.", ""]
    report.parent.mkdir(parents=True, exist_ok=True)
    temporary = report.with_name(f".{report.name}.tmp")
    temporary.write_text("\n".join(lines))
    temporary.replace(report)
    return report


def _not_run(lines, title):
    lines += [title, "", "*Not run yet* (`scripts/validate.py --only ...`).", ""]


def _section_a(lines, study, out, report):
    title = "## a. FOM against ROM and PROM over mesh levels and actuation stiffnesses"
    if not study:
        return _not_run(lines, title)
    labels = study["models"]
    models = {m: labels[m] for m in model_order(labels)}
    rows = study["rows"]
    completed = [row for row in rows if row["fom"].get("status") == "completed"]
    failed = [row for row in rows if row["fom"].get("status") != "completed"]
    amplitudes = [row["fom"]["tail_amplitude"] for row in completed]
    lines += [title, "",
              f"{len(rows)} cases: levels {', '.join(map(str, study['levels']))} × k = "
              f"{', '.join(f'{k / 1e3:g}' for k in study['stiffnesses'])} kPa, horizon {study['duration']:g} s; "
              f"FOM tail amplitudes {fmt(min(amplitudes, default=None), '.2f', 100)}–"
              f"{fmt(max(amplitudes, default=None), '.2f', 100)} cm; {len(failed)} FOM run(s) stopped. "
              "Reduced models are built at ξ = 0 of the nominal fish (PROM p = 3, 5, 8: the shape sets of SO1, SO2, "
              "SO3) and compared with the FOM at ξ = 0; errors are model − FOM.", ""]
    for key, caption, kind in (("heatmap_relative", "Relative distance error heat maps", "relative"),
                               ("heatmap_absolute", "Absolute distance error heat maps", "absolute")):
        errors = [(abs(row["models"][m]["distance_error_relative"]), models[m], row) for row in rows for m in row["models"]
                  if row["models"][m].get("distance_error_relative") is not None]
        worst = max(errors, key=lambda e: e[0], default=None)
        sentence = (f"Each panel shows one reduced model's {kind} distance error over mesh level (columns) and actuation "
                    "stiffness (rows, with the FOM tail-amplitude range); hatched cells are FOM runs that stopped. ")
        if worst and kind == "relative":
            sentence += (f"The largest relative error is {100 * worst[0]:.1f}% ({worst[1]}, level {worst[2]['level']}, "
                         f"k = {worst[2]['stiffness'] / 1e3:g} kPa).")
        elif kind == "absolute":
            absolute = [(abs(row["models"][m]["distance_error_absolute"]), models[m], row) for row in rows
                        for m in row["models"] if row["models"][m].get("distance_error_absolute") is not None]
            largest = max(absolute, key=lambda e: e[0], default=None)
            if largest:
                sentence += (f"The largest absolute error is {1000 * largest[0]:.2f} mm ({largest[1]}, level "
                             f"{largest[2]['level']}, k = {largest[2]['stiffness'] / 1e3:g} kPa); absolute errors grow "
                             "with the distance swum, i.e. with k.")
        _figure(lines, out, report, key, caption, sentence)
    balances = [abs(row["fom"]["energy"]["imbalance_midpoint_relative"]) for row in rows
                if (row["fom"].get("energy") or {}).get("imbalance_midpoint_relative") is not None]
    lines += ["### FOM reference runs", "",
              "Distance, tail amplitude, cost, Newton iterations and energy balance (imbalance with the midpoint "
              "dissipation D_mid relative to the energy throughput, see the stress tests) of every FOM case; a stopped "
              "run gives the solver's message"
              + (f"; the energy imbalance stays below {100 * max(balances):.2f}%." if balances else "."), ""]
    lines += table(["level", "cells", "k [kPa]", "status", "distance [cm]", "tail amplitude [cm]", "set-up [s]",
                    "solve [s]", "Newton mean / max", "energy imbalance", "message"],
                   [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}", row["fom"].get("status"),
                     fmt(row["fom"].get("distance"), ".3f", 100), fmt(row["fom"].get("tail_amplitude"), ".3f", 100),
                     fmt(row["fom"].get("setup_time"), ".2f"), fmt(row["fom"].get("solve_time"), ".1f"),
                     f"{fmt((row['fom'].get('newton') or {}).get('mean'), '.2f')} / "
                     f"{fmt((row['fom'].get('newton') or {}).get('max'), '.0f')}",
                     percent((row["fom"].get("energy") or {}).get("imbalance_midpoint_relative"), 3),
                     short(row["fom"].get("message"))] for row in rows])
    lines += [""]
    for key, what, unit, scale, spec in (
            ("distance_error_relative", "Relative distance error", "%", 100, "+.2f"),
            ("distance_error_absolute", "Absolute distance error", "mm", 1000, "+.3f"),
            ("tail_amplitude_error_relative", "Relative tail-amplitude error", "%", 100, "+.2f"),
            ("tail_amplitude_error_absolute", "Absolute tail-amplitude error", "mm", 1000, "+.3f")):
        values = [abs(row["models"][m][key]) for row in rows for m in row["models"] if row["models"][m].get(key) is not None]
        per_model = {m: max((abs(row["models"][m][key]) for row in rows if row["models"].get(m, {}).get(key) is not None),
                            default=None) for m in models}
        sentence = (f"{what} [{unit}] of each reduced model against the FOM per case; the largest magnitudes are "
                    + ", ".join(f"{models[m]} {fmt(v, '.3g', scale)} {unit}" for m, v in per_model.items()) + ".")
        lines += [f"### {what} [{unit}]", "", sentence if values else f"{what}: no completed pair yet.", ""]
        lines += table(["level", "cells", "k [kPa]", "FOM A [cm]"] + [models[m] for m in models],
                       [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}",
                         fmt(row["fom"].get("tail_amplitude"), ".2f", 100)]
                        + [fmt(row["models"].get(m, {}).get(key), spec, scale)
                           if row["models"].get(m, {}).get("status") == "completed" else row["models"].get(m, {}).get("status", "—")
                           for m in models] for row in rows])
        lines += [""]
    lines += ["### Build and solve times [s]", "",
              f"Build (basis + reduced tensors) and solve time ({study['duration']:g} s horizon; in brackets the PROM "
              "solve with sensitivities) of each reduced model per case; the FOM column is its total wall time.", ""]
    lines += table(["level", "cells", "k [kPa]", "FOM"] + [f"{models[m]} build / solve" for m in models],
                   [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}", fmt(row["fom"].get("wall_time"), ".1f")]
                    + [f"{fmt(row['models'].get(m, {}).get('build_time'), '.2f')} / "
                       f"{fmt(row['models'].get(m, {}).get('solve_time'), '.2f')}"
                       + (f" ({fmt(row['models'][m].get('solve_time_sensitivities'), '.2f')})"
                          if row["models"].get(m, {}).get("solve_time_sensitivities") else "") for m in models]
                    for row in rows])
    listed = cases_above(study)
    lines += ["", f"### Cases above ±{100 * TOLERANCE_LIST:g}%", ""]
    if listed:
        lines += [f"{len(listed)} model/case pairs have a distance error beyond ±{100 * TOLERANCE_LIST:g}%, with the "
                  "FOM tail amplitude and the cells of the case:", ""]
        lines += table(["model", "level", "cells", "k [kPa]", "FOM tail amplitude [cm]", "distance error",
                        "tail amplitude error"],
                       [[entry["model"], entry["level"], entry["cells"], f"{entry['stiffness'] / 1e3:g}",
                         fmt(entry["tail_amplitude"], ".2f", 100), percent(entry["error"], 1),
                         percent(entry["tail_amplitude_error"], 1)] for entry in listed])
    else:
        lines += [f"No completed case has a distance error beyond ±{100 * TOLERANCE_LIST:g}%."]
    lines += [""]


def _section_b(lines, study, out, report):
    title = "## b. Cost against size"
    if not study:
        return _not_run(lines, title)
    models = study["models"]
    solve = [f for f in study["fits"] if f["quantity"] == "solve" and f["model"] != "FOM" and f.get("exponent") is not None]
    build = [f for f in study["fits"] if f["quantity"] == "build" and f["model"] != "FOM" and f.get("exponent") is not None]
    sentence = ("Build and solve wall time of every model against the number of cells (every case of study a: small "
                "markers; per-level median: lines), log-log, with the least-squares exponents in the legends. ")
    if solve and build:
        sentence += (f"Reduced solve exponents range {min(f['exponent'] for f in solve):.2f}–"
                     f"{max(f['exponent'] for f in solve):.2f} and build exponents "
                     f"{min(f['exponent'] for f in build):.2f}–{max(f['exponent'] for f in build):.2f}.")
    lines += [title, ""]
    _figure(lines, out, report, "cost", "Cost against cells", sentence)
    lines += ["Least-squares exponents e of t = c · cells^e (build split into basis, reduced tensors and the rest: "
              "FOM set-up, spine rows, basis gathering).", ""]
    lines += table(["model", "quantity", "exponent e", "c [s]", "points"],
                   [[models.get(f["model"], f["model"]), f["quantity"], fmt(f.get("exponent"), ".3f"),
                     fmt(f.get("prefactor"), ".3g"), f.get("points", "—")] for f in sorted_fits(study)])
    lines += [""]


def _section_c(lines, study, out, report):
    title = "## c. Run time against error (reference case)"
    if not study:
        return _not_run(lines, title)
    points = pareto_points(study)
    front = pareto_front(points)
    default = next((p for p in study["points"] if p.get("default")), {})
    reference = study.get("reference", {})
    lines += [title, "",
              f"Reference: the FOM at h = {study['reference_time_step']} s (level {study['level']}, distance "
              f"{fmt(reference.get('distance'), '.3f', 100)} cm, {fmt(reference.get('wall_time'), '.1f')} s); the Taylor-order "
              f"points are the SO1 PROM at ξ = {', '.join(f'{k} {v:g}' for k, v in study['taylor_design'].items())} "
              "(every parameter at its validity radius) against the FOM at that design and the same fine step.", ""]
    _figure(lines, out, report, "pareto", "Run time against error",
            f"Every variant's |distance error| against its wall time; the default (star) has "
            f"{percent(default.get('distance_error_relative'))} in {fmt(default.get('wall_time'), '.2f')} s, and the "
            f"Pareto front of the ξ = 0 variants is {', '.join(p.get('short') or p['label'] for p in front) or '—'}.")
    lines += table(["variant", "family", "status", "m", "wall time [s]", "build [s]", "solve [s]", "distance [cm]",
                    "error", "Pareto"],
                   [[p["label"] + (" **(default)**" if p.get("default") else ""), p["family"], p.get("status"),
                     p.get("size") or "—", fmt(p.get("wall_time"), ".2f"), fmt(p.get("build_time"), ".2f"),
                     fmt(p.get("solve_time"), ".2f"), fmt(p.get("distance"), ".3f", 100),
                     percent(p.get("distance_error_relative")),
                     "yes" if any(f["id"] == p["id"] for f in front) else ""] for p in study["points"]])
    lines += [""]


def _section_d(lines, study, out, report):
    title = "## d. Time-step convergence"
    if not study:
        return _not_run(lines, title)
    head = [q for q in study["quantities"] if "head x," in q["name"] and q.get("ratio") is not None]
    lines += [title, "",
              f"Level {study['level']}, h = {', '.join(f'{h:g}' for h in study['time_steps'])} s; differences are "
              f"maxima over the samples of the h = {study['grid_step']:g} s grid; a second-order scheme gives ratios ≈ 4. "
              "Newmark with γ = ½ + α_N is second order only for α_N = 0: for α_N > 0 an O(α_N h) error term "
              "makes the ratios fall towards 2 once it dominates, so each family is run at α_N = "
              + ", ".join(f"{alpha:g}" for alpha in study.get("alphas", [])) + " (0, SPEC's value, the default).", ""]
    _figure(lines, out, report, "convergence", "Time-step convergence",
            "Successive differences over time for head x (FOM, ROM) and the PROM sensitivities; "
            + ("head-x ratios " + ", ".join(f"{q['name']} {q['ratio']:.2f}" for q in head) + "." if head else ""))
    lines += table(["quantity", "status", "max |q_h − q_h/2| per pair", "ratio"],
                   [[q["name"], q.get("status"), ", ".join(f"{pair}: {fmt(value, '.3g')}" for pair, value in
                                                           zip(q.get("pairs", []), q.get("differences", [])))
                     or short(q.get("message")), fmt(q.get("ratio"), ".2f")] for q in study["quantities"]])
    lines += [""]


def _section_mesh(lines, study, out, report):
    title = "## Mesh convergence of the FOM"
    if not study or not study.get("rows"):
        return _not_run(lines, title)
    units = {"distance": ("cm", 100.0), "tail_amplitude": ("cm", 100.0), "first_frequency": ("Hz", 1.0),
             "static_tail_deflection": ("cm", 100.0)}
    lines += [title, "",
              "The nominal fish per element degree and mesh level: swimming distance, tail amplitude, first natural "
              "frequency (head clamped) and static tail deflection with the muscles at their peak (head clamped). "
              "Reference: Richardson extrapolation of the three finest cases of the highest degree with h = "
              "cells^(-1/3); its estimated error is the correction |f* − f_finest|. When the differences change sign "
              "(no order, shown as —) the finest value is the reference and the last difference its error.", ""]
    lines += table(["quantity", "reference", "observed order", "estimated error", "from degree"],
                   [[name, f"{fmt(ref['value'], '.4g', units[name][1])} {units[name][0]}",
                     fmt(ref.get("observed_order"), ".2f"), f"{fmt(ref['estimated_error'], '.2g', units[name][1])} "
                     f"{units[name][0]}", str(ref.get("degree"))] for name, ref in study["reference"].items()])
    lines += [""]
    lines += table(["degree", "level", "cells", "dofs", "distance [cm]", "error", "tail amplitude [cm]",
                    "f_1 [Hz]", "static tail y [cm]", "wall time [s]"],
                   [[str(row["degree"]), str(row["level"]), str(row["cells"]), str(row["dofs"]),
                     fmt(row["distance"], ".4g", 100.0), percent(row["relative_error_distance"], 1),
                     fmt(row["tail_amplitude"], ".4g", 100.0), fmt(row["first_frequency"], ".4g"),
                     fmt(row["static_tail_deflection"], ".4g", 100.0), fmt(row["wall_time"], ".1f")]
                    for row in study["rows"]])
    default = study.get("default")
    lines += ["", ("Cheapest (degree, level) within 3 % of the reference distance: "
                   f"degree {default['degree']}, level {default['level']} "
                   f"({percent(default['relative_error_distance'], 1)}, {default['wall_time']:.1f} s)."
                   if default else "No case is within 3 % of the reference distance."), ""]
    for failure in study.get("failed", []):
        lines += [f"- {failure['label']}: {failure['status']}, {short(failure.get('message'))}"]
    _figure(lines, out, report, "mesh", "Mesh convergence", "FOM wall time against the error of each quantity.")


def _section_e(lines, study):
    title = "## e. MPI: the FOM with mpirun -n 1 and -n 2"
    if not study:
        return _not_run(lines, title)
    speedups = [c for c in study["comparisons"] if c.get("speedup")]
    lines += [title, "",
              "Wall time of `aquarom simulate` (the simulation, without interpreter start) and agreement of the two "
              "runs; " + (", ".join(f"level {c['level']}: speed-up {c['speedup']:.2f}, distance difference "
                                    f"{fmt(c.get('distance_relative_difference'), '.1e')}" for c in speedups) or
                          "no pair of completed runs yet") + ".", ""]
    lines += table(["level", "cells", "ranks", "status", "wall time [s]", "process [s]", "distance [cm]",
                    "tail amplitude [cm]", "Newton mean", "peak memory rank 0 [MB]", "message"],
                   [[r["level"], r.get("cells") or "—", r["ranks"], r.get("status"), fmt(r.get("wall_time"), ".1f"),
                     fmt(r.get("process_time"), ".1f"), fmt(r.get("distance"), ".4f", 100),
                     fmt(r.get("tail_amplitude"), ".4f", 100), fmt(r.get("mean_newton_iterations"), ".2f"),
                     fmt(r.get("peak_memory_mb_rank0"), ".0f"), short(r.get("message"), 80)] for r in study["runs"]])
    lines += ["", "Speed-up and agreement per level (head x compared sample by sample over the common time).", ""]
    lines += table(["level", "cells", "speed-up (total)", "speed-up (time integration)", "distance difference",
                    "max |Δ head x| [m]", "compared until [s]"],
                   [[c["level"], c.get("cells") or "—", fmt(c.get("speedup"), ".2f"), fmt(c.get("speedup_solve"), ".2f"),
                     fmt(c.get("distance_relative_difference"), ".2e"), fmt(c.get("head_x_max_difference"), ".2e"),
                     fmt(c.get("compared_until"), ".2f")] for c in study["comparisons"]])
    lines += [""]


def _section_stress(lines, study, out, report):
    title = "## Stress tests of numerical stability"
    if not study:
        return _not_run(lines, title)
    rows = study["rows"]
    unclean = [row for row in rows if not row.get("clean")]
    lines += [title, "",
              f"Level {study['level']}, horizon {study['duration']:g} s. A case passes when it converges or stops "
              "with a solver message naming the time (never a NaN, never a hang: a time limit per case); "
              f"{len(rows) - len(unclean)} of {len(rows)} cases pass.", ""]
    lines += table(["case", "model", "status", "clean", "distance [cm]", "tail amplitude [cm]", "Newton mean / max",
                    "wall time [s]", "message"],
                   [[row["description"], row["model"], row["status"], "yes" if row.get("clean") else "**no**",
                     fmt(row.get("distance"), ".3f", 100), fmt(row.get("tail_amplitude"), ".3f", 100),
                     f"{fmt((row.get('newton') or {}).get('mean'), '.2f')} / {(row.get('newton') or {}).get('max', '—')}",
                     fmt(row.get("wall_time"), ".1f"), short(row.get("message"))] for row in rows])
    fine = [row for row in rows if row["id"] == "fine-mesh-prom"]
    for row in fine:
        lines += ["", f"Fine-mesh PROM build: {row.get('cells')} cells, m = {row.get('size')}, build "
                  f"{fmt(row.get('build_time'), '.1f')} s, tensors finite: {row.get('finite_tensors')}, dropped vectors: "
                  f"{', '.join(row.get('dropped') or []) or 'none'}, process peak memory "
                  f"{fmt(row.get('peak_rss_mb_process'), '.0f')} MB."]
    energetic = [row for row in rows if row.get("energy")]
    if energetic:
        lines += ["", "### Energy balance (FOM)", "",
                  f"Work done on the fish against dissipated plus stored energy at the end of the run; {study['energy_note']}. "
                  "Imbalance = W_act + W_thrust + W_drag − D − E_kin − E_el, relative to the energy throughput "
                  "Σ_n (|ΔW_act| + |ΔW_thrust| + |ΔW_drag|) (the final works alone can be near zero: the muscles take "
                  "back over a cycle what they gave). "
                  "D is the trapezoidal sum of the issue, Σ h ½(u̇_n·C u̇_n + u̇_{n+1}·C u̇_{n+1}), which over-counts by "
                  "h/4 Δu̇·C Δu̇ per step (an O(h²) error that grows with h); D_mid = Σ h ū·C ū with ū the step's mean "
                  "velocity is the form of Newmark's own energy identity, so its imbalance is the scheme's numerical "
                  "dissipation (zero for α_N = 0 up to the quadrature of the nonlinear forces).", ""]
        lines += table(["case", "W_act [mJ]", "W_thrust [mJ]", "W_drag [mJ]", "throughput [mJ]", "D [mJ]", "D_mid [mJ]",
                        "kinetic [mJ]", "elastic [mJ]", "imbalance (D)", "imbalance (D_mid)"],
                       [[row["id"]] + [fmt(row["energy"].get(key), ".4g", 1e3) for key in (
                           "work_actuation", "work_thrust", "work_drag", "throughput", "dissipated",
                           "dissipated_midpoint", "kinetic", "elastic")]
                        + [percent(row["energy"]["imbalance_relative"], 2),
                           percent(row["energy"].get("imbalance_midpoint_relative"), 3)] for row in energetic])
        lines += [""]
        worst = max(energetic, key=lambda row: abs(row["energy"]["imbalance_relative"] or 0))
        worst_mid = max(energetic, key=lambda row: abs(row["energy"].get("imbalance_midpoint_relative") or 0))
        _figure(lines, out, report, "energy", "Energy balance of the FOM stress cases",
                f"Cumulative work in against dissipated + stored energy over time; the largest imbalance is "
                f"{percent(worst['energy']['imbalance_relative'], 2)} with the trapezoidal D ({worst['id']}) and "
                f"{percent(worst_mid['energy'].get('imbalance_midpoint_relative'), 3)} with D_mid ({worst_mid['id']}).")
    lines += [""]


def _embedded(path: Path, report: Path) -> str:
    """A Markdown file's text with its relative links made relative to the report, headings demoted."""
    text = path.read_text()
    prefix = _link(path.parent, report)

    def relink(match):
        target = match.group(2)
        if re.match(r"^(https?:|/|#)", target):
            return match.group(0)
        return f"{match.group(1)}({prefix}/{target})" if prefix != "." else match.group(0)

    text = re.sub(r"(\]\s*)\(([^)\s]+)\)", relink, text)
    return re.sub(r"^(#+)", r"\1##", text, flags=re.MULTILINE).strip()


def _section_validity(lines, path: Path, report: Path):
    """The PROM validity-radius study (scripts/validate_prom_radius.py), when it has been run."""
    if path.exists():
        lines += ["## PROM validity radius", "",
                  f"From `{_link(path, report)}` (`scripts/validate_prom_radius.py`): the SO1 PROM built at ξ = 0 "
                  "against the FOM along each shape direction.", "", _embedded(path, report), ""]


def _section_optimisation(lines, summary: Path, report: Path):
    lines += ["## Optimisation studies", ""]
    if not summary.exists():
        lines += [f"*No optimisation summary yet* (`make study` writes `{_link(summary, report)}`).", ""]
        return
    lines += [f"From `{_link(summary, report)}`: the optimisation table of the shape studies.", "",
              _embedded(summary, report), ""]
