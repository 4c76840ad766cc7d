"""Files the toolkit reads back, each through one loader with a schema and one-line errors.

A damaged file (unreadable, not JSON, a key missing or of the wrong type, a CSV with other
columns or text where numbers belong) is an :class:`InputError` naming the file, the key and
what would be valid, never a ``KeyError`` or ``IndexError`` later on.

A schema is a small tree of checkers: :data:`NUMBER`, :data:`INTEGER`, :data:`TEXT`,
:data:`FLAG`, :data:`ANYTHING`, :func:`optional`, :func:`list_of` and :func:`record` (a JSON
object with required and optional keys; other keys are allowed).
"""
from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file, require_regular_file  # noqa: F401  (require_: for their users)
from aquarom_fenics.io.tables import OPTIONAL_TRAJECTORY_COLUMNS, TRAJECTORY_COLUMNS, TRAJECTORY_FILE_COLUMNS

MAX_READBACK_BYTES = 256 * 1024 * 1024
"""Largest JSON or CSV file read back [bytes] (a checkpoint of a long optimisation is a few MB)."""
MAX_MESH_FILE_BYTES = 2 * 1024 ** 3
"""Largest mesh file read (any format) [bytes]: checked by the reader and by the scene's hash."""


class SchemaError(ValueError):
    """A value that does not fit its schema: ``where`` (a dotted key) and what was expected."""

    def __init__(self, where: str, expected: str, value):
        shown = repr(value)
        super().__init__(f"{where or 'the file'} must be {expected}, got {shown[:60]}{'…' if len(shown) > 60 else ''}")


Check = Callable[[object, str], None]


def _scalar(expected: str, test) -> Check:
    def check(value, where):
        if not test(value):
            raise SchemaError(where, expected, value)
    return check


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


NUMBER = _scalar("a number", lambda v: _is_number(v))
FINITE = _scalar("a finite number", lambda v: _is_number(v) and math.isfinite(v))
INTEGER = _scalar("a whole number >= 0", lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 0)
TEXT = _scalar("a string", lambda v: isinstance(v, str))
FLAG = _scalar("true or false", lambda v: isinstance(v, bool))
ANYTHING = _scalar("anything", lambda v: True)


def optional(check: Check) -> Check:
    """``check``, or null."""
    def optional_check(value, where):
        if value is not None:
            check(value, where)
    return optional_check


def list_of(check: Check, length: int | None = None) -> Check:
    """A JSON array (of ``length`` items, when given) whose items pass ``check``."""
    def list_check(value, where):
        if not isinstance(value, list) or (length is not None and len(value) != length):
            raise SchemaError(where, "a list" + (f" of {length} items" if length is not None else ""), value)
        for index, item in enumerate(value):
            check(item, f"{where}[{index}]")
    return list_check


@dataclass
class record:
    """A JSON object with ``required`` keys and ``optional`` ones, each with its check."""

    required: dict[str, Check]
    optional: dict[str, Check] = field(default_factory=dict)

    def __call__(self, value, where):
        if not isinstance(value, dict):
            raise SchemaError(where, "an object {…}", value)
        for key, check in self.required.items():
            if key not in value:
                raise SchemaError(f"{where}.{key}".lstrip("."), "present", "nothing")
            check(value[key], f"{where}.{key}".lstrip("."))
        for key, check in self.optional.items():
            if key in value:
                check(value[key], f"{where}.{key}".lstrip("."))


def load_json(path: Path, schema: Check, kind: str, remedy: str = "") -> dict:
    """The JSON file ``path`` checked against ``schema``; InputError "KIND PATH: what; remedy"."""
    path = Path(path)
    hint = f"; {remedy}" if remedy else ""
    text = read_text_file(path, kind, MAX_READBACK_BYTES, remedy, nesting="json")
    try:
        data = json.loads(text)
    except ValueError as error:
        raise InputError(f"{kind} {path}: not valid JSON ({error}){hint}") from None
    try:
        schema(data, "")
    except SchemaError as error:
        raise InputError(f"{kind} {path}: {error}{hint}") from None
    return data


# ---------------------------------------------------------------------- the file kinds
def run_summary_schema() -> record:
    """summary.json of a simulation run (what ``aquarom animate`` reads)."""
    return record({"completed": FLAG},
                  {"stop_reason": TEXT, "scene": TEXT, "model": TEXT, "xi": record({}), "scene_values": record({}, {"mesh": record({})}),
                   "steps": INTEGER, "distance": optional(NUMBER)})


