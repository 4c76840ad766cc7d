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
"""How near an end of the body (a fraction of its length) the head region must reach to be at that end."""

_HEAD_END_TOLD: set[tuple[str, str]] = set()
"""(mesh, statement) already logged (a study loads one mesh many times)."""


def head_side(mesh: FishMesh, head: str, axis: str = "x") -> str | None:
    """"+axis" or "-axis": the end of the body along ``axis`` nearer the volume centroid of the region
    ``head``; "middle" when it is at the middle, None when the mesh has no such region."""
    cells = np.asarray(mesh.regions.get(head, ()), dtype=np.int64)
    if cells.size == 0:
        return None
    column = AXES.index(axis)
    volumes = np.abs(signed_cell_volumes(mesh.points, mesh.cells[cells]))
    centre = float(np.average(mesh.points[mesh.cells[cells]].mean(axis=1)[:, column], weights=volumes))
    low, high = float(mesh.points[:, column].min()), float(mesh.points[:, column].max())
    offset = centre - 0.5 * (low + high)
    if abs(offset) <= 1e-9 * (high - low):
        return "middle"
    return f"+{axis}" if offset > 0.0 else f"-{axis}"


def inferred_head_end(mesh: FishMesh, head: str, axis: str) -> str:
    """The head end of a mesh whose scene does not give [mesh] head_end: the end of the body along
    ``axis`` that its region ``head`` reaches (within HEAD_END_TOLERANCE of the length), said in one
    log line. InputError when that is ambiguous: no such region, or one that reaches both ends or
    neither (a head in the middle)."""
    remedy = f"set [mesh] head_end = \"+{axis}\" or \"-{axis}\""
    cells = np.asarray(mesh.regions.get(head, ()), dtype=np.int64)
    if cells.size == 0:
        present = ", ".join(f"'{name}'" for name in mesh.regions if len(mesh.regions[name])) or "none"
        raise InputError(f"mesh {mesh.source}: [mesh] head_end is not given and there is no region '{head}' "
                         f"([regions] head) to tell it from (its regions are {present}); {remedy}")
    column = AXES.index(axis)
    coordinates = mesh.points[:, column]
    low, high = float(coordinates.min()), float(coordinates.max())
    reach = HEAD_END_TOLERANCE * (high - low)
    head_coordinates = coordinates[np.unique(mesh.cells[cells])]
    ends = [end for end, reached in ((f"+{axis}", head_coordinates.max() >= high - reach),
                                     (f"-{axis}", head_coordinates.min() <= low + reach)) if reached]
    if len(ends) != 1:
        where = "both ends" if ends else "neither end"
        raise InputError(f"mesh {mesh.source}: [mesh] head_end is not given and the region '{head}' reaches {where} "
                         f"of the body along {axis} ({low:.4g} to {high:.4g} m), so the head end is ambiguous; {remedy}")
    statement = (f"mesh {mesh.source}: the head is at its {ends[0]} end, where the region '{head}' lies ([mesh] "
                 f"head_end not given; set it to say so)")
    if (mesh.source, statement) not in _HEAD_END_TOLD:
        _HEAD_END_TOLD.add((mesh.source, statement))
        log.warning("%s", statement)
    return ends[0]


def in_swimming_frame(mesh: FishMesh, axis: str, head_end: str, head: str) -> FishMesh:
    """The mesh in the swimming frame: its body along x with the head at the largest x, where the tags
    and the physics expect it.

    ``axis`` ("x", "y", "z") is the body's axis in the mesh and ``head_end`` ("+axis" or "-axis", or ""
    to infer it from the region ``head``, ``inferred_head_end``) the end its head lies at. The
    points go through TO_SWIMMING_FRAME[head_end] (a quarter turn for y and z, a mirror in x for
    "-x"); a mirror swaps every cell's vertices 2 and 3 so that it stays positively oriented (the
    regions keep their cells). InputError when the declared end is not along ``axis`` or the mesh's
    region ``head`` lies at the other end (or the middle).
    """
    if axis not in AXES:
        raise InputError(f"mesh {mesh.source}: [mesh] axis = {axis!r}; it must be \"x\", \"y\" or \"z\"")
    if not head_end:
        head_end = inferred_head_end(mesh, head, axis)
    if head_end not in (f"+{axis}", f"-{axis}"):
        raise InputError(f"mesh {mesh.source}: [mesh] head_end = {head_end!r} is not an end along [mesh] axis = "
                         f"\"{axis}\"; it must be \"+{axis}\" or \"-{axis}\" (or left out, to be inferred)")
    side = head_side(mesh, head, axis)
    if side is not None and side != head_end:
        where = "at the middle of the body" if side == "middle" else f"at the {side} end of the body"
        remedy = (f"set [mesh] head_end = \"{side}\"" if side != "middle"
                  else "the head must be at one end of the body")
        raise InputError(f"mesh {mesh.source}: its region '{head}' lies {where}, but [mesh] head_end = "
                         f"\"{head_end}\"; {remedy}")
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
