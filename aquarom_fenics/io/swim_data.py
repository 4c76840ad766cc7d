"""A measured swim to calibrate against (issue 52): a CSV of tracked points in the model's frame.

The first column is ``time_s`` [s]; the others are ``<point>_<axis>_m`` [m], the displacements of
trajectory.csv's points from their rest positions (``head_x_m`` the head's volume average, ``tail_y_m`` and
``tail_x_m`` the tail station, ``com_x_m`` and ``com_y_m`` the centre of mass), any subset, at any frame rate. A tracking tool's
export in pixels is brought to this format by a scale [m/px] and the rest position as origin (the
manual's page "From the robot to the model and back"). Every refusal is one line (InputError, exit 2).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file

MAX_SWIM_FILE_BYTES = 64 * 2**20
"""Largest swim CSV read [bytes]."""

SWIM_COLUMNS = {"head_x_m": "head_x", "tail_y_m": "tail_y", "com_x_m": "com_x", "tail_x_m": "tail_x", "com_y_m": "com_y"}
"""The columns a swim may have (besides time_s) and the model's observable each is compared with."""

HELD_COLUMNS = ("head_y_m", "head_z_m")
"""Columns refused: the head is held in y and z (SPEC §5), the model's head does not move there."""

MAX_RANGE_BODY_LENGTHS = 10.0
"""A column whose range exceeds this many body lengths is refused (millimetres or pixels, not metres)."""


@dataclass(frozen=True)
class SwimData:
    """A measured swim: times t_i [s] and the tracked displacements y_ij [m] of ``observables`` j."""

    time: np.ndarray                     # (n,) strictly increasing, in [0, duration]
    values: np.ndarray                   # (n, k) [m]
    observables: tuple[str, ...]         # k names of SWIM_COLUMNS' values, e.g. ("head_x", "tail_y")
    source: str

    @property
    def columns(self) -> tuple[str, ...]:
        names = {value: key for key, value in SWIM_COLUMNS.items()}
        return tuple(names[name] for name in self.observables)


def read_swim(path: Path, duration: float, n_parameters: int, body_length: float) -> SwimData:
    """Read and check the swim CSV ``path`` against a scene of horizon ``duration`` [s] and body length
    ``body_length`` [m] for a fit of ``n_parameters`` parameters."""
    path = Path(path)
    what = f"swim data {path}"
    text = read_text_file(path, "swim data", MAX_SWIM_FILE_BYTES)
    rows = [row for row in csv.reader(text.splitlines()) if row and any(cell.strip() for cell in row)]
    if not rows:
        raise InputError(f"{what}: empty; the first line must be the header time_s,<point>_<axis>_m,...")
    header = [cell.strip() for cell in rows[0]]
    observables = _check_header(header, what)
    table = _numbers(rows[1:], len(header), what)
    time, values = table[:, 0], table[:, 1:]
    _check_times(time, duration, what)
    if time.size < n_parameters or time.size * values.shape[1] <= n_parameters:
        raise InputError(f"{what}: {time.size} row(s) of {values.shape[1]} column(s) for {n_parameters} "
                         f"parameter(s); a fit needs more data than parameters")
    for column, name in enumerate(header[1:]):
        spread = float(values[:, column].max() - values[:, column].min())
        if spread > MAX_RANGE_BODY_LENGTHS * body_length:
            raise InputError(f"{what}: column {name} spans {spread:g} m, more than {MAX_RANGE_BODY_LENGTHS:g} body "
                             f"lengths ({body_length:g} m each); positions must be in metres (millimetres or pixels? "
                             "divide by 1000, or multiply by the scale in m/px)")
    return SwimData(time, values, observables, str(path))


def _check_header(header: list[str], what: str) -> tuple[str, ...]:
    if not header or header[0] != "time_s":
        raise InputError(f"{what}: the first column must be time_s, got {header[0] if header else ''!r}")
    names = header[1:]
    if not names:
        raise InputError(f"{what}: no tracked column after time_s; give any of {', '.join(SWIM_COLUMNS)}")
    for name in names:
        if name in HELD_COLUMNS:
            raise InputError(f"{what}: column {name} refused: the head is held in y and z (SPEC §5), the model's "
                             "head moves only along x")
        if name not in SWIM_COLUMNS:
            raise InputError(f"{what}: unknown column {name!r}; the columns are time_s and any of "
                             f"{', '.join(SWIM_COLUMNS)} (<point>_<axis>_m, metres)")
    duplicates = sorted({name for name in header if header.count(name) > 1})
    if duplicates:
        raise InputError(f"{what}: column {duplicates[0]} appears twice")
    return tuple(SWIM_COLUMNS[name] for name in names)


def _numbers(rows: list[list[str]], width: int, what: str) -> np.ndarray:
    table = np.empty((len(rows), width))
    for index, row in enumerate(rows):
        line = index + 2
        if len(row) != width:
            raise InputError(f"{what}: line {line} has {len(row)} value(s), the header {width}")
        for column, cell in enumerate(row):
            try:
                value = float(cell)
            except ValueError:
                raise InputError(f"{what}: line {line}, column {column + 1}: {cell.strip()!r} is not a number") from None
            if not math.isfinite(value):
                raise InputError(f"{what}: line {line}, column {column + 1}: {cell.strip()} (every value must be "
                                 "a finite number; drop the frames where a point was lost)")
            table[index, column] = value
    return table


def _check_times(time: np.ndarray, duration: float, what: str) -> None:
    if time.size == 0:
        raise InputError(f"{what}: a header but no rows")
    steps = np.diff(time)
    if np.any(steps <= 0):
        bad = int(np.argmax(steps <= 0))
        raise InputError(f"{what}: times not increasing: {time[bad]:g} s then {time[bad + 1]:g} s (line {bad + 3})")
    if time[0] < 0:
        raise InputError(f"{what}: time {time[0]:g} s before the start of the swim (0 s)")
    if time[-1] > duration * (1 + 1e-9):
        raise InputError(f"{what}: times up to {time[-1]:g} s, beyond the scene's duration {duration:g} s; set "
                         "[solver] duration (a whole number of time steps) to cover the data")