def load_run_summary(path: Path) -> dict:
    """summary.json of a simulation run, checked (xi values must be numbers)."""
    data = load_json(path, run_summary_schema(), "run summary",
                     "rerun `aquarom simulate` into this folder with --force")
    for name, value in data.get("xi", {}).items():
        try:
            NUMBER(value, f"xi.{name}")
        except SchemaError as error:
            raise InputError(f"run summary {path}: {error}") from None
    return data


def checkpoint_schema(dimension: int, method: str, shapes: int | None = None) -> record:
    """checkpoint.json of an optimisation with ``dimension`` design variables, the first ``shapes``
    of them shape parameters (all of them when None; a co-optimisation adds the amplitude): the
    basis centre is a shape."""
    vector = list_of(FINITE, dimension)
    shape = list_of(FINITE, dimension if shapes is None else shapes)
    finished = record({"optimum": vector, "cost": FINITE, "gradient": vector, "distance": FINITE,
                       "distance_gradient": vector, "prom_size": INTEGER, "reason": TEXT})
    if method == "paper":
        state = record({"z": vector, "iteration": INTEGER, "scaling": vector, "previous_gradient": optional(vector),
                        "since_build": INTEGER,
                        "center": optional(record({"z": vector, "distance": FINITE, "distance_gradient": vector},
                                                  {"prom_z": vector}))},
                       {"confirm": ANYTHING, "restarted": ANYTHING, "finished": finished})
    else:
        state = record({"center": vector, "radius": FINITE, "iteration": INTEGER},
                       {"cuts": list_of(vector), "finished": finished})
    row = record({"iteration": INTEGER, "wall_time": FINITE})
    return record({"scene_hash": TEXT, "method": TEXT, "state": state, "history": list_of(row),
                   "builds": INTEGER, "build_time": FINITE, "solve_time": FINITE},
                  {"reused": INTEGER, "basis_reuses": INTEGER, "build_records": list_of(ANYTHING),
                   "basis_center": optional(shape)})


def load_checkpoint(path: Path, dimension: int, method: str, shapes: int | None = None) -> dict:
    """checkpoint.json, checked against :func:`checkpoint_schema` (nothing is written before)."""
    return load_json(path, checkpoint_schema(dimension, method, shapes), "checkpoint", "start without --resume")


def budget_front_schema(shape_names: list[str]) -> record:
    """budget_front.json of a budget front: the pareto.csv rows of the budgets done so far, each with
    its budget and optimum (``xi_<name>`` of each shape, the amplitude), for the scene of ``scene_hash``."""
    optimum = {f"xi_{name}": FINITE for name in shape_names}
    return record({"scene_hash": TEXT,
                   "rows": list_of(record({"budget": FINITE, "amplitude": FINITE, **optimum}))})


def load_budget_front(path: Path, shape_names: list[str]) -> dict:
    """budget_front.json, checked against :func:`budget_front_schema` (nothing is written before)."""
    return load_json(path, budget_front_schema(shape_names), "budget front checkpoint", "run without --resume")


def optimization_summary_schema(names: list[str]) -> record:
    """summary.json of an optimisation over the design variables ``names``: a completed run, or
    one stopped early (``completed`` false, with its stop reason)."""
    completed = record({"optimum": record({name: FINITE for name in names}), "prom_distance_optimal": FINITE,
                        "cost_weights": record({"distance": FINITE, "energy": FINITE, "alpha": FINITE}),
                        "fom_check": record({"optimal_distance": optional(FINITE), "error": optional(TEXT)})})
    stopped = record({"stop_reason": TEXT})

    def check(value, where):
        record({"scene_hash": TEXT}, {"completed": FLAG})(value, where)
        (stopped if value.get("completed") is False else completed)(value, where)
    return check


def load_optimization_summary(path: Path, names: list[str]) -> dict:
    """summary.json of an optimisation, checked against :func:`optimization_summary_schema`."""
    return load_json(path, optimization_summary_schema(names), "optimisation summary",
                     "run without --resume into another --out")


def is_inside_name(name) -> bool:
    """A name of a file inside a folder: relative, without ``.``, ``..`` or empty parts, no NUL
    (a trailing ``/`` marks an empty folder)."""
    if not isinstance(name, str) or not name or "\0" in name or name.startswith("/"):
        return False
    parts = name[:-1].split("/") if name.endswith("/") else name.split("/")
    return all(part not in ("", ".", "..") for part in parts)


