"""The design's body for fabrication and other solvers: closed STL surfaces and tagged volume meshes.

The body is the design mesh x_0 + U ξ: the mesh's vertices moved by the shape displacement and
its linear tetrahedra (at degree 2 the edge midpoints are nodes of the FOM, not of the geometry,
whose cells stay straight-sided tetrahedra). Its surface is the boundary of all cells; a region's
surface (``--regions``) is the boundary of the region's cells, so an interface between two regions
belongs to both, oppositely oriented. The regions are the mesh's tagged cell sets: the scene's head,
each muscle it drives and the passive body (the cells of neither).

Files carry the mark :data:`EXPORT_MARK` (the STL header, a comment in .msh and .vtu), by which
``--force`` tells a file it may replace.
"""
from __future__ import annotations

import re
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.geometry.mesh import signed_cell_volumes
from aquarom_fenics.geometry.surface import Surface, boundary_surface, surface_problem, tetrahedra_volume
from aquarom_fenics.geometry.tags import is_tagged

UNITS = {"mm": 1000.0, "m": 1.0}
"""Length units of the files and the factor from metres."""

EXPORT_MARK = "aquarom export"
SUFFIXES = (".stl", ".msh", ".vtu")
PASSIVE = "passive"
"""Name of the cells in no tagged region of the scene (the passive body)."""

_STL_RECORD = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])


@dataclass(frozen=True)
class DesignBody:
    """The design mesh: vertex positions [m], positively oriented tetrahedra and named cell sets."""

    points: np.ndarray
    cells: np.ndarray
    regions: dict[str, np.ndarray]

    @property
    def volume(self) -> float:
        """Σ of the tetrahedra's volumes [m³]."""
        return tetrahedra_volume(self.points, self.cells)


def design_body(scene, fish, xi: dict[str, float]) -> DesignBody:
    """The design mesh of ``xi`` (``fish.design``: the checked shape-varied nodes, vertices first) with
    the scene's regions; InputError for a design that turns a tetrahedron inside out."""
    points = fish.design(xi)[:fish.mesh.points.shape[0]]
    cells = np.asarray(fish.mesh.cells, dtype=np.int64)
    inverted = signed_cell_volumes(points, cells) <= 0.0
    if inverted.any():
        where = fish.tags.box.relative(fish.mesh.points[cells[np.flatnonzero(inverted)[0]]].mean(axis=0))[0]
        raise InputError(f"design: {int(inverted.sum())} tetrahedra of the design mesh x_0 + U ξ are inverted or flat "
                         f"(the first near x, y, z = {where[0]:.4g}, {where[1]:.4g}, {where[2]:.4g} m from the head "
                         "face's centre): its straight-sided cells fold, so it has no surface to export; "
                         "move the design away from its bounds or use a coarser mesh")
    return DesignBody(points, cells, scene_regions(scene, fish))


def scene_regions(scene, fish) -> dict[str, np.ndarray]:
    """{name: cells}: the head, each driven muscle (the scene's region names) and the passive body,
    from the mesh's tagged regions; {} for a mesh without them (its regions are chosen by centroid,
    which is no geometry to cast)."""
    head = scene.regions.head
    muscles = tuple(muscle.region for muscle in scene.actuated_muscles)
    if not is_tagged(fish.mesh, (head, *muscles)):
        return {}
    regions = {head: np.asarray(fish.tags.head_cells)} | dict(zip(muscles, map(np.asarray, fish.tags.muscle_cells)))
    taken = np.zeros(len(fish.mesh.cells), dtype=bool)
    for cells in regions.values():
        taken[cells] = True
    passive = PASSIVE if PASSIVE not in regions else f"{PASSIVE}_body"
    if not taken.all():
        regions[passive] = np.flatnonzero(~taken)
    return regions


def checked_surface(points: np.ndarray, cells: np.ndarray, what: str) -> Surface:
    """The boundary of ``cells`` after the checks of :func:`surface_problem`; InputError (the mesh or
    design is at fault) or SolverError (the volume does not add up) naming ``what``."""
    surface = boundary_surface(points, cells)
    problem = surface_problem(surface, tetrahedra_volume(points, cells))
    if problem is None:
        return surface
    kind, why = problem
    raise (SolverError if kind == "volume" else InputError)(f"{what}: surface {why}; nothing written")


def region_file_names(names) -> dict[str, str]:
    """{region: file name ``NAME.stl``} with characters other than letters, digits, ``-`` and ``_``
    replaced by ``_``; InputError when two regions end with the same name."""
    files = {name: re.sub(r"[^A-Za-z0-9_-]", "_", name) + ".stl" for name in names}
    if len(set(files.values())) != len(files):
        raise InputError(f"--regions: the regions {', '.join(names)} do not give distinct file names")
    return files


