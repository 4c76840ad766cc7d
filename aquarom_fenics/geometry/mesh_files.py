"""Tetrahedral meshes and their regions read from files: gmsh ``.msh`` (gmsh's own reader),
Abaqus ``.inp`` (C3D4, meshio) and, with meshio too, ``.vtu``, ``.med`` and Exodus ``.e``/``.exo``
(``meshio_files``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh_checks import check_solid, other_volume_cells, transformed_points
from aquarom_fenics.geometry.meshio_files import MESHIO_READERS, refuse_other_volume_cells
from aquarom_fenics.geometry.mesh import (FishMesh, mean_edge_length, oriented_positively, signed_cell_volumes,
                                           used_nodes_only)
from aquarom_fenics.io.readback import MAX_MESH_FILE_BYTES, require_regular_file


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


GMSH_QUADRATIC_TETRAHEDRON = 11
"""gmsh element type of the 10-node (second-order) tetrahedron."""


def _group_name(gmsh, dim: int, tag: int) -> str:
    """A physical group's name, or its number as text when it has none."""
    return gmsh.model.getPhysicalName(dim, tag) or str(tag)


def _gmsh_contents(gmsh):
    """(node tags, coordinates, tetrahedron tags, tetrahedron node tags, {volume group: tetrahedron
    tags}, the quoted names of the other groups, element types present, {name: count} of the volume
    elements other than linear tetrahedra) of the current gmsh model."""
    node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
    element_tags, element_nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON)
    volume_groups: dict[str, list[np.ndarray]] = {}
    other_groups = []
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = _group_name(gmsh, dim, tag)
        if dim != 3:
            other_groups.append(f"'{name}'")
            continue
        for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            tags, _ = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON, entity)
            volume_groups.setdefault(name, []).append(np.asarray(tags, dtype=np.int64))
    groups = {name: np.concatenate(parts) for name, parts in volume_groups.items()}
    element_types = set(int(kind) for kind in gmsh.model.mesh.getElementTypes())
    others = {}
    for kind in sorted(element_types - {GMSH_TETRAHEDRON}):
        name, dimension = gmsh.model.mesh.getElementProperties(kind)[:2]
        if dimension == 3:
            others[name] = len(gmsh.model.mesh.getElementsByType(kind)[0])
    return node_tags, coordinates, element_tags, element_nodes, groups, other_groups, element_types, others


def _no_tetrahedra(path: Path, groups, other_groups, element_types) -> InputError:
    """The one line for a .msh file without linear tetrahedra, naming the likely cause."""
    if GMSH_QUADRATIC_TETRAHEDRON in element_types:
        return InputError(f"mesh file {path}: its tetrahedra are second-order (gmsh element type 11); mesh with "
                          "Mesh.ElementOrder = 1 (the FOM makes its own quadratic nodes with [mesh] degree = 2)")
    if other_groups and not groups:
        return InputError(
            f"mesh file {path}: no tetrahedra: its physical groups ({', '.join(other_groups)}) are all surfaces, "
            "curves or points, and gmsh saves only the elements of physical groups; add a volume "
            "physical group for the body (gmsh.model.addPhysicalGroup(3, volume_tags), named e.g. \"body\"), "
            "or set Mesh.SaveAll = 1 before writing")
    return InputError(f"mesh file {path}: contains no linear tetrahedra (gmsh element type 4); "
                      "mesh the volume with first-order tetrahedra")


def _read_gmsh(path: Path):
    """(points, cells, regions) of a gmsh .msh file (formats 2 and 4): the linear tetrahedra in the
    order of their element tags, and every volume physical group as a region (its name, or its
    number as text when unnamed)."""
    try:
        with gmsh_model("aquarom_read", _GMSH_READ_OPTIONS) as gmsh:
            gmsh.merge(str(path))
            node_tags, coordinates, element_tags, element_nodes, groups, others, kinds, cells = _gmsh_contents(gmsh)
    except Exception as error:
        raise InputError(f"mesh file {path}: gmsh cannot read it ({error})") from None
    if len(element_tags) == 0:
        raise _no_tetrahedra(path, groups, others, kinds)
    error = other_volume_cells(path, len(element_tags), cells)
    if error is not None:
        raise error
    element_tags = np.asarray(element_tags, dtype=np.int64)
    order = np.argsort(element_tags, kind="stable")
    element_nodes = np.asarray(element_nodes, dtype=np.int64).reshape(-1, 4)[order]
    try:
        points, cells = points_and_cells_from_gmsh(node_tags, coordinates, element_nodes)
    except ValueError as error:
        raise InputError(f"mesh file {path}: {error}") from None
    sorted_tags = element_tags[order]
    regions = {name: np.searchsorted(sorted_tags, tags) for name, tags in groups.items()}
    return points, cells, regions