INSIDE_NAME = _scalar("a relative name inside the folder (no '..', not absolute)", is_inside_name)


def manifest_schema() -> record:
    """manifest.json of an output folder: the files the toolkit wrote there (relative names inside
    the folder), and how."""
    return record({}, {"files": list_of(INSIDE_NAME), "command": TEXT})


def load_manifest(path: Path) -> dict:
    """manifest.json, checked (``files`` a list of relative names inside its folder); a manifest
    that is a link is refused (it is never followed)."""
    if Path(path).is_symlink():
        raise InputError(f"manifest {path}: a symbolic link, not a file the toolkit wrote")
    return load_json(path, manifest_schema(), "manifest")


def run_record_schema() -> record:
    """run.json of a resumable output folder: what makes its answers (scene hash, command, model,
    options), written when the run starts and compared by ``--resume``."""
    return record({"command": TEXT, "scene_hash": TEXT})


def load_run_record(path: Path) -> dict:
    """run.json, checked (a command and a scene hash at least)."""
    return load_json(path, run_record_schema(), "run record", "run without --resume into another --out")


def load_csv_table(path: Path, columns: tuple[str, ...] | list[str], kind: str, remedy: str = "",
                   text_columns: tuple[str, ...] = (), optional_columns: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """A CSV file with a header holding ``columns`` (others allowed) and at least one row; numbers
    in every column but ``text_columns`` (an empty cell is NaN); ``optional_columns`` read too when present."""
    path = Path(path)
    text = read_text_file(path, kind, MAX_READBACK_BYTES, remedy)
    remedy = f"; {remedy}" if remedy else ""
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as error:
        raise InputError(f"{kind} {path}: not a CSV file ({error}){remedy}") from None
    if not rows:
        raise InputError(f"{kind} {path}: empty (no header {','.join(columns)}){remedy}")
    header = rows[0]
    missing = [name for name in columns if name not in header]
    if missing:
        raise InputError(f"{kind} {path}: the header lacks {', '.join(missing)} (needs {','.join(columns)}){remedy}")
    body = [row for row in rows[1:] if row]
    if not body:
        raise InputError(f"{kind} {path}: no rows after the header{remedy}")
    table = {}
    for name in [*columns, *(name for name in optional_columns if name in header)]:
        index = header.index(name)
        values = []
        for number, row in enumerate(body, start=2):
            cell = row[index] if index < len(row) else None
            if cell is None:
                raise InputError(f"{kind} {path}: line {number} has {len(row)} cells, not {len(header)}{remedy}")
            if name in text_columns:
                values.append(cell)
                continue
            try:
                values.append(float(cell) if cell != "" else math.nan)
            except ValueError:
                raise InputError(f"{kind} {path}: line {number}, column {name}: {cell[:30]!r} is not a number"
                                 f"{remedy}") from None
        table[name] = np.array(values, dtype=object if name in text_columns else float)
    return table


def load_trajectory(path: Path) -> dict[str, np.ndarray]:
    """trajectory.csv of a run: time [s], head x, tail y, centre-of-mass x [m], tail x and centre-of-mass y [m]
    when the file has them (a run written before they existed does not), Newton iterations; finite values,
    times increasing."""
    remedy = "rerun `aquarom simulate` into this folder with --force"
    optional = [TRAJECTORY_FILE_COLUMNS[name] for name in OPTIONAL_TRAJECTORY_COLUMNS]
    file_columns = [TRAJECTORY_FILE_COLUMNS[name] for name in TRAJECTORY_COLUMNS if name not in OPTIONAL_TRAJECTORY_COLUMNS]
    table = load_csv_table(path, file_columns, "trajectory", remedy, optional_columns=tuple(optional))
    for name, values in table.items():
        if not np.all(np.isfinite(values)):
            raise InputError(f"trajectory {path}: column {name} holds empty or non-finite values; {remedy}")
    if np.any(np.diff(table[TRAJECTORY_FILE_COLUMNS["time"]]) <= 0):
        raise InputError(f"trajectory {path}: the times do not increase; {remedy}")
    return {name: table[TRAJECTORY_FILE_COLUMNS[name]] for name in TRAJECTORY_COLUMNS
            if TRAJECTORY_FILE_COLUMNS[name] in table}


def read_trajectory_csv(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a trajectory.csv by the names of ``Trajectory`` (time [s], head_x, tail_y, com_x [m]),
    checked by :func:`load_trajectory`."""
    return load_trajectory(path)
