"""CSV tables a run writes row by row, and the columns of trajectory.csv."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

TRAJECTORY_COLUMNS = ("time", "head_x", "tail_y", "com_x", "tail_x", "com_y", "newton_iterations")
"""The arrays of a trajectory, by name: time [s], head x, tail y, centre-of-mass x, tail x, centre-of-mass y
[m], Newton iterations."""

OPTIONAL_TRAJECTORY_COLUMNS = ("tail_x", "com_y")
"""Columns a trajectory.csv written before they existed lacks (read as absent, not refused)."""


class IncrementalCSV:
    """A CSV file written one row at a time and flushed at once, so that the rows already written
    survive a run that stops later."""

    def __init__(self, path: Path, header: list[str]):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(path, "w", newline="")
        self._writer = csv.writer(self._stream)
        self.rows = 0
        self._writer.writerow(header)
        self._stream.flush()

    def write_row(self, values: list) -> None:
        self._writer.writerow(values)
        self._stream.flush()
        self.rows += 1

    def close(self) -> None:
        self._stream.close()


TRAJECTORY_FILE_COLUMNS = {"time": "time_s", "head_x": "head_x_m", "tail_y": "tail_y_m", "com_x": "com_x_m",
                           "tail_x": "tail_x_m", "com_y": "com_y_m", "newton_iterations": "newton_iterations"}
"""trajectory.csv's header: every column named with its SI unit (time [s], positions [m])."""


class TrajectoryCSV(IncrementalCSV):
    """trajectory.csv, one row per converged step (kept if a later step fails): time_s, head_x_m,
    tail_y_m, com_x_m, tail_x_m, com_y_m (head and centre-of-mass x, tail y, tail x, centre-of-mass y,
    all displacements [m]) and newton_iterations."""

    def __init__(self, path: Path):
        super().__init__(path, [TRAJECTORY_FILE_COLUMNS[name] for name in TRAJECTORY_COLUMNS])

    def write(self, time, head_x, tail_y, com_x, tail_x, com_y, iterations) -> None:
        self.write_row([f"{time:.10g}", *(f"{value:.17g}" for value in (head_x, tail_y, com_x, tail_x, com_y)),
                        iterations])


def write_trajectory_csv(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A whole trajectory at once (reduced runs are fast enough not to stream)."""
    table = TrajectoryCSV(path)
    for row in zip(*(arrays[name] for name in TRAJECTORY_COLUMNS)):
        table.write(*row[:-1], int(row[-1]))
    table.close()
