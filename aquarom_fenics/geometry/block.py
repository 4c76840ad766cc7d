"""The reference block of SPEC §3 meshed with linear tetrahedra, and its mesh cache.

The block meshes are generated with gmsh on one quarter of the box and mirrored in numpy, so
that they are exactly symmetric about y = 0 and z = 0 and have equally spaced nodes on the body
axis y = z = 0. Levels, element sizes and gmsh options are the recipe ``meshes/block.toml``.
"""

from __future__ import annotations

import tomllib
import warnings
import zipfile
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, gmsh_version, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh import FishMesh, oriented_positively
from aquarom_fenics.io.paths import mesh_cache, shipped_meshes
from aquarom_fenics.io.persistence import get_or_compute, write_npz_atomic


BLOCK_RECIPE = tomllib.loads((shipped_meshes() / "block.toml").read_text())
"""The reference block's recipe (``meshes/block.toml``): levels, element sizes, gmsh options."""

LEVEL_TARGET_CELLS = {int(level): entry["cells"] for level, entry in BLOCK_RECIPE["levels"].items()}
LEVEL_MESH_SIZE = {int(level): entry["size"] for level, entry in BLOCK_RECIPE["levels"].items()}
"""gmsh element size [m] per level on the reference box."""
REFERENCE_BOX = tuple(BLOCK_RECIPE["reference_box"])
BLOCK_MESH_RECIPE = BLOCK_RECIPE["recipe"]
"""Version of the block-meshing procedure; part of the cache file name."""

_GMSH_BLOCK_OPTIONS = BLOCK_RECIPE["gmsh"]


def _check_block_input(level: int, length: float, width: float, height: float) -> None:
    is_integer = isinstance(level, (int, np.integer)) and not isinstance(level, bool)
    if not is_integer or level not in LEVEL_TARGET_CELLS:
        valid = ", ".join(str(key) for key in LEVEL_TARGET_CELLS)
        raise InputError(f"block mesh: level {level!r} does not exist; use one of {valid}")
    for name, value in (("length", length), ("width", width), ("height", height)):
        try:
            positive = bool(np.isfinite(float(value)) and float(value) > 0.0)
        except (TypeError, ValueError):
            positive = False
        if not positive:
            raise InputError(f"block mesh: {name} = {value!r} m; it must be a positive number")


def block_mesh_size(level: int, length: float, width: float, height: float) -> float:
    """gmsh element size (m) of a level: h = h_level (L W H / L_ref W_ref H_ref)^(1/3)."""
    reference_volume = float(np.prod(REFERENCE_BOX))
    return LEVEL_MESH_SIZE[level] * (length * width * height / reference_volume) ** (1.0 / 3.0)


def block_axis_segments(level: int, length: float, width: float, height: float) -> int:
    """Number of equal segments of the body axis: round(L / h), at least 2."""
    return max(2, int(round(length / block_mesh_size(level, length, width, height))))


