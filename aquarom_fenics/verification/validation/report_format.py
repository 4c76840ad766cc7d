"""Shared pieces of the validation report: study files, number formats, Markdown tables, figure files.

Plain JSON in, strings out; matplotlib is imported only when a figure is drawn.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

DPI = 120
TOLERANCE_REFERENCE = 0.05     # default ROM at the reference case: |distance error| within 5%
TOLERANCE_LIST = 0.10          # cases listed above 10%
RATIO_RANGE = (3.5, 4.5)       # successive-difference ratios of a second-order scheme (time-stepping issue)
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
    for name in ("a", "b", "c", "d", "e", "stress", "mesh_convergence", "stations", "fish_mesh_convergence", "calibration",
                 "run"):
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



def energy_share(energy: dict | None, key: str, spec: str = ".3f") -> str:
    """A share of the energy throughput from a record's balance: '—' without one, 'not available' for a
    run whose balance could not be formed (cut steps)."""
    if not energy:
        return "—"
    if not energy.get("available"):
        return "not available"
    value = energy.get(key)
    return fmt(value, spec, 100.0, signed=True) + ("%" if value is not None else "")


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


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def saved(figure, path: Path, rect=(0, 0, 1, 1)) -> Path:
    """Lay out ``figure`` within ``rect``, write it to ``path`` at DPI and close it."""
    figure.tight_layout(rect=rect)
    figure.savefig(path, dpi=DPI)
    pyplot().close(figure)
    return path


def grid_and_legend(axes, fontsize: int) -> None:
    """Major and minor grid on every axis, and a legend where something is labelled."""
    for axis in axes:
        axis.grid(alpha=0.3, which="both")
        if axis.get_legend_handles_labels()[0]:
            axis.legend(fontsize=fontsize)


def link(path: Path, report: Path) -> str:
    return Path(os.path.relpath(path, report.parent)).as_posix()


def show_figure(lines, out, report, key, caption, sentence):
    path = out / FIGURES[key]
    if path.exists():
        lines += [f"![{caption}]({link(path, report)})", "", f"*{caption}.* {sentence}", ""]
    else:
        lines += [f"*{caption}: not drawn yet.*", ""]


def not_run(lines, title):
    lines += [title, "", "*Not run yet* (`scripts/validate.py --only ...`).", ""]
