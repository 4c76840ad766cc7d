"""The reference block of SPEC §3 meshed with linear tetrahedra, and its mesh cache.

The block meshes are generated with gmsh on one quarter of the box, cut by the planes of the
region interfaces (head/body, muscle ends) so that every region is a tagged set of cells, and
mirrored in numpy, so that they are exactly symmetric about y = 0 and z = 0 (the plane between the
left and the right muscle) and have nodes on the body axis y = z = 0. Levels, element sizes and
gmsh options are the recipe ``meshes/block.toml``.
"""

from __future__ import annotations

import tomllib
import warnings
import zipfile
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, gmsh_version, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh import FishMesh, check_region_fractions, oriented_positively
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


def _snap_to_box(points: np.ndarray, lower: np.ndarray, upper: np.ndarray, x_planes=()) -> np.ndarray:
    """Coordinates within 1e-9 × box size of a box plane, of 0 or (x) of an interface plane set to
    that value exactly."""
    tolerance = 1e-9 * float(np.max(upper - lower))
    snapped = points.copy()
    for planes in (lower, upper, np.zeros(3)):
        near = np.abs(snapped - planes) <= tolerance
        snapped = np.where(near, planes, snapped)
    for x in x_planes:
        near = np.abs(snapped[:, 0] - x) <= tolerance
        snapped[near, 0] = x
    return snapped


def muscle_segment_ends(length: float, muscle_range, pairs: int = 1) -> np.ndarray:
    """x [m] of the ends of the ``pairs`` equal segments of the muscle range, tail to head (pairs + 1 values)."""
    rear, front = (bound * length for bound in muscle_range)
    inner = [rear + k * (front - rear) / pairs for k in range(1, pairs)]
    return np.array([rear, *inner, front])


def region_planes(length: float, head_fraction: float, muscle_range, pairs: int = 1) -> np.ndarray:
    """Sorted x positions (m, head face at x = 0) of the region interfaces inside the box: the head's
    rear face x = -head_fraction L, the muscles' ends x = muscle_range L (SPEC §2–§3) and, with
    ``pairs`` > 1, the ends of the muscle segments."""
    planes = {-head_fraction * length, *muscle_segment_ends(length, muscle_range, pairs).tolist()}
    inside = [x for x in planes if -length < x < 0.0]
    return np.array(sorted(inside))


QUARTER_REGIONS = ("head", "muscle", "body")
"""Physical volume groups of the quarter block; the mirror in y splits "muscle" into left and right."""