def _snap_to_box(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Coordinates within 1e-9 × box size of a box plane or of 0 set to that value exactly."""
    tolerance = 1e-9 * float(np.max(upper - lower))
    snapped = points.copy()
    for planes in (lower, upper, np.zeros(3)):
        near = np.abs(snapped - planes) <= tolerance
        snapped = np.where(near, planes, snapped)
    return snapped


def _quarter_block(size: float, axis_nodes: int, length: float, width: float, height: float):
    """gmsh mesh of x ∈ [-L, 0], y ∈ [0, W/2], z ∈ [0, H/2] with equally spaced nodes on the two
    box edges in the plane y = 0 (z = 0 and z = H/2). Returns (points, cells)."""
    options = {**_GMSH_BLOCK_OPTIONS, "Mesh.MeshSizeMin": size, "Mesh.MeshSizeMax": size}
    with gmsh_model("aquarom_block_quarter", options) as gmsh:
        gmsh.model.occ.addBox(-length, 0.0, 0.0, length, width / 2, height / 2)
        gmsh.model.occ.synchronize()
        margin = 1e-6 * length
        for z_edge in (0.0, height / 2):
            edges = gmsh.model.getEntitiesInBoundingBox(
                -length - margin, -margin, z_edge - margin, margin, margin, z_edge + margin, 1
            )
            for _, tag in edges:
                gmsh.model.mesh.setTransfiniteCurve(tag, axis_nodes)
        gmsh.model.mesh.generate(3)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        _, element_nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON)
    return points_and_cells_from_gmsh(node_tags, coordinates, element_nodes)




def _mirrored(points: np.ndarray, cells: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh together with its mirror image about the plane where coordinate `axis` is 0.

    Nodes on that plane (coordinate exactly 0) are shared with the mirror image; mirrored cells get
    vertices 2 and 3 swapped so that they keep a positive orientation.
    """
    on_plane = points[:, axis] == 0.0
    mirror_index = np.arange(len(points), dtype=np.int64)
    off_plane = np.flatnonzero(~on_plane)
    mirror_index[off_plane] = len(points) + np.arange(len(off_plane), dtype=np.int64)
    mirror_points = points[off_plane].copy()
    mirror_points[:, axis] *= -1.0
    mirror_cells = mirror_index[cells][:, [0, 1, 3, 2]]
    return np.vstack([points, mirror_points]), np.vstack([cells, mirror_cells])


def _generate_block(level: int, length: float, width: float, height: float):
    """(points, cells) of the block: the gmsh quarter mirrored in y, then in z."""
    size = block_mesh_size(level, length, width, height)
    axis_nodes = block_axis_segments(level, length, width, height) + 1
    points, cells = _quarter_block(size, axis_nodes, length, width, height)
    lower = np.array([-length, 0.0, 0.0])
    upper = np.array([0.0, width / 2, height / 2])
    points = _snap_to_box(points, lower, upper)
    cells = oriented_positively(points, cells)
    points, cells = _mirrored(points, cells, axis=1)
    points, cells = _mirrored(points, cells, axis=2)
    return points, cells


def block_cache_path(level: int, length: float, width: float, height: float, cache_dir: Path | None = None) -> Path:
    """Where :func:`block_mesh` caches a level (whether or not it exists yet)."""
    return _block_cache_path(cache_dir or mesh_cache(), level, length, width, height)


def _block_cache_path(cache_dir: Path, level: int, length: float, width: float, height: float):
    name = (
        f"block_level{level}_L{length:.9g}_W{width:.9g}_H{height:.9g}"
        f"_gmsh{gmsh_version()}_recipe{BLOCK_MESH_RECIPE}.npz"
    )
    return cache_dir / name


def _load_cached_block(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(points, cells) from a cache file; ValueError if it is not a valid mesh."""
    try:
        with np.load(path, allow_pickle=False) as data:
            points = np.array(data["points"], dtype=float)
            cells = np.array(data["cells"], dtype=np.int64)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"not a mesh archive ({error})") from None
    valid = (
        points.ndim == 2
        and points.shape[1] == 3
        and cells.ndim == 2
        and cells.shape[1] == 4
        and len(cells) > 0
        and np.all(np.isfinite(points))
        and cells.min() >= 0
        and cells.max() < len(points)
    )
    if not valid:
        raise ValueError("not a valid tetrahedral mesh")
    return points, cells


def block_mesh(
    level: int,
    length: float = 0.20,
    width: float = 0.04,
    height: float = 0.10,
    cache_dir: Path | None = None,
) -> FishMesh:
    """The box x ∈ [-L, 0], y ∈ [-W/2, W/2], z ∈ [-H/2, H/2] (m) meshed with linear tetrahedra.

    The mesh is mirror-symmetric about y = 0 and z = 0 and has round(L/h) + 1 equally spaced
    nodes on the body axis y = z = 0 from x = -L to x = 0 (h: `block_mesh_size`). The result is
    cached in `cache_dir` (default `meshes/cache` of the repository) and read from there on
    later calls (checksummed, see `persistence.get_or_compute`); a damaged cache file is regenerated,
    an unwritable cache only warned about.
    """
    _check_block_input(level, length, width, height)
    level = int(level)
    cache_dir = mesh_cache() if cache_dir is None else Path(cache_dir)
    cache_path = _block_cache_path(cache_dir, level, length, width, height)

    def not_cached(error: OSError) -> None:
        warnings.warn(f"block mesh not cached in {cache_dir}: {error}", stacklevel=4)

    points, cells = get_or_compute(
        cache_path, lambda: _generate_block(level, length, width, height),
        save=lambda mesh, path: write_npz_atomic(path, {"points": mesh[0], "cells": mesh[1]}),
        load=_load_cached_block, label="mesh cache", on_store_error=not_cached)
    source = f"block level {level} (L={length:g} m, W={width:g} m, H={height:g} m)"
    return FishMesh(points=points, cells=cells, source=source)
