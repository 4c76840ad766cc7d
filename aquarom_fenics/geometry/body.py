"""The body a mesh describes: its length within the range of swimmers, its axis and head end (turned
into the swimming frame: along x, head at +x), and a summary (length, volume, region volumes, element count) for ``aquarom mesh`` and every dry run.
"""

from __future__ import annotations

import logging

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.mesh import FishMesh, oriented_positively, signed_cell_volumes


log = logging.getLogger("aquarom")

LENGTH_RANGE = (1e-3, 5.0)
"""Lengths along x [m] of the bodies accepted: 1 mm to 5 m (a mesh outside is in other units)."""


def check_body_length(length: float, source: str, block: bool = False, axis: str = "x") -> None:
    """InputError unless LENGTH_RANGE[0] ≤ length ≤ LENGTH_RANGE[1] (m, along ``axis``, after [mesh] scale);
    ``block``: the built-in block, whose sides are given in metres."""
    low, high = LENGTH_RANGE
    if low <= length <= high:
        return
    if block:
        hint = "give [mesh] length, width and height in metres"
    elif length > 1000 * high:
        hint = ("no unit of length makes it a swimmer (it would be over 5 m even in millimetres); check its "
                "coordinates and [mesh] scale")
    elif length > high:
        hint = ("its coordinates are probably in millimetres or centimetres: set [mesh] scale = 0.001 (mm) or "
                "0.01 (cm)")
    else:
        hint = "set [mesh] scale to the factor from its units to metres"
    raise InputError(f"mesh {source}: the body is {length:.4g} m long along {axis}, outside {1000 * low:g} mm to "
                     f"{high:g} m; {hint}")


AXES = ("x", "y", "z")
"""The axes a body may lie along in its mesh file ([mesh] axis)."""

TO_SWIMMING_FRAME = {
    "+x": np.eye(3),
    "-x": np.diag([-1.0, 1.0, 1.0]),                                   # a mirror in x, as before axes
    "+y": np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),   # quarter turns about z: z stays up
    "-y": np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
    "+z": np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),   # quarter turns about y: y stays lateral
    "-z": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
}
"""Per head end: the signed permutation P taking the mesh's coordinates to the swimming frame, x' = P x,
where the body lies along x with its head at +x (the frame of the block, the tags and the physics)."""

HEAD_END_TOLERANCE = 1e-6
"""How near an end of the body (a fraction of its length along the axis) the head region must reach to be at
that end; also how much longer (the same fraction) than along its axis a body may be along another axis."""

_HEAD_END_TOLD: set[tuple[str, str]] = set()
"""(mesh, statement) already logged (a study loads one mesh many times)."""


def check_block_sides(length: float, width: float, height: float) -> None:
    """InputError unless the built-in block is longest along x, the axis it swims along (within
    HEAD_END_TOLERANCE of its length), as ``check_axis_is_longest`` asks of a mesh file's body."""
    side, size = max((("width", width), ("height", height)), key=lambda pair: pair[1])
    if size > (1.0 + HEAD_END_TOLERANCE) * length:
        raise InputError(f"mesh block: [mesh] {side} = {size:g} m is over its length = {length:g} m; the block swims "
                         "along x, its longest side: give [mesh] length, width and height so that length is the "
                         "longest")


def check_axis_is_longest(mesh: FishMesh, axis: str) -> None:
    """InputError unless the body is longest along ``axis`` (within HEAD_END_TOLERANCE of its length
    there): a body lies along its length, and the stations, the shapes and the head end are taken
    along that axis."""
    extents = np.ptp(mesh.points, axis=0)
    column, longest = AXES.index(axis), int(np.argmax(extents))
    if extents[longest] > (1.0 + HEAD_END_TOLERANCE) * extents[column]:
        other = AXES[longest]
        raise InputError(f"mesh {mesh.source}: [mesh] axis = \"{axis}\", but the body is {extents[column]:.4g} m long "
                         f"along {axis} and {extents[longest]:.4g} m along {other}; the axis is the body's longest "
                         f"dimension: set [mesh] axis = \"{other}\" (and head_end \"+{other}\" or \"-{other}\")")


def head_end_of_region(mesh: FishMesh, head: str, axis: str) -> str | None:
    """"+axis" or "-axis": the one end of the body along ``axis`` that the region ``head`` reaches (its
    nodes within HEAD_END_TOLERANCE of the length of that end), None when the mesh has no such region.
    InputError when the region reaches both ends (the head and other pieces in one group, or the whole
    body) or neither (a region in the middle): a head is at one end."""
    cells = np.asarray(mesh.regions.get(head, ()), dtype=np.int64)
    if cells.size == 0:
        return None
    coordinates = mesh.points[:, AXES.index(axis)]
    low, high = float(coordinates.min()), float(coordinates.max())
    reach = HEAD_END_TOLERANCE * (high - low)
    head_coordinates = coordinates[np.unique(mesh.cells[cells])]
    front, rear = float(head_coordinates.max()), float(head_coordinates.min())
    ends = [end for end, reached in ((f"+{axis}", front >= high - reach), (f"-{axis}", rear <= low + reach)) if reached]
    if len(ends) == 1:
        return ends[0]
    where, remedy = (("both ends", "give the head alone its group (not with the tail or the whole body)")
                     if ends else ("neither end", "group the piece at the head end of the body as the head"))
    raise InputError(f"mesh {mesh.source}: the region '{head}' ([regions] head) reaches {where} of the body along "
                     f"{axis} (it spans {rear:.4g} to {front:.4g} m, the body {low:.4g} to {high:.4g} m); the head "
                     f"region must reach exactly one end, where the head is: {remedy}, or name that group in "
                     "[regions] head")