def _quarter_block(size: float, length: float, width: float, height: float, planes: np.ndarray,
                   head_fraction: float, muscle_range):
    """gmsh mesh of x ∈ [-L, 0], y ∈ [0, W/2], z ∈ [0, H/2], cut by the planes x = planes[k] into
    slabs that the mesh conforms to. Each slab belongs to the physical group "head"
    (x ≥ -head_fraction L), "muscle" (muscle_range[0] L ≤ x ≤ muscle_range[1] L) or "body".
    The two box edges in the plane y = 0 (z = 0 and z = H/2) get equally spaced nodes per slab.

    Returns (points, cells, region of each cell as an index into QUARTER_REGIONS).
    """
    options = {**_GMSH_BLOCK_OPTIONS, "Mesh.MeshSizeMin": size, "Mesh.MeshSizeMax": size}
    ends = np.concatenate([[-length], planes, [0.0]])
    with gmsh_model("aquarom_block_quarter", options) as gmsh:
        slabs = [(3, gmsh.model.occ.addBox(rear, 0.0, 0.0, front - rear, width / 2, height / 2))
                 for rear, front in zip(ends[:-1], ends[1:])]
        if len(slabs) > 1:
            gmsh.model.occ.fragment(slabs[:1], slabs[1:])
        gmsh.model.occ.synchronize()
        margin = 1e-6 * length
        for z_edge in (0.0, height / 2):
            edges = gmsh.model.getEntitiesInBoundingBox(
                -length - margin, -margin, z_edge - margin, margin, margin, z_edge + margin, 1
            )
            for _, tag in edges:
                low, high = gmsh.model.getBoundingBox(1, tag)[0], gmsh.model.getBoundingBox(1, tag)[3]
                gmsh.model.mesh.setTransfiniteCurve(tag, max(1, int(round((high - low) / size))) + 1)
        groups = {name: [] for name in QUARTER_REGIONS}
        head_rear, (muscle_rear, muscle_front) = -head_fraction * length, (b * length for b in muscle_range)
        for _, volume in gmsh.model.getEntities(3):
            box = gmsh.model.getBoundingBox(3, volume)
            centre = 0.5 * (box[0] + box[3])
            name = ("head" if centre >= head_rear else
                    "muscle" if muscle_rear < centre < muscle_front else "body")
            groups[name].append(volume)
        for name, volumes in groups.items():
            if volumes:
                gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, volumes), name)
        gmsh.model.mesh.generate(3)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        element_nodes, regions = [], []
        for dim, group in gmsh.model.getPhysicalGroups(3):
            region = QUARTER_REGIONS.index(gmsh.model.getPhysicalName(dim, group))
            for volume in gmsh.model.getEntitiesForPhysicalGroup(dim, group):
                _, nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON, volume)
                element_nodes.append(nodes)
                regions.append(np.full(len(nodes) // 4, region, dtype=np.int64))
    points, cells = points_and_cells_from_gmsh(node_tags, coordinates, np.concatenate(element_nodes))
    return points, cells, np.concatenate(regions)


def mirrored(points: np.ndarray, cells: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
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


def block_region_names(pairs: int = 1) -> tuple[str, ...]:
    """The regions of the block: head, the muscles left_muscle and right_muscle and, with ``pairs`` > 1,
    their segments left_1 … left_n, right_1 … right_n (numbered from the tail)."""
    segments = [f"{side}_{k}" for side in ("left", "right") for k in range(1, pairs + 1)] if pairs > 1 else []
    return ("head", "left_muscle", "right_muscle", *segments)


def _generate_block(level: int, length: float, width: float, height: float, head_fraction: float = 0.35,
                    muscle_range=(-0.95, -0.35), pairs: int = 1):
    """(points, cells, regions) of the block: the gmsh quarter mirrored in y, then in z; ``regions``
    maps "head", "left_muscle" (y > 0) and "right_muscle" (y < 0) and the segments of
    :func:`block_region_names` to sorted cell indices."""
    size = block_mesh_size(level, length, width, height)
    planes = region_planes(length, head_fraction, muscle_range, pairs)
    points, cells, quarter_regions = _quarter_block(size, length, width, height, planes, head_fraction, muscle_range)
    lower = np.array([-length, 0.0, 0.0])
    upper = np.array([0.0, width / 2, height / 2])
    points = _snap_to_box(points, lower, upper, planes)
    cells = oriented_positively(points, cells)
    n_quarter = len(cells)
    points, cells = mirrored(points, cells, axis=1)
    points, cells = mirrored(points, cells, axis=2)
    region = np.tile(quarter_regions, 4)
    left_half = np.tile(np.arange(2 * n_quarter) < n_quarter, 2)
    muscle = region == QUARTER_REGIONS.index("muscle")
    regions = {"head": np.flatnonzero(region == QUARTER_REGIONS.index("head")),
               "left_muscle": np.flatnonzero(muscle & left_half),
               "right_muscle": np.flatnonzero(muscle & ~left_half)}
    if pairs > 1:                # the mesh conforms to the segments: each cell's centroid is inside one
        segment = np.searchsorted(muscle_segment_ends(length, muscle_range, pairs), points[cells].mean(axis=1)[:, 0])
        for k in range(1, pairs + 1):
            regions[f"left_{k}"] = np.flatnonzero(muscle & left_half & (segment == k))
            regions[f"right_{k}"] = np.flatnonzero(muscle & ~left_half & (segment == k))
    return points, cells, regions


def block_cache_path(level: int, length: float, width: float, height: float, cache_dir: Path | None = None,
                     head_fraction: float = 0.35, muscle_range=(-0.95, -0.35), pairs: int = 1) -> Path:
    """Where :func:`block_mesh` caches a level (whether or not it exists yet)."""
    return _block_cache_path(cache_dir or mesh_cache(), level, length, width, height, head_fraction, muscle_range,
                             pairs)


def _block_cache_path(cache_dir: Path, level: int, length: float, width: float, height: float,
                      head_fraction: float, muscle_range, pairs: int = 1):
    rear, front = muscle_range
    name = (
        f"block_level{level}_L{length:.9g}_W{width:.9g}_H{height:.9g}"
        f"_head{head_fraction:.9g}_muscles{rear:.9g}_{front:.9g}" + (f"_pairs{pairs}" if pairs > 1 else "") +
        f"_gmsh{gmsh_version()}_recipe{BLOCK_MESH_RECIPE}.npz"
    )
    return cache_dir / name


_REGION_KEY = "region_"
"""Prefix of the cache archive's region arrays (cell indices)."""


def _save_block(mesh, path: Path) -> None:
    points, cells, regions = mesh
    write_npz_atomic(path, {"points": points, "cells": cells,
                            **{_REGION_KEY + name: indices for name, indices in regions.items()}})


def _load_cached_block(path: Path, names=block_region_names()):
    """(points, cells, regions) from a cache file; ValueError if it is not a valid tagged mesh with the
    regions ``names``."""
    try:
        with np.load(path, allow_pickle=False) as data:
            points = np.array(data["points"], dtype=float)
            cells = np.array(data["cells"], dtype=np.int64)
            regions = {key[len(_REGION_KEY):]: np.array(data[key], dtype=np.int64)
                       for key in data.files if key.startswith(_REGION_KEY)}
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
        and set(regions) == set(names)
        and all(indices.ndim == 1 and len(indices) > 0 and indices.min() >= 0 and indices.max() < len(cells)
                for indices in regions.values())
    )
    if not valid:
        raise ValueError("not a valid tetrahedral mesh with its regions")
    return points, cells, regions


def block_mesh(
    level: int,
    length: float = 0.20,
    width: float = 0.04,
    height: float = 0.10,
    cache_dir: Path | None = None,
    head_fraction: float = 0.35,
    muscle_range=(-0.95, -0.35),
    pairs: int = 1,
) -> FishMesh:
    """The box x ∈ [-L, 0], y ∈ [-W/2, W/2], z ∈ [-H/2, H/2] (m) meshed with linear tetrahedra that
    conform to the regions (SPEC §3): the head x ≥ -head_fraction L and the muscles
    muscle_range[0] L < x < muscle_range[1] L, left (y > 0) and right (y < 0), are tagged cell sets
    (``FishMesh.regions``) whose interfaces are faces of the mesh; with ``pairs`` > 1 the muscles'
    x-range is split into that many equal segments, tagged too (:func:`block_region_names`).

    The mesh is mirror-symmetric about y = 0 and z = 0 and has nodes on the body axis y = z = 0
    from x = -L to x = 0, equally spaced between the interface planes (h: `block_mesh_size`). The
    result is cached in `cache_dir` (default `meshes/cache` of the repository) and read from there
    on later calls (checksummed, see `persistence.get_or_compute`); a damaged cache file is
    regenerated, an unwritable cache only warned about.
    """
    _check_block_input(level, length, width, height)
    check_region_fractions(f"block level {level}", head_fraction, muscle_range)
    level = int(level)
    head_fraction, muscle_range = float(head_fraction), tuple(float(bound) for bound in muscle_range)
    cache_dir = mesh_cache() if cache_dir is None else Path(cache_dir)
    cache_path = _block_cache_path(cache_dir, level, length, width, height, head_fraction, muscle_range, pairs)

    def not_cached(error: OSError) -> None:
        warnings.warn(f"block mesh not cached in {cache_dir}: {error}", stacklevel=4)

    points, cells, regions = get_or_compute(
        cache_path, lambda: _generate_block(level, length, width, height, head_fraction, muscle_range, pairs),
        save=_save_block, load=lambda path: _load_cached_block(path, block_region_names(pairs)), label="mesh cache",
        on_store_error=not_cached)
    source = f"block level {level} (L={length:g} m, W={width:g} m, H={height:g} m)"
    return FishMesh(points=points, cells=cells, source=source, regions=regions)
