"""The body a mesh describes: its length within the range of swimmers, its head end along x, and a
summary (length, volume, region volumes, element count) for ``aquarom mesh`` and every dry run.
"""

from __future__ import annotations

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.mesh import FishMesh, oriented_positively, signed_cell_volumes


LENGTH_RANGE = (1e-3, 5.0)
"""Lengths along x [m] of the bodies accepted: 1 mm to 5 m (a mesh outside is in other units)."""


def check_body_length(length: float, source: str, block: bool = False) -> None:
    """InputError unless LENGTH_RANGE[0] ≤ length ≤ LENGTH_RANGE[1] (m, along x, after [mesh] scale);
    ``block``: the built-in block, whose sides are given in metres."""
    low, high = LENGTH_RANGE
    if low <= length <= high:
        return
    if block:
        hint = "give [mesh] length, width and height in metres"
    elif length > high:
        hint = ("its coordinates are probably in millimetres or centimetres: set [mesh] scale = 0.001 (mm) or "
                "0.01 (cm)")
    else:
        hint = "set [mesh] scale to the factor from its units to metres"
    raise InputError(f"mesh {source}: the body is {length:.4g} m long along x, outside {1000 * low:g} mm to "
                     f"{high:g} m; {hint}")


def head_side(mesh: FishMesh, head: str) -> str | None:
    """"+x" or "-x": the end of the body along x nearer the volume centroid of the region ``head``;
    "middle" when it is at the middle, None when the mesh has no such region."""
    cells = np.asarray(mesh.regions.get(head, ()), dtype=np.int64)
    if cells.size == 0:
        return None
    volumes = np.abs(signed_cell_volumes(mesh.points, mesh.cells[cells]))
    centre = float(np.average(mesh.points[mesh.cells[cells]].mean(axis=1)[:, 0], weights=volumes))
    x_min, x_max = float(mesh.points[:, 0].min()), float(mesh.points[:, 0].max())
    offset = centre - 0.5 * (x_min + x_max)
    if abs(offset) <= 1e-9 * (x_max - x_min):
        return "middle"
    return "+x" if offset > 0.0 else "-x"


def with_head_at_max_x(mesh: FishMesh, head_end: str, head: str) -> FishMesh:
    """The mesh with its head at the largest x, where the tags and the physics expect it.

    ``head_end`` = "+x": the mesh as it is; "-x": mirrored, x → -x, with every cell's vertices 2
    and 3 swapped so that it stays positively oriented (the regions keep their cells). InputError
    when the mesh's region ``head`` lies at the other end (or the middle).
    """
    if head_end not in ("+x", "-x"):
        raise InputError(f"mesh {mesh.source}: [mesh] head_end = {head_end!r}; it must be \"+x\" or \"-x\"")
    side = head_side(mesh, head)
    if side is not None and side != head_end:
        where = "at the middle of the body" if side == "middle" else f"at the {side} end of the body"
        remedy = (f"set [mesh] head_end = \"{side}\"" if side != "middle"
                  else "the head must be at one end of the body")
        raise InputError(f"mesh {mesh.source}: its region '{head}' lies {where}, but [mesh] head_end = "
                         f"\"{head_end}\"; {remedy}")
    if head_end == "+x":
        return mesh
    points = mesh.points.copy()
    points[:, 0] = -points[:, 0]
    return FishMesh(points=points, cells=oriented_positively(points, mesh.cells), source=mesh.source,
                    regions=mesh.regions)


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
