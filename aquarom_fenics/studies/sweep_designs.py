"""The designs of a sweep: the rows of a CSV file, a grid or a seeded Latin hypercube over the scene's
bounds, each a value per design variable of the scene, its shapes then its ``[gait]`` variables
(:func:`variables`; a variable a source does not set keeps its start value). At most :data:`MAX_DESIGNS`
designs, checked before any is made."""
from __future__ import annotations

import csv
import io
import itertools
import math
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file
from aquarom_fenics.io.command_values import parse_number
from aquarom_fenics.io.scene import Scene

MAX_DESIGNS = 100_000
"""Most designs of one sweep (a grid's product or --samples), checked before any is made."""
MAX_DESIGN_FILE_BYTES = 64 * 1024 * 1024
"""Largest --designs file [bytes]."""


def variables(scene: Scene) -> tuple:
    """The sweep's design variables: the scene's shapes, then its ``[gait]`` variables (io/scene_gait.py),
    each with its name, bounds and start."""
    return (*scene.shapes, *scene.gait)


def variable_names(scene: Scene) -> list[str]:
    """The names of :func:`variables`: a design's keys and sweep.csv's columns."""
    return [variable.name for variable in variables(scene)]


def _require_shapes(scene: Scene) -> None:
    if not variables(scene):
        raise InputError(f"scene {scene.source} has no [shapes] or [gait] variables: there is no design space to sweep")
    shared = set(scene.shape_names) & set(scene.gait_names)
    if shared:
        raise InputError(f"scene {scene.source}: '{sorted(shared)[0]}' names both a shape and a [gait] variable; "
                         "a sweep's columns need distinct names")


def _complete(scene: Scene, values: dict[str, float]) -> dict[str, float]:
    """Every design variable of the scene, in its order: the given values, else the start values."""
    return {variable.name: float(values.get(variable.name, variable.start)) for variable in variables(scene)}


def grid_designs(specs: list[str], scene: Scene) -> list[dict[str, float]]:
    """The Cartesian product of ``name=lo:hi:n`` axes (n evenly spaced values from lo to hi)."""
    _require_shapes(scene)
    axes = {}
    for spec in specs:
        where = f"--grid {spec}"
        name, sep, interval = spec.partition("=")
        parts = interval.split(":")
        if not sep or len(parts) != 3:
            raise InputError(f"{where}: expected name=lo:hi:n, e.g. --grid z_tail=-0.5:0.5:5")
        name = name.strip()
        if name not in variable_names(scene):
            raise InputError(f"{where}: '{name}' is not a shape variation or [gait] variable of scene {scene.name} "
                             f"(valid: {', '.join(variable_names(scene))})")
        if name in axes:
            raise InputError(f"{where}: {name} is given twice; give each variable one --grid")
        low, high = parse_number(parts[0], where), parse_number(parts[1], where)
        try:
            count = int(parts[2])
        except ValueError:
            raise InputError(f"{where}: n = '{parts[2]}' must be a whole number of values ≥ 1") from None
        if count < 1:
            raise InputError(f"{where}: n = {count} must be ≥ 1")
        if count == 1 and low != high:
            raise InputError(f"{where}: one value (n = 1) needs lo = hi")
        total = count * math.prod(len(values) for values in axes.values())
        if total > MAX_DESIGNS:
            raise InputError(f"{where}: the grid would hold {total:,} designs, more than {MAX_DESIGNS:,}; "
                             "use fewer values per axis, or split the sweep")
        axes[name] = np.linspace(low, high, count).tolist()
    names = list(axes)
    return [_complete(scene, dict(zip(names, values))) for values in itertools.product(*axes.values())]


def csv_designs(path: Path, scene: Scene) -> list[dict[str, float]]:
    """The rows of a CSV file whose header names design variables of the scene (each at most once)."""
    _require_shapes(scene)
    text = read_text_file(path, "--designs", MAX_DESIGN_FILE_BYTES)      # a byte-order mark is allowed
    try:
        rows = _bounded_rows(csv.reader(io.StringIO(text, newline="")), path)
    except csv.Error as error:
        raise InputError(f"--designs {path}: not a CSV file ({error})") from None
    if len(rows) < 2:
        raise InputError(f"--designs {path}: needs a header of variable names and at least one row of values")
    header = [cell.strip() for cell in rows[0]]
    for name in header:
        if name not in variable_names(scene):
            raise InputError(f"--designs {path}: column '{name}' is not a shape variation or [gait] variable of "
                             f"scene {scene.name} (valid: {', '.join(variable_names(scene))})")
        if header.count(name) > 1:
            raise InputError(f"--designs {path}: column '{name}' appears twice")
    designs = []
    for number, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise InputError(f"--designs {path}: line {number} has {len(row)} values for {len(header)} columns")
        designs.append(_complete(scene, {name: parse_number(cell.strip(), f"--designs {path} line {number} column {name}")
                                         for name, cell in zip(header, row)}))
    return designs


def _bounded_rows(reader, path: Path) -> list[list[str]]:
    """The non-blank rows of ``reader``, a header and at most :data:`MAX_DESIGNS` more; InputError
    (one line) as soon as there are more, before the rest of the file is read."""
    rows = []
    for row in reader:
        if any(cell.strip() for cell in row):
            rows.append(row)
            if len(rows) > MAX_DESIGNS + 1:
                raise InputError(f"--designs {path}: more than {MAX_DESIGNS:,} designs (a header and one row "
                                 "per design); split the file into several sweeps")
    return rows


def latin_hypercube(scene: Scene, samples: int, seed: int) -> list[dict[str, float]]:
    """``samples`` designs of a Latin hypercube over the scene's bounds: in every variable's range each
    of the ``samples`` equal strata holds one design (uniform inside its stratum); numpy's PCG64
    generator seeded with ``seed``."""
    _require_shapes(scene)
    if not 1 <= samples <= MAX_DESIGNS:
        raise InputError(f"--samples {samples}: must be in [1, {MAX_DESIGNS:,}]")
    if seed < 0:
        raise InputError(f"--seed {seed}: must be ≥ 0")
    generator = np.random.default_rng(seed)
    columns = []
    for variable in variables(scene):
        strata = generator.permutation(samples)
        unit = (strata + generator.random(samples)) / samples
        columns.append(variable.lower + unit * (variable.upper - variable.lower))
    return [_complete(scene, {variable.name: float(column[k]) for variable, column in zip(variables(scene), columns)})
            for k in range(samples)]


def driven(scene: Scene, design: dict) -> tuple[Scene, dict]:
    """The scene driven by the design's ``[gait]`` values (``apply_gait``; the scene itself without
    them) and the design's shape values: what a model runs. InputError where the gait is refused
    (a period of too few steps, a pair's stress above the fibre stiffness)."""
    shapes = {name: design[name] for name in scene.shape_names}
    if not scene.gait:
        return scene, shapes
    from aquarom_fenics.io.scene_gait import apply_gait

    return apply_gait(scene, {name: design[name] for name in scene.gait_names}), shapes
