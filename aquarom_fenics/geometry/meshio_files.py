"""Tetrahedral meshes and their regions from the other formats meshers export, read by meshio:
VTK XML ``.vtu``, Salome ``.med`` and Exodus II ``.e``/``.exo`` (SPEC §3).

Each reader returns (points, cells, regions) as ``mesh_files`` expects them: the first-order
tetrahedra in file order, and {region name: indices of those tetrahedra}.

- ``.vtu``: the regions are the values of an integer cell-data array (the first present of
  :data:`REGION_ARRAYS`, or the only integer array), each named by the file's field data
  (``name: [value, 3]`` as gmsh writes it, or ``name: [value]``) or by its value as text; an
  unnamed 0 marks the cells of no region.
- ``.med``: the regions are the groups of the cells' families (meshio's ``cell_tags``); a family
  without a group is named by its number as text, family 0 (no family) is no region.
- Exodus: the regions are the element blocks of tetrahedra, named by their position in the file
  (``"1"``, ``"2"``, …; meshio does not read the blocks' names). Reading needs netCDF4.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.mesh import used_nodes_only
from aquarom_fenics.geometry.mesh_checks import other_volume_cells

REGION_ARRAYS = ("gmsh:physical", "CellEntityIds", "region", "regions", "medit:ref")
"""Names of the integer cell-data array that holds a .vtu file's regions, in order of preference."""

EXODUS_SUFFIXES = (".e", ".exo")


def _read_with(path: Path, module, format_name: str):
    """meshio's reader of one format (``meshio.read`` prints and exits on some errors); InputError
    naming the format and the cause when it fails or a package it needs is missing."""
    try:
        return module.read(str(path))
    except ImportError as error:
        package = error.name or str(error)
        raise InputError(f"mesh file {path}: reading {format_name} with meshio needs the Python package "
                         f"{package}, which is not installed (Debian: python3-{package.lower()})") from None
    except Exception as error:
        problem = str(error).strip() or type(error).__name__
        raise InputError(f"mesh file {path}: meshio cannot read it as {format_name} ({problem})") from None


_VOLUME_KINDS = ("tetra", "hexahedron", "wedge", "pyramid", "vtk_lagrange_tetrahedron", "vtk_lagrange_hexahedron",
                 "vtk_lagrange_wedge", "vtk_lagrange_pyramid")
"""Beginnings of the names of meshio's volume cell types (tetra10, hexahedron20, wedge15, … included)."""


def refuse_other_volume_cells(path: Path, mesh, blocks: list[int]) -> None:
    """InputError naming the volume cells other than first-order tetrahedra beside the tetrahedra of
    ``blocks`` (``mesh_checks.other_volume_cells``)."""
    others: dict[str, int] = {}
    for block in mesh.cells:
        if block.type != "tetra" and block.type.lower().startswith(_VOLUME_KINDS):
            others[block.type] = others.get(block.type, 0) + len(block.data)
    error = other_volume_cells(path, sum(len(mesh.cells[index].data) for index in blocks), others)
    if error is not None:
        raise error


def _tetra_blocks(path: Path, mesh) -> list[int]:
    """Indices of the mesh's blocks of first-order tetrahedra; InputError when there are none, or when
    there are volume cells of other types beside them."""
    blocks = [index for index, block in enumerate(mesh.cells) if block.type == "tetra"]
    if blocks:
        refuse_other_volume_cells(path, mesh, blocks)
        return blocks
    kinds = sorted({block.type for block in mesh.cells})
    if "tetra10" in kinds:
        raise InputError(f"mesh file {path}: its tetrahedra are second-order (10 nodes); export first-order "
                         "tetrahedra (the FOM makes its own quadratic nodes with [mesh] degree = 2)")
    raise InputError(f"mesh file {path}: contains no first-order tetrahedra (cells found: "
                     f"{', '.join(kinds) or 'none'}); mesh the volume with 4-node tetrahedra")


def _points_and_cells(path: Path, mesh, blocks: list[int]) -> tuple[np.ndarray, np.ndarray]:
    points = np.asarray(mesh.points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"mesh file {path}: its nodes have {points.shape[-1]} coordinates; expected x, y, z")
    cells = np.vstack([np.asarray(mesh.cells[index].data, dtype=np.int64) for index in blocks])
    return used_nodes_only(points, cells)


