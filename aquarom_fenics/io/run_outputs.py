"""What a simulation run leaves in its folder, written by one writer for the FOM and the reduced models.

``trajectory.csv`` (time_s, head_x_m, tail_y_m, com_x_m, tail_x_m, com_y_m, newton_iterations per sample),
``displacement.npz`` (the nodal displacement series the animation reads), ``summary.json`` (distance, tail amplitude,
stop reason, scene, design, versions) and ``trajectory.png``.
"""
from __future__ import annotations

import resource
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.plots import plot_trajectory
from aquarom_fenics.io.tables import write_trajectory_csv
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic, write_npz_atomic


RUN_SUMMARY_UNITS = {"distance": "m", "tail_amplitude": "m", "wall_time": "s", "timings": "s",
                     "build_timings": "s", "peak_memory_mb": "MB", "xi": "1 (shape parameters are dimensionless)",
                     "strain": "1 (Green-Lagrange strain); its time in s, its point in m (mesh coordinates)"}
"""The ``units`` block of a run's summary.json: every dimensional key and its SI unit."""

DISPLACEMENT_FILE = "displacement.npz"
"""Nodal displacement time series of a run, written next to trajectory.csv."""


@dataclass(frozen=True)
class DisplacementSeries:
    """Nodal displacements of one run on its design mesh."""

    points: np.ndarray        # (n_nodes, 3) design positions x_0 + U ξ [m]
    cells: np.ndarray         # (n_cells, 4) node indices of the linear tetrahedra
    time: np.ndarray          # (n_samples,) sample times [s]
    displacement: np.ndarray  # (n_samples, n_nodes, 3) displacement from the design [m]

    def deformed(self, sample: int) -> np.ndarray:
        """Nodal positions [m] at one sample (true scale)."""
        return self.points + self.displacement[sample]


def write_displacement_series(path: Path, points, cells, time, nodal_displacements) -> Path:
    """Write ``displacement.npz`` (through a temporary file, so a reader never sees half of it).

    ``points`` (n_nodes, 3) are the design positions x_0 + U ξ [m], ``cells`` (n_cells, 4) the
    tetrahedra, ``time`` the n_samples sample times [s] and ``nodal_displacements`` the
    (n_samples, n_nodes, 3) nodal displacements from the design [m] (a list of (n_nodes, 3)
    arrays will do). Returns ``path``.
    """
    series = DisplacementSeries(np.asarray(points, dtype=np.float64), np.asarray(cells, dtype=np.int64),
                                np.asarray(time, dtype=np.float64),
                                np.asarray(nodal_displacements, dtype=np.float64))
    problem = _shape_problem(series)
    if problem:
        raise ValueError(f"displacement series for {path}: {problem}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_npz_atomic(path, {"points": series.points, "cells": series.cells, "time": series.time,
                            "displacement": series.displacement}, compressed=True)
    return path


def read_displacement_series(path: Path) -> DisplacementSeries:
    """The series written by :func:`write_displacement_series` (InputError if it is not one)."""
    path = Path(path)
    try:
        with np.load(path) as data:
            series = DisplacementSeries(data["points"], data["cells"], data["time"], data["displacement"])
    except FileNotFoundError:
        raise InputError(f"{path} does not exist") from None
    except (KeyError, OSError, ValueError, zipfile.BadZipFile) as error:
        raise InputError(f"{path} is not a displacement series (points, cells, time, displacement): {error}") from None
    problem = _shape_problem(series)
    if problem:
        raise InputError(f"{path}: {problem}")
    return series


def _shape_problem(series: DisplacementSeries) -> str:
    """What is inconsistent about the arrays' shapes, or an empty string."""
    n_nodes = series.points.shape[0] if series.points.ndim == 2 else -1
    if series.points.shape != (n_nodes, 3) or n_nodes < 4:
        return f"points must be (n_nodes, 3), got {series.points.shape}"
    if series.cells.ndim != 2 or series.cells.shape[1] != 4:
        return f"cells must be (n_cells, 4), got {series.cells.shape}"
    if series.cells.size and not 0 <= series.cells.min() <= series.cells.max() < n_nodes:
        return f"cells refer to nodes outside 0 … {n_nodes - 1}"
    if series.time.ndim != 1 or series.time.size == 0:
        return f"time must be a non-empty 1-d array, got {series.time.shape}"
    expected = (series.time.size, n_nodes, 3)
    if series.displacement.shape != expected:
        return f"displacement must be (n_samples, n_nodes, 3) = {expected}, got {series.displacement.shape}"
    return ""


def write_run_outputs(out_dir: Path, scene, result, model_name: str, design: dict[str, float], rest_points,
                      cells, nodal_displacements, comm, extra: dict | None = None,
                      trajectory_written: bool = False, regions: np.ndarray | None = None) -> None:
    """The files of a FOM or reduced run in ``out_dir`` (called on the writing rank).

    trajectory.csv from ``result.trajectory`` (unless the run streamed it, ``trajectory_written``),
    displacement.npz of the vertex displacements [m] from ``rest_points`` (the design's vertex
    positions [m]) on ``cells``, summary.json (``result.summary()``, the model, scene, design,
    MPI ranks, peak memory [MB], versions and ``extra`` model facts), with the scene's plots
    trajectory.png and, with the scene's ``[output] xdmf``, displacement.xdmf: the design mesh
    (its cell ``regions``, when given) and the displacement series on it, zero at t = 0.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    arrays = result.trajectory.arrays()
    if not trajectory_written:
        write_trajectory_csv(out_dir / "trajectory.csv", arrays)
    write_displacement_series(out_dir / DISPLACEMENT_FILE, rest_points, cells, arrays["time"], nodal_displacements)
    if scene.output.xdmf:
        from aquarom_fenics.io.xdmf import write_design_xdmf

        write_design_xdmf(out_dir / "displacement.xdmf", rest_points, cells, regions, arrays["time"],
                          nodal_displacements)
    summary = result.summary() | (extra or {}) | {
        "model": model_name, "scene": scene.name, "scene_hash": scene.hash, "scene_values": scene.to_dict(),
        "xi": {name: float(value) for name, value in design.items()}, "mpi_ranks": comm.size,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "versions": software_versions(), "units": RUN_SUMMARY_UNITS}
    write_json_atomic(out_dir / "summary.json", summary)
    if scene.output.plots and len(result.trajectory) > 1:
        title = f"{scene.name} ({model_name}): distance " + (
            f"{100 * result.distance:.2f} cm" if result.completed else "n/a (stopped early)")
        plot_trajectory(out_dir / "trajectory.png", arrays, title)
