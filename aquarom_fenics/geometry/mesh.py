"""Linear tetrahedral meshes as plain numpy arrays: the reference block and imported files.

A mesh is a `FishMesh`: node coordinates in metres and positively oriented linear tetrahedra.
The block meshes of SPEC §3 are generated with gmsh on one quarter of the box and mirrored in
numpy, so that they are exactly symmetric about y = 0 and z = 0 and have equally spaced nodes on
the body axis y = z = 0.
"""

from __future__ import annotations

import os
import signal
import tempfile
import threading
import tomllib
import warnings
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import mesh_cache, shipped_meshes

BLOCK_RECIPE = tomllib.loads((shipped_meshes() / "block.toml").read_text())
"""The reference block's recipe (``meshes/block.toml``): levels, element sizes, gmsh options."""

LEVEL_TARGET_CELLS = {int(level): entry["cells"] for level, entry in BLOCK_RECIPE["levels"].items()}
LEVEL_MESH_SIZE = {int(level): entry["size"] for level, entry in BLOCK_RECIPE["levels"].items()}
"""gmsh element size [m] per level on the reference box."""
REFERENCE_BOX = tuple(BLOCK_RECIPE["reference_box"])
BLOCK_MESH_RECIPE = BLOCK_RECIPE["recipe"]
"""Version of the block-meshing procedure; part of the cache file name."""

_GMSH_TETRAHEDRON = 4
_GMSH_BLOCK_OPTIONS = BLOCK_RECIPE["gmsh"]
_GMSH_READ_OPTIONS = {"General.Terminal": 0, "General.NumThreads": 1}


@dataclass(frozen=True)
class FishMesh:
    """A linear tetrahedral mesh."""

    points: np.ndarray  # (n_nodes, 3) float64, metres
    cells: np.ndarray  # (n_cells, 4) int64, positively oriented tetrahedra
    source: str  # where it came from, e.g. "block level 1" or the file path


TETRAHEDRON_EDGES = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]])
"""Local vertices of the six edges of a tetrahedron, in the reference (basix/UFC) edge order."""


@dataclass(frozen=True)
class LagrangeNodes:
    """The displacement nodes of a degree-1 or degree-2 Lagrange space on a `FishMesh`.

    Degree 1: the vertices. Degree 2: the vertices, then one node at the midpoint of every edge
    (``edges[e]`` its two vertices, node ``n_vertices + e``). ``cell_nodes`` lists each cell's
    nodes, vertices first, then its edges in the order of ``TETRAHEDRON_EDGES``.
    """

    degree: int
    points: np.ndarray  # (n_nodes, 3) metres; the first n_vertices rows are the mesh points
    cell_nodes: np.ndarray  # (n_cells, 4) or (n_cells, 10)
    edges: np.ndarray  # (n_edges, 2) vertex pairs, smaller index first (empty at degree 1)
    n_vertices: int

    def nodes_of_pairs(self, pairs: np.ndarray) -> np.ndarray:
        """Node index of each vertex pair (a, b): the vertex a if a = b, else the edge's midpoint."""
        pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
        nodes = pairs[:, 0].copy()
        on_edge = pairs[:, 0] != pairs[:, 1]
        if on_edge.any():
            keys = self.edges[:, 0] * self.n_vertices + self.edges[:, 1]
            wanted = pairs[on_edge, 0] * self.n_vertices + pairs[on_edge, 1]
            nodes[on_edge] = self.n_vertices + np.searchsorted(keys, wanted)
        return nodes

    def facet_nodes(self, facets: np.ndarray) -> np.ndarray:
        """All nodes of the given (n, 3) vertex triangles (their vertices and edge midpoints)."""
        facets = np.asarray(facets, dtype=np.int64)
        if self.degree == 1:
            return np.unique(facets)
        pairs = facets[:, [[0, 0], [1, 1], [2, 2], [0, 1], [1, 2], [0, 2]]].reshape(-1, 2)
        return np.unique(self.nodes_of_pairs(pairs))