def stl_bytes(surface: Surface, units: str) -> bytes:
    """Binary STL of ``surface`` (given in metres) in ``units``: an 80-byte header with the mark, the
    number of triangles (uint32), and per triangle its unit normal and vertices (float32) and 0 (uint16)."""
    scaled = surface.scaled(UNITS[units])
    records = np.zeros(len(scaled.triangles), dtype=_STL_RECORD)
    records["normal"] = scaled.normals
    records["vertices"] = scaled.points[scaled.triangles]
    header = f"{EXPORT_MARK}: binary STL, {units}, outward normals".encode().ljust(80, b" ")
    return header + struct.pack("<I", len(records)) + records.tobytes()


def read_stl(data: bytes) -> tuple[str, np.ndarray, np.ndarray]:
    """(header, (m, 3) normals, (m, 3, 3) vertices) of a binary STL; ValueError when the size does
    not match the count."""
    if len(data) < 84:
        raise ValueError("shorter than a binary STL header")
    count = struct.unpack("<I", data[80:84])[0]
    if len(data) != 84 + count * _STL_RECORD.itemsize:
        raise ValueError(f"{len(data)} bytes for {count} triangles")
    records = np.frombuffer(data, dtype=_STL_RECORD, offset=84, count=count)
    return data[:80].decode("ascii", "replace").rstrip(), records["normal"].astype(float), \
        records["vertices"].astype(float)


def volume_mesh_bytes(body: DesignBody, units: str, suffix: str) -> bytes:
    """The tagged volume mesh in ``units`` as a gmsh 2.2 ASCII ``.msh`` (one volume physical group per
    region, named) or a VTK XML ``.vtu`` (cell data ``region``, its names in the field data as
    ``name: [tag, 3]``); tags 1, 2, … in the order of ``body.regions``, 0 for a mesh without regions."""
    from xml.sax.saxutils import quoteattr

    import meshio

    tags = np.zeros(len(body.cells), dtype=np.int32)
    field_data = {}
    for tag, (name, cells) in enumerate(body.regions.items(), start=1):
        tags[cells] = tag
        field_data[name] = np.array([tag, 3])
    points = body.points * UNITS[units]
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"body{suffix}"
        if suffix == ".msh":
            mesh = meshio.Mesh(points, [("tetra", body.cells)], field_data=field_data,
                               cell_data={"gmsh:physical": [tags], "gmsh:geometrical": [tags]})
            meshio.write(path, mesh, file_format="gmsh22", binary=False)
            text = path.read_text()
            marker = f"$Comments\n{EXPORT_MARK}: {units}\n$EndComments\n"
            return text.replace("$EndMeshFormat\n", "$EndMeshFormat\n" + marker, 1).encode()
        mesh = meshio.Mesh(points, [("tetra", body.cells)], field_data=field_data, cell_data={"region": [tags]})
        meshio.write(path, mesh, file_format="vtu")
        data = path.read_bytes()
    first, _, rest = data.partition(b"\n")
    names = "".join(f'<DataArray type="Int32" Name={quoteattr(name)} NumberOfComponents="2" format="ascii">'
                    f"{value[0]} {value[1]}</DataArray>\n" for name, value in field_data.items())
    rest = rest.replace(b"<UnstructuredGrid>\n", f"<UnstructuredGrid>\n<FieldData>\n{names}</FieldData>\n".encode(), 1)
    return first + f"\n<!-- {EXPORT_MARK}: {units} -->\n".encode() + rest


def is_export_file(path: Path) -> bool:
    """A file written by the export (its first 4 kB carry :data:`EXPORT_MARK`)."""
    try:
        with open(path, "rb") as stream:
            return EXPORT_MARK.encode() in stream.read(4096)
    except OSError:
        return False


def bounding_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners of the points."""
    return points.min(axis=0), points.max(axis=0)


def write_design_stl(scene, fish, xi: dict[str, float], path: Path, units: str = "mm") -> Path | None:
    """Write the checked body surface of the design ``xi`` to ``path`` (binary STL in ``units``, atomically);
    a design whose surface fails a check is logged as a warning and not written (None)."""
    import logging

    from aquarom_fenics.io.persistence import write_bytes_atomic

    try:
        body = design_body(scene, fish, xi)
        surface = checked_surface(body.points, body.cells, f"design {path.name}")
    except (InputError, SolverError) as problem:
        logging.getLogger("aquarom").warning("%s not written: %s", path, problem)
        return None
    write_bytes_atomic(path, stl_bytes(surface, units))
    return path