def inferred_head_end(mesh: FishMesh, head: str, axis: str) -> str:
    """The head end of a mesh whose scene does not give [mesh] head_end: the end of the body along
    ``axis`` that its region ``head`` reaches (``head_end_of_region``), said in one log line.
    InputError when the mesh has no such region."""
    end = head_end_of_region(mesh, head, axis)
    if end is None:
        present = ", ".join(f"'{name}'" for name in mesh.regions if len(mesh.regions[name])) or "none"
        raise InputError(f"mesh {mesh.source}: [mesh] head_end is not given and there is no region '{head}' "
                         f"([regions] head) to tell it from (its regions are {present}); set [mesh] head_end = "
                         f"\"+{axis}\" or \"-{axis}\"")
    statement = (f"mesh {mesh.source}: the head is at its {end} end, where the region '{head}' lies ([mesh] "
                 f"head_end not given; set it to say so)")
    if (mesh.source, statement) not in _HEAD_END_TOLD:
        _HEAD_END_TOLD.add((mesh.source, statement))
        log.warning("%s", statement)
    return end


def in_swimming_frame(mesh: FishMesh, axis: str, head_end: str, head: str) -> FishMesh:
    """The mesh in the swimming frame: its body along x with the head at the largest x, where the tags
    and the physics expect it.

    ``axis`` ("x", "y", "z") is the body's axis in the mesh, its longest dimension, and ``head_end``
    ("+axis" or "-axis", or "" to infer it from the region ``head``, ``inferred_head_end``) the end its
    head lies at. The points go through TO_SWIMMING_FRAME[head_end] (a quarter turn for y and z, a
    mirror in x for "-x"); a mirror swaps every cell's vertices 2 and 3 so that it stays positively
    oriented (the regions keep their cells). InputError when the body is longer along another axis,
    the declared end is not along ``axis``, or the mesh's region ``head`` does not reach exactly one
    end (``head_end_of_region``) or reaches the other one.
    """
    if axis not in AXES:
        raise InputError(f"mesh {mesh.source}: [mesh] axis = {axis!r}; it must be \"x\", \"y\" or \"z\"")
    if head_end and head_end not in (f"+{axis}", f"-{axis}"):
        raise InputError(f"mesh {mesh.source}: [mesh] head_end = {head_end!r} is not an end along [mesh] axis = "
                         f"\"{axis}\"; it must be \"+{axis}\" or \"-{axis}\" (or left out, to be inferred)")
    check_axis_is_longest(mesh, axis)
    if not head_end:
        head_end = inferred_head_end(mesh, head, axis)
    side = head_end_of_region(mesh, head, axis)
    if side is not None and side != head_end:
        raise InputError(f"mesh {mesh.source}: its region '{head}' lies at the {side} end of the body, but [mesh] "
                         f"head_end = \"{head_end}\"; set [mesh] head_end = \"{side}\"")
    if head_end == "+x":
        return mesh
    transform = TO_SWIMMING_FRAME[head_end]
    points = mesh.points @ transform.T
    cells = oriented_positively(points, mesh.cells) if np.linalg.det(transform) < 0 else mesh.cells
    return FishMesh(points=points, cells=cells, source=mesh.source, regions=mesh.regions)


def body_lines(mesh: FishMesh, regions: dict[str, np.ndarray], how: str) -> list[str]:
    """Lines describing the body: length along x, volume and element count, then the volume of each
    region (the share of the body in per cent); ``how`` says where the regions come from."""
    volumes = np.abs(signed_cell_volumes(mesh.points, mesh.cells))
    total = float(volumes.sum())
    length = float(np.ptp(mesh.points[:, 0]))
    parts = [f"{name} {volumes[np.asarray(cells, dtype=np.int64)].sum():.4g} m³ "
             f"({100 * volumes[np.asarray(cells, dtype=np.int64)].sum() / total:.1f} %)"
             for name, cells in regions.items()]
    return [f"body: length {length:.4g} m along x (head at the largest x), volume {total:.4g} m³, "
            f"{len(mesh.cells)} tetrahedra",
            f"regions: {', '.join(parts) or 'none'} ({how})"]


def block_lines(length: float, width: float, height: float, head_fraction: float, muscle_range,
                cells: int, level: int) -> list[str]:
    """``body_lines`` of a block not yet meshed: exact region volumes (the block's mesh conforms to
    them) and its level's advertised number of cells."""
    total = length * width * height
    muscle = (muscle_range[1] - muscle_range[0]) * total / 2
    regions = {"head": head_fraction * total, "left_muscle": muscle, "right_muscle": muscle}
    parts = [f"{name} {volume:.4g} m³ ({100 * volume / total:.1f} %)" for name, volume in regions.items()]
    return [f"body: length {length:.4g} m along x (head at the largest x), volume {total:.4g} m³, "
            f"~{cells} tetrahedra (level {level}, meshed by the run)",
            f"regions: {', '.join(parts)} (tagged)"]
