"""Figures of `make validate` from the study files <out>/<study>.json (PNG, no FEniCS import)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from aquarom_fenics.verification.validation.figures_accuracy import cost_figure, heatmaps, pareto_figure
from aquarom_fenics.verification.validation.report_format import (FIGURES, grid_and_legend, load_studies, percent,
                                                                   pyplot, saved)

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


PAIR_STYLES = ("-", "--", ":", "-.", (0, (1, 1)), (0, (5, 1)), (0, (3, 1, 1, 1, 1, 1)))
"""Line styles of the successive pairs of time steps."""


def convergence_figure(study: dict, path: Path) -> Path:
    plt = pyplot()
    figure, axes = plt.subplots(1, 2, figsize=(14, 6))
    for quantity in study["quantities"]:
        if "difference_series" not in quantity:
            continue
        axis = axes[1] if "ξ" in quantity["name"] else axes[0]
        colour = None
        for pair, series, style in zip(quantity["pairs"], quantity["difference_series"], PAIR_STYLES):
            values = np.asarray(series, dtype=float)
            values = np.where(values > 0, values, np.nan)     # t = 0: identical initial state
            line, = axis.semilogy(quantity["time"], values, linestyle=style, color=colour, linewidth=1,
                                  label=f"{quantity['name']}, h = {pair} s")
            colour = line.get_color()
    axes[0].set_ylabel("|head x(h) − head x(h/2)| [m]")
    axes[1].set_ylabel("|S(h) − S(h/2)| of head x [m per unit ξ]")
    axes[0].set_title("head x: successive differences")
    axes[1].set_title("sensitivities d head x / d ξ: successive differences")
    for axis in axes:
        axis.set_xlabel("time [s]")
    grid_and_legend(axes, fontsize=6)
    figure.suptitle("Time-step convergence (second order: each halving of h divides the difference by ≈ 4; "
                    "α_N > 0 tends to first order, ≈ 2)")
    return saved(figure, path)


MESH_QUANTITIES = (("distance", "swimming distance"), ("static_tail_deflection", "static tail deflection"),
                   ("first_frequency", "first frequency"), ("tail_amplitude", "tail amplitude"))


def mesh_figure(study: dict, path: Path) -> Path:
    """FOM wall time against the relative error of each quantity, one line per element degree."""
    plt = pyplot()
    figure, axes = plt.subplots(1, len(MESH_QUANTITIES), figsize=(18, 5), sharey=True)
    for axis, (name, label) in zip(axes, MESH_QUANTITIES):
        for degree, marker in ((1, "o"), (2, "s")):
            # a quantity without a reference (None) has no error to draw, nor a case that is the reference (0)
            rows = [row for row in study["rows"] if row["degree"] == degree and row[f"{name}_error"]]
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
    grid_and_legend(axes, fontsize=8)
    figure.suptitle("Mesh convergence: FOM cost against error w.r.t. the Richardson reference (dotted: 3 %)")
    return saved(figure, path)


def energy_figure(study: dict, path: Path) -> Path | None:
    """Per FOM stress case: cumulative work in, Rayleigh and numerical dissipation and stored energy [mJ],
    and on the right axis what is left (the Newton residual of the steps)."""
    rows = [row for row in study["rows"] if (row.get("energy") or {}).get("available")]
    if not rows:
        return None
    plt = pyplot()
    columns = min(4, len(rows))
    lines = math.ceil(len(rows) / columns)
    figure, axes = plt.subplots(lines, columns, figsize=(4.2 * columns, 3.3 * lines), squeeze=False)
    for axis, row in zip(axes.ravel(), rows):
        series = {key: 1e3 * np.asarray(value) for key, value in row["energy"]["series"].items()}
        time_values = series["time"] / 1e3
        axis.plot(time_values, series["work"], label="work in (actuation + thrust + drag)")
        axis.plot(time_values, series["dissipated_rayleigh"], "--", label="dissipated (Rayleigh)")
        axis.plot(time_values, series["dissipated_numerical"], "-.", label="dissipated (time scheme)")
        axis.plot(time_values, series["stored"], ":", label="stored (kinetic + elastic)")
        right = axis.twinx()
        right.plot(time_values, series["work"] - series["dissipated_rayleigh"] - series["dissipated_numerical"]
                   - series["stored"], color="crimson", linewidth=1.0, label="imbalance (Newton residual)")
        right.set_ylabel("imbalance [mJ]", color="crimson", fontsize=8)
        right.tick_params(axis="y", colors="crimson", labelsize=7)
        if row is rows[0]:
            handles = axis.get_legend_handles_labels()
            extra = right.get_legend_handles_labels()
            figure.legend(handles[0] + extra[0], handles[1] + extra[1], fontsize=8, loc="lower center", ncol=5,
                          frameon=False)
        energy = row["energy"]
        axis.set_title(f"{row['id']}: {row['status']}; numerical dissipation "
                       f"{percent(energy.get('numerical_dissipation_relative'), 3)}", fontsize=8)
        axis.set_xlabel("time [s]")
        axis.set_ylabel("energy [mJ]")
        axis.grid(alpha=0.3)
    for axis in axes.ravel()[len(rows):]:
        axis.axis("off")
    figure.suptitle("Energy balance of the FOM stress cases (shares of the energy throughput)")
    return saved(figure, path, rect=(0, 0.06, 1, 1))