def _regions_from_values(values: np.ndarray, names: dict[int, list[str]]) -> dict[str, np.ndarray]:
    """{name: cells} from one integer per cell; a value names the regions ``names[value]``, or is
    the region of its number as text."""
    regions: dict[str, list[np.ndarray]] = {}
    for value in np.unique(values):
        cells = np.flatnonzero(values == value)
        for name in names.get(int(value), [str(int(value))]):
            regions.setdefault(name, []).append(cells)
    return {name: np.unique(np.concatenate(parts)) for name, parts in regions.items()}


def _cell_values(mesh, name: str, blocks: list[int]) -> np.ndarray:
    return np.concatenate([np.asarray(mesh.cell_data[name][index]).reshape(-1) for index in blocks])


def _region_array(path: Path, mesh, blocks: list[int]) -> str | None:
    """The name of the .vtu cell-data array holding the regions, or None when it has none."""
    def integral(name):
        values = _cell_values(mesh, name, blocks)
        return values.size == sum(len(mesh.cells[index].data) for index in blocks) and (
            np.issubdtype(values.dtype, np.integer)
            or (name in REGION_ARRAYS and np.all(np.isfinite(values)) and np.all(values == np.round(values))))

    candidates = [name for name in mesh.cell_data if integral(name)]
    for name in REGION_ARRAYS:
        if name in mesh.cell_data:
            if name not in candidates:
                raise InputError(f"mesh file {path}: cell data '{name}' does not hold one integer per cell; "
                                 "expected region numbers")
            return name
    if len(candidates) > 1:
        raise InputError(f"mesh file {path}: several integer cell-data arrays ({', '.join(candidates)}) and none "
                         f"named as a region array; name the regions' array one of {', '.join(REGION_ARRAYS)}")
    return candidates[0] if candidates else None


def _field_data_names(field_data: dict) -> dict[int, list[str]]:
    """{value: [name]} from field data ``name: [value, dimension]`` (dimension 3) or ``name: [value]``."""
    names: dict[int, list[str]] = {}
    for name, data in field_data.items():
        data = np.asarray(data).reshape(-1)
        if data.size == 1 or (data.size == 2 and int(data[1]) == 3):
            names.setdefault(int(data[0]), []).append(str(name))
    return names


def read_vtu(path: Path):
    """(points, cells, regions) of a VTK XML unstructured grid (.vtu)."""
    from meshio import vtu

    mesh = _read_with(path, vtu, "a VTK XML unstructured grid (.vtu)")
    blocks = _tetra_blocks(path, mesh)
    points, cells = _points_and_cells(path, mesh, blocks)
    array = _region_array(path, mesh, blocks)
    if array is None:
        return points, cells, {}
    values = np.round(_cell_values(mesh, array, blocks)).astype(np.int64)
    names = _field_data_names(mesh.field_data or {})
    regions = _regions_from_values(values, names)
    if 0 not in names:
        regions.pop("0", None)        # 0 marks the cells of no region (gmsh: no physical group)
    return points, cells, regions


def read_med(path: Path):
    """(points, cells, regions) of a Salome MED file (.med): the groups of the cells' families."""
    from meshio import med

    mesh = _read_with(path, med, "a MED file (.med)")
    blocks = _tetra_blocks(path, mesh)
    points, cells = _points_and_cells(path, mesh, blocks)
    if "cell_tags" not in mesh.cell_data:
        return points, cells, {}
    families = _cell_values(mesh, "cell_tags", blocks).astype(np.int64)
    groups = {int(family): [str(name) for name in names] for family, names in getattr(mesh, "cell_tags", {}).items()}
    regions = _regions_from_values(families, groups)
    regions.pop("0", None)
    return points, cells, regions


def read_exodus(path: Path):
    """(points, cells, regions) of an Exodus II file (.e, .exo): its element blocks of tetrahedra."""
    from meshio import exodus

    mesh = _read_with(path, exodus, "an Exodus II file")
    blocks = _tetra_blocks(path, mesh)
    points, cells = _points_and_cells(path, mesh, blocks)
    sizes = [len(mesh.cells[index].data) for index in blocks]
    starts = np.cumsum([0] + sizes[:-1])
    regions = {str(index + 1): np.arange(start, start + size) for index, start, size in zip(blocks, starts, sizes)}
    return points, cells, regions


MESHIO_READERS = {".vtu": read_vtu, ".med": read_med} | {suffix: read_exodus for suffix in EXODUS_SUFFIXES}
"""The meshio readers by file suffix (lower case)."""