def lagrange_nodes(mesh: FishMesh, degree: int) -> LagrangeNodes:
    """The nodes of the degree-``degree`` Lagrange space on ``mesh`` (SPEC §3: vertices and, at
    degree 2, edge midpoints x_m = (x_a + x_b)/2)."""
    cells = np.asarray(mesh.cells, dtype=np.int64)
    n_vertices = mesh.points.shape[0]
    if degree == 1:
        return LagrangeNodes(1, mesh.points, cells, np.empty((0, 2), dtype=np.int64), n_vertices)
    cell_edges = np.sort(cells[:, TETRAHEDRON_EDGES], axis=2).reshape(-1, 2)
    edges, edge_of = np.unique(cell_edges, axis=0, return_inverse=True)
    midpoints = 0.5 * (mesh.points[edges[:, 0]] + mesh.points[edges[:, 1]])
    cell_nodes = np.hstack([cells, n_vertices + edge_of.reshape(-1, 6)])
    return LagrangeNodes(degree, np.vstack([mesh.points, midpoints]), cell_nodes, edges, n_vertices)


# ---------------------------------------------------------------------------------------------
# Geometry of tetrahedra


def signed_cell_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volumes (m³) of tetrahedra: V = det[x1 - x0, x2 - x0, x3 - x0] / 6.

    Positive when (x1 - x0, x2 - x0, x3 - x0) is a right-handed triple.
    """
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    edges = vertices[:, 1:, :] - vertices[:, :1, :]
    return np.linalg.det(edges) / 6.0


def cell_quality(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Volume-to-edge shape measure q = 6√2 V / ℓ_rms³ per tetrahedron (dimensionless).

    ℓ_rms is the root mean square of the six edge lengths and V the signed volume, so q = 1 for
    the regular tetrahedron, q → 0 for a degenerate (flat) one and q < 0 for an inverted one.
    """
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    first, second = np.triu_indices(4, k=1)
    edge_vectors = vertices[:, second, :] - vertices[:, first, :]
    edge_rms = np.sqrt(np.mean(np.sum(edge_vectors**2, axis=2), axis=1))
    volumes = signed_cell_volumes(points, cells)
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = 6.0 * np.sqrt(2.0) * volumes / edge_rms**3
    return np.where(edge_rms > 0.0, quality, 0.0)


def mean_edge_length(points: np.ndarray, cells: np.ndarray) -> float:
    """Mean length (m) of the six edges of all tetrahedra (shared edges counted per cell)."""
    vertices = np.asarray(points, dtype=float)[np.asarray(cells)]
    first, second = np.triu_indices(4, k=1)
    edge_vectors = vertices[:, second, :] - vertices[:, first, :]
    return float(np.mean(np.linalg.norm(edge_vectors, axis=2)))


def oriented_positively(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The cells with vertices 2 and 3 swapped wherever the signed volume is negative."""
    cells = np.array(cells, dtype=np.int64)
    negative = signed_cell_volumes(points, cells) < 0.0
    cells[negative] = cells[negative][:, [0, 1, 3, 2]]
    return cells


def _used_nodes_only(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop nodes no cell uses and renumber the cells (node order kept)."""
    used = np.unique(cells)
    new_index = np.full(len(points), -1, dtype=np.int64)
    new_index[used] = np.arange(len(used), dtype=np.int64)
    return points[used], new_index[cells]


# ---------------------------------------------------------------------------------------------
# gmsh session


def _import_gmsh():
    """Import gmsh, keeping the caller's SIGINT handler (the gmsh module resets it on import)."""
    in_main_thread = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGINT) if in_main_thread else None
    import gmsh

    if in_main_thread and handler is not None:
        signal.signal(signal.SIGINT, handler)
    return gmsh


@contextmanager
def _stderr_silenced():
    """Redirect file descriptor 2 to /dev/null (gmsh prints to it from C)."""
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(devnull)
        os.close(saved)


def _gmsh_is_initialized(gmsh) -> bool:
    """True when the gmsh API is initialized (the 4.8 API has no `gmsh.isInitialized`)."""
    if hasattr(gmsh, "isInitialized"):
        return bool(gmsh.isInitialized())
    with _stderr_silenced():
        try:
            return bool(gmsh.option.getString("General.Version"))
        except Exception:
            return False


@contextmanager
def _gmsh_model(name: str, options: dict[str, float]):
    """A fresh gmsh model with the given options, removed afterwards.

    gmsh is initialized only if it is not already, and then finalized on exit; otherwise the
    caller's current model and option values are restored.
    """
    gmsh = _import_gmsh()
    started_here = not _gmsh_is_initialized(gmsh)
    if started_here:
        gmsh.initialize(readConfigFiles=False)
    previous_model = gmsh.model.getCurrent()
    previous_options = {option: gmsh.option.getNumber(option) for option in options}
    try:
        for option, value in options.items():
            gmsh.option.setNumber(option, value)
        gmsh.model.add(name)
        yield gmsh
    finally:
        if started_here:
            gmsh.finalize()
        else:
            if gmsh.model.getCurrent() == name:
                gmsh.model.remove()
            if previous_model in gmsh.model.list():
                gmsh.model.setCurrent(previous_model)
            for option, value in previous_options.items():
                gmsh.option.setNumber(option, value)