def _read_abaqus(path: Path):
    """(points, cells, regions) of an Abaqus .inp file read by meshio: the C3D4 elements in file
    order, and every element set (*Elset, or elset= of an *Element section) holding some of them
    as a region."""
    from meshio import abaqus    # its own reader: meshio.read() prints a ReadError and exits

    _check_abaqus_labels(path)
    try:
        mesh = abaqus.read(str(path))
    except Exception as error:
        problem = str(error).strip() or type(error).__name__
        if isinstance(error, KeyError):
            problem = f"an element or set refers to the undefined label {error}"
        raise InputError(f"mesh file {path}: meshio cannot read it as an Abaqus input file ({problem})") from None
    if len(mesh.points) == 0:
        raise InputError(f"mesh file {path}: no *Node section; expected an Abaqus input file")
    blocks = [index for index, block in enumerate(mesh.cells) if block.type == "tetra"]
    if not blocks:
        kinds = ", ".join(sorted({block.type for block in mesh.cells})) or "none"
        raise InputError(f"mesh file {path}: no *Element, type=C3D4 section (elements found: {kinds}); "
                         "expected first-order tetrahedra")
    refuse_other_volume_cells(path, mesh, blocks)
    offsets = dict(zip(blocks, np.cumsum([0] + [len(mesh.cells[index].data) for index in blocks[:-1]])))
    cells = np.vstack([np.asarray(mesh.cells[index].data, dtype=np.int64) for index in blocks])
    regions = {}
    for name, per_block in mesh.cell_sets.items():
        members = [offsets[index] + np.asarray(indices, dtype=np.int64)
                   for index, indices in enumerate(per_block) if index in offsets and len(indices)]
        if members:
            regions[name] = np.concatenate(members)
    points, cells = used_nodes_only(np.asarray(mesh.points, dtype=float), cells)
    return points, cells, regions


MAX_ABAQUS_LABEL = 2**31 - 1
"""Largest node or element label accepted in an .inp file (Abaqus labels are 32-bit integers)."""

_LABELLED_SECTIONS = ("node", "element", "nset", "elset")


def _check_abaqus_labels(path: Path) -> None:
    """InputError (one line, with the line number) for a label over :data:`MAX_ABAQUS_LABEL` in the
    data of a *Node (its first field), *Element, *Nset or *Elset section; meshio would fail on it
    with a message about C integers, or hold it where a set is generated from a range."""
    section = ""
    with open(path, encoding="utf-8", errors="replace") as stream:
        for number, line in enumerate(stream, start=1):
            text = line.strip()
            if text.startswith("*"):
                section = "" if text.startswith("**") else text[1:].split(",")[0].strip().lower()
                continue
            if section not in _LABELLED_SECTIONS:
                continue
            fields = [field.strip() for field in text.split(",")]
            for field in fields[:1] if section == "node" else fields:
                if field.isdigit() and (len(field) > 10 or int(field) > MAX_ABAQUS_LABEL):
                    raise InputError(f"mesh file {path} line {number}: label {field[:24]}{'…' if len(field) > 24 else ''} "
                                     f"is over {MAX_ABAQUS_LABEL} (labels are 32-bit integers); renumber the mesh")


def _unique_cells(cells: np.ndarray, regions: dict[str, np.ndarray]):
    """Cells without repeats (gmsh format 2 writes a tetrahedron once per physical group it is in),
    the first of each kept, and the regions as sorted indices of the kept cells."""
    _, first, inverse = np.unique(np.sort(cells, axis=1), axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    keep = np.sort(first)
    new_index = np.empty(len(first), dtype=np.int64)
    new_index[np.argsort(first)] = np.arange(len(first))
    renumber = new_index[inverse]
    return cells[keep], {name: np.unique(renumber[indices]) for name, indices in regions.items()}


_MESH_READERS = {".msh": _read_gmsh, ".inp": _read_abaqus} | MESHIO_READERS


def read_mesh(path, scale: float = 1.0, translate=(0.0, 0.0, 0.0)) -> FishMesh:
    """Read a gmsh `.msh` (formats 2 and 4, with gmsh's own reader), an Abaqus `.inp` (C3D4), a
    `.vtu`, `.med` or Exodus `.e`/`.exo` (with meshio) tetrahedral mesh and its regions.

    Points become `points * scale + translate` (m); only nodes used by tetrahedra are kept, a
    tetrahedron repeated in the file is kept once and every tetrahedron is oriented positively.
    Regions (``FishMesh.regions``): the volume physical groups of a .msh file (unnamed ones by
    their number as text), the element sets of an .inp file that hold tetrahedra, and those of
    the meshio formats as ``meshio_files`` describes (.vtu: an integer cell-data array named by the
    field data; .med: the families' groups; Exodus: the element blocks). Abaqus: the
    `*Node` and `*Element, type=C3D4` data are read as they stand (labels may be sparse; part
    instance placements are ignored).
    """
    path = Path(path)
    factor, shift = _check_transform(path, scale, translate)
    reader = _MESH_READERS.get(path.suffix.lower())
    if reader is None:
        raise InputError(
            f"mesh file {path}: unsupported suffix {path.suffix!r}; use one of {', '.join(_MESH_READERS)} "
            "(gmsh, Abaqus, VTK XML, MED, Exodus II)"
        )
    require_regular_file(path, "mesh file", MAX_MESH_FILE_BYTES)     # no FIFO, device or link loop
    points, cells, regions = reader(path)
    cells, regions = _unique_cells(cells, regions)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"mesh file {path}: its nodes have {points.shape[-1]} coordinates; expected x, y, z")
    points = transformed_points(path, points, cells, factor, shift)
    volumes = np.abs(signed_cell_volumes(points, cells))
    degenerate = volumes <= 1e-12 * mean_edge_length(points, cells) ** 3
    if np.any(degenerate):
        first = int(np.flatnonzero(degenerate)[0]) + 1
        raise InputError(
            f"mesh file {path}: {int(degenerate.sum())} tetrahedra have zero volume "
            f"(the first is tetrahedron number {first} of the file)"
        )
    check_solid(path, points, cells)
    return FishMesh(points=points, cells=oriented_positively(points, cells), source=str(path), regions=regions)
