"""Tetrahedral meshes read from files: gmsh ``.msh`` and Abaqus ``.inp`` (C3D4)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh import (FishMesh, mean_edge_length, oriented_positively, signed_cell_volumes,
                                           used_nodes_only)


_GMSH_READ_OPTIONS = {"General.Terminal": 0, "General.NumThreads": 1}


def _check_transform(path: Path, scale, translate) -> tuple[float, np.ndarray]:
    """(scale, translate) as a float and a (3,) array, or InputError."""
    try:
        factor = float(scale)
    except (TypeError, ValueError):
        factor = np.nan
    if not (np.isfinite(factor) and factor > 0.0):
        raise InputError(f"mesh file {path}: scale = {scale!r}; it must be a positive number")
    try:
        shift = np.asarray(translate, dtype=float)
    except (TypeError, ValueError):
        shift = np.full(1, np.nan)
    if shift.shape != (3,) or not np.all(np.isfinite(shift)):
        raise InputError(
            f"mesh file {path}: translate = {translate!r}; it must be three numbers (m)"
        )
    return factor, shift


def _read_gmsh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        with gmsh_model("aquarom_read", _GMSH_READ_OPTIONS) as gmsh:
            gmsh.merge(str(path))
            node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
            _, element_nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON)
    except Exception as error:
        raise InputError(f"mesh file {path}: gmsh cannot read it ({error})") from None
    if len(element_nodes) == 0:
        raise InputError(
            f"mesh file {path}: contains no linear tetrahedra (gmsh element type 4); "
            "mesh the volume with first-order tetrahedra"
        )
    try:
        return points_and_cells_from_gmsh(node_tags, coordinates, element_nodes)
    except ValueError as error:
        raise InputError(f"mesh file {path}: {error}") from None


def _keyword_line(line: str) -> tuple[str, dict[str, str]]:
    """('*element', {'type': 'C3D4', ...}) from '*Element, type=C3D4, ...'."""
    name, *parameters = [part.strip() for part in line.split(",")]
    options = {}
    for parameter in parameters:
        key, _, value = parameter.partition("=")
        options[key.strip().lower()] = value.strip()
    return name.lower(), options


_ABAQUS_RECORD_LENGTH = {"node": 4, "tetrahedron": 5}
"""Values per record: 'label, x, y, z' and 'label, n1, n2, n3, n4'."""


def _abaqus_records(path: Path, text: str):
    """(section, values, line_number) per data record of *Node and *Element, type=C3D4 sections.

    A record may continue over several lines until it has its number of values. Other sections
    are skipped.
    """
    section = None
    pending: list[str] = []
    for line_number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            if pending:
                raise InputError(
                    f"mesh file {path}, line {line_number}: the record before this keyword is "
                    f"incomplete ({', '.join(pending)})"
                )
            keyword, options = _keyword_line(line)
            section = None
            if keyword == "*node":
                section = "node"
            elif keyword == "*element" and options.get("type", "").upper() == "C3D4":
                section = "tetrahedron"
            continue
        if section is None:
            continue
        pending.extend(value.strip() for value in line.rstrip(",").split(","))
        if len(pending) >= _ABAQUS_RECORD_LENGTH[section]:
            yield section, pending, line_number
            pending = []
    if pending:
        raise InputError(f"mesh file {path}: the file ends inside a record ({', '.join(pending)})")


def _label(text: str) -> int:
    """A node or element label: a whole number in [0, 2^62] (ValueError otherwise)."""
    label = int(text)
    if not 0 <= label <= MAX_LABEL:
        raise ValueError(text)
    return label


def _parse_abaqus(path: Path, text: str):
    """(node labels, node coordinates, tetrahedra as node labels) of an Abaqus input file."""
    node_labels, node_coordinates, tetrahedra = [], [], []
    for section, values, line_number in _abaqus_records(path, text):
        try:
            if len(values) != _ABAQUS_RECORD_LENGTH[section]:
                raise ValueError
            if section == "node":
                node_labels.append(_label(values[0]))
                node_coordinates.append([float(value) for value in values[1:]])
            else:
                tetrahedra.append([_label(value) for value in values[1:]])
        except ValueError:
            kind = "'label, x, y, z'" if section == "node" else "'label, n1, n2, n3, n4'"
            raise InputError(
                f"mesh file {path}, line {line_number}: cannot read {', '.join(values)!r} "
                f"as {kind}"
            ) from None
    return (
        np.array(node_labels, dtype=np.int64),
        np.array(node_coordinates, dtype=float).reshape(-1, 3),
        np.array(tetrahedra, dtype=np.int64).reshape(-1, 4),
    )


MAX_MESH_FILE_BYTES = 2 * 1024 ** 3
"""Largest mesh file read [bytes]."""
MAX_LABEL = 2 ** 62
"""Largest node or element label of an Abaqus file (they are stored as 64-bit integers)."""


def _read_abaqus(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"mesh file {path}: cannot read it as text ({error})") from None
    labels, coordinates, tetrahedra = _parse_abaqus(path, text)
    if len(labels) == 0:
        raise InputError(f"mesh file {path}: no *Node section; expected an Abaqus input file")
    if len(tetrahedra) == 0:
        raise InputError(
            f"mesh file {path}: no *Element, type=C3D4 section; expected linear tetrahedra"
        )
    sorted_labels, first_positions = np.unique(labels, return_index=True)
    if len(sorted_labels) < len(labels):
        raise InputError(f"mesh file {path}: node labels are not unique")
    position = np.clip(np.searchsorted(sorted_labels, tetrahedra), 0, len(sorted_labels) - 1)
    undefined = sorted_labels[position] != tetrahedra
    if np.any(undefined):
        raise InputError(
            f"mesh file {path}: an element refers to the undefined node {tetrahedra[undefined][0]}"
        )
    return used_nodes_only(coordinates[first_positions], position)


_MESH_READERS = {".msh": _read_gmsh, ".inp": _read_abaqus}


def read_mesh(path, scale: float = 1.0, translate=(0.0, 0.0, 0.0)) -> FishMesh:
    """Read a gmsh `.msh` or Abaqus `.inp` (C3D4) tetrahedral mesh.

    Points become `points * scale + translate` (m); only nodes used by tetrahedra are kept and
    every tetrahedron is oriented positively. Abaqus: the `*Node` and `*Element, type=C3D4`
    data of the file are read as they stand (labels may be sparse; part instance placements
    and all other keywords are ignored).
    """
    path = Path(path)
    factor, shift = _check_transform(path, scale, translate)
    reader = _MESH_READERS.get(path.suffix.lower())
    if reader is None:
        raise InputError(
            f"mesh file {path}: unsupported suffix {path.suffix!r}; use a gmsh .msh or an "
            "Abaqus .inp file"
        )
    from aquarom_fenics.io.readback import require_regular_file

    require_regular_file(path, "mesh file", MAX_MESH_FILE_BYTES)
    points, cells = reader(path)
    points = points * factor + shift
    if not np.all(np.isfinite(points)):
        raise InputError(f"mesh file {path}: non-finite node coordinates")
    volumes = np.abs(signed_cell_volumes(points, cells))
    degenerate = volumes <= 1e-12 * mean_edge_length(points, cells) ** 3
    if np.any(degenerate):
        first = int(np.flatnonzero(degenerate)[0]) + 1
        raise InputError(
            f"mesh file {path}: {int(degenerate.sum())} tetrahedra have zero volume "
            f"(the first is tetrahedron number {first} of the file)"
        )
    return FishMesh(points=points, cells=oriented_positively(points, cells), source=str(path))