def _gmsh_version() -> str:
    return _import_gmsh().__version__


# ---------------------------------------------------------------------------------------------
# Block meshes


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
    with _gmsh_model("aquarom_block_quarter", options) as gmsh:
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
        _, element_nodes = gmsh.model.mesh.getElementsByType(_GMSH_TETRAHEDRON)
    return _points_and_cells_from_gmsh(node_tags, coordinates, element_nodes)


def _points_and_cells_from_gmsh(node_tags, coordinates, element_nodes):
    """(points, cells) from gmsh node tags/coordinates and tetrahedron node tags, renumbered to
    the nodes the tetrahedra use."""
    node_tags = np.asarray(node_tags, dtype=np.int64)
    points = np.asarray(coordinates, dtype=float).reshape(-1, 3)
    cell_tags = np.asarray(element_nodes, dtype=np.int64).reshape(-1, 4)
    order = np.argsort(node_tags)
    position = np.searchsorted(node_tags[order], cell_tags)
    position = np.clip(position, 0, len(node_tags) - 1)
    if not np.all(node_tags[order][position] == cell_tags):
        raise ValueError("a tetrahedron refers to a node that is not defined")
    return _used_nodes_only(points[order], position)


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
        f"_gmsh{_gmsh_version()}_recipe{BLOCK_MESH_RECIPE}.npz"
    )
    return cache_dir / name


def _load_cached_block(path: Path):
    """(points, cells) from a cache file, or None if it is missing or not a valid mesh."""
    try:
        with np.load(path, allow_pickle=False) as data:
            points = np.array(data["points"], dtype=float)
            cells = np.array(data["cells"], dtype=np.int64)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
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
    return (points, cells) if valid else None


def _write_atomically(path: Path, points: np.ndarray, cells: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(descriptor, "wb") as stream:
            np.savez(stream, points=points, cells=cells)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


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
    later calls; an unreadable cache file is regenerated, an unwritable cache only warned about.
    """
    _check_block_input(level, length, width, height)
    level = int(level)
    cache_dir = mesh_cache() if cache_dir is None else Path(cache_dir)
    cache_path = _block_cache_path(cache_dir, level, length, width, height)
    cached = _load_cached_block(cache_path)
    if cached is None:
        points, cells = _generate_block(level, length, width, height)
        try:
            _write_atomically(cache_path, points, cells)
        except OSError as error:
            warnings.warn(f"block mesh not cached in {cache_dir}: {error}", stacklevel=2)
    else:
        points, cells = cached
    source = f"block level {level} (L={length:g} m, W={width:g} m, H={height:g} m)"
    return FishMesh(points=points, cells=cells, source=source)


# ---------------------------------------------------------------------------------------------
# Imported meshes


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
        with _gmsh_model("aquarom_read", _GMSH_READ_OPTIONS) as gmsh:
            gmsh.merge(str(path))
            node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
            _, element_nodes = gmsh.model.mesh.getElementsByType(_GMSH_TETRAHEDRON)
    except Exception as error:
        raise InputError(f"mesh file {path}: gmsh cannot read it ({error})") from None
    if len(element_nodes) == 0:
        raise InputError(
            f"mesh file {path}: contains no linear tetrahedra (gmsh element type 4); "
            "mesh the volume with first-order tetrahedra"
        )
    try:
        return _points_and_cells_from_gmsh(node_tags, coordinates, element_nodes)
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


def _parse_abaqus(path: Path, text: str):
    """(node labels, node coordinates, tetrahedra as node labels) of an Abaqus input file."""
    node_labels, node_coordinates, tetrahedra = [], [], []
    for section, values, line_number in _abaqus_records(path, text):
        try:
            if len(values) != _ABAQUS_RECORD_LENGTH[section]:
                raise ValueError
            if section == "node":
                node_labels.append(int(values[0]))
                node_coordinates.append([float(value) for value in values[1:]])
            else:
                tetrahedra.append([int(value) for value in values[1:]])
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
    return _used_nodes_only(coordinates[first_positions], position)


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
    if not path.is_file():
        raise InputError(f"mesh file {path}: not found")
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
