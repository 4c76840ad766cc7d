"""Shape fields of one's own: a name, a value u(X) and its gradient ∇u(X), registered in this process
beside the catalogue of SPEC §4 and used by name in a scene's ``[shapes]``.

X are nominal positions relative to the body's bounding box, as the catalogue's fields take them:
(n, 3) rows (x, y, z) in metres with the head face at x = 0, the tail face at x = -L and y, z from
the box's centre line. The value returns the displacement U(X) per unit ξ, (n, 3) in metres; the
gradient G_ij = ∂U_i/∂X_j, (n, 3, 3), dimensionless. The design is x_ξ = x_0 + Σ_k ξ_k U_k (SPEC §1),
and the forms use F_1 = I + Σ_k ξ_k ∇U_k at their quadrature points (SPEC §4), so the gradient must
be the value's: ``aquarom_fenics.verification.shape_fields`` checks it with a Taylor test.

A registered field lives in the Python process that registered it: the Python API runs it, the
command line imports the module that registers it (``--shapes-module``), worker processes started
afresh (parallel sweeps, multistart pools) do not know it.

A scene's hash includes :func:`registered_fingerprint`: the digest of each registered field it uses
at the scene's own mesh, the value U at every displacement node (vertices, and edge midpoints at
degree 2) and the gradient ∇U at every quadrature point of the forms; so two fields that move any
node, or change F_1 anywhere, differently give two hashes. The geometry layer, which reads meshes,
provides those points (:func:`use_mesh_points`).
"""
from __future__ import annotations

import hashlib
import itertools
import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry import shapes

Value = Callable[[np.ndarray], np.ndarray]
"""(n, 3) relative positions X [m] -> (n, 3) displacement U(X) [m] per unit ξ."""
Gradient = Callable[[np.ndarray], np.ndarray]
"""(n, 3) relative positions X [m] -> (n, 3, 3) gradient ∂U_i/∂X_j."""

NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
RESERVED = ("amplitude", "design", "status", "distance_m", "tail_amplitude_m", "wall_time_s", "cached")
"""Names that a design's tables and outputs use beside the shape names."""

PROBE_DIVISIONS = 5
PROBE_BOX = (0.2, 0.04, 0.1)
"""L, W, H [m] of the probe box: the built-in block's default ``[mesh] length, width, height``."""


def probe_points() -> np.ndarray:
    """(125, 3) relative positions where a field is checked at registration: the centres of a 5 × 5 × 5
    grid of the built-in block's box (L × W × H = 0.2 × 0.04 × 0.1 m), all inside the body."""
    length, width, height = PROBE_BOX
    centres = (np.arange(PROBE_DIVISIONS) + 0.5) / PROBE_DIVISIONS
    x = -length * centres
    y = width * (centres - 0.5)
    z = height * (centres - 0.5)
    return np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1).reshape(-1, 3)


def evaluated(name: str, what: str, function, points: np.ndarray, tail: tuple[int, ...]) -> np.ndarray:
    """``function(points)`` as a float array of shape (n, *tail); InputError for another shape or a
    non-finite entry, naming the field and the first such point."""
    result = np.asarray(function(points), dtype=float)
    expected = (len(points), *tail)
    if result.shape != expected:
        raise InputError(f"shape field '{name}': its {what} returned an array of shape {result.shape} for "
                         f"{len(points)} points; expected {expected}")
    finite = np.isfinite(result.reshape(len(points), -1)).all(axis=1)
    if not finite.all():
        first = points[int(np.flatnonzero(~finite)[0])]
        raise InputError(f"shape field '{name}': its {what} is not finite at {int((~finite).sum())} of "
                         f"{len(points)} points, the first X = ({first[0]:.4g}, {first[1]:.4g}, {first[2]:.4g}) m "
                         "(relative to the box)")
    return result


MeshPoints = Callable[[object], tuple[str, np.ndarray, np.ndarray]]
"""scene -> (key of its mesh, (n, 3) relative displacement nodes, (m, 3) relative quadrature points)."""

_MESH_POINTS: list[MeshPoints] = []
_SERIALS = itertools.count(1)


def use_mesh_points(function: MeshPoints) -> None:
    """Take the scene's nodes and quadrature points from ``function`` (set by ``geometry.fish``)."""
    _MESH_POINTS[:] = [function]


@dataclass(frozen=True)
class RegisteredField:
    """A user's shape field; ``serial`` tells this registration from any other of the process
    (the same name registered again gets a new one)."""

    name: str
    value: Value
    gradient: Gradient
    serial: int

    def fingerprint_at(self, nodes: np.ndarray, points: np.ndarray) -> str:
        """SHA-256 (16 hex digits) of the name, U at the (n, 3) relative ``nodes`` and ∇U at the
        (m, 3) relative quadrature ``points`` (and of the points themselves)."""
        digest = hashlib.sha256(self.name.encode())
        for array in (nodes, evaluated(self.name, "value", self.value, nodes, (3,)),
                      points, evaluated(self.name, "gradient", self.gradient, points, (3, 3))):
            digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
        return digest.hexdigest()[:16]

    def displacement(self, x, y, z, box) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The catalogue's signature: (x, y, z) arrays of one shape -> (dx, dy, dz) of that shape."""
        points = np.stack([np.ravel(x), np.ravel(y), np.ravel(z)], axis=1).astype(float)
        u = evaluated(self.name, "value", self.value, points, (3,))
        return tuple(u[:, i].reshape(np.shape(x)) for i in range(3))

    def field_gradient(self, x, y, z, box) -> np.ndarray:
        """The catalogue's gradient signature: (x, y, z) arrays -> (n, 3, 3)."""
        points = np.stack([np.ravel(x), np.ravel(y), np.ravel(z)], axis=1).astype(float)
        return evaluated(self.name, "gradient", self.gradient, points, (3, 3))


_FIELDS: dict[str, RegisteredField] = {}


def _check_name(name) -> None:
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise InputError(f"shape field name {name!r}: use letters, digits and underscores, not starting with a "
                         "digit (it is a key of [shapes] and a column of the outputs)")
    if name in shapes.CATALOG:
        raise InputError(f"shape field '{name}': the name is the catalogue's field {name}; choose another name")
    if name in _FIELDS:
        raise InputError(f"shape field '{name}': already registered in this process; "
                         f"unregister_shape_field('{name}') first to replace it")
    if name in RESERVED:
        raise InputError(f"shape field '{name}': the name is reserved ({', '.join(RESERVED)}); choose another name")


def register_shape_field(name: str, value: Value, gradient: Gradient, points=None) -> RegisteredField:
    """Register the field ``name`` with its value U(X) and gradient ∇U(X) (module docstring).

    Both are called once at ``points`` ((n, 3) relative positions [m], default
    :func:`probe_points`) and must return finite arrays of shape (n, 3) and (n, 3, 3) there.
    InputError (one line) for a bad name, a name taken, a function that is not callable, a wrong
    shape or a non-finite value. Returns the registered field.
    """
    _check_name(name)
    for what, function in (("value", value), ("gradient", gradient)):
        if not callable(function):
            raise InputError(f"shape field '{name}': its {what} must be a function of X ((n, 3) array), "
                             f"got {type(function).__name__}")
    probe = probe_points() if points is None else np.asarray(points, dtype=float)
    if probe.ndim != 2 or probe.shape[1] != 3 or len(probe) == 0 or not np.all(np.isfinite(probe)):
        raise InputError(f"shape field '{name}': points must be a finite (n, 3) array of relative positions, "
                         f"got shape {probe.shape}")
    evaluated(name, "value", value, probe, (3,))
    evaluated(name, "gradient", gradient, probe, (3, 3))
    field = RegisteredField(name, value, gradient, next(_SERIALS))
    _FIELDS[name] = field
    shapes.REGISTERED[name] = (field.displacement, field.field_gradient)
    return field


def unregister_shape_field(name: str) -> None:
    """Forget the registered field ``name``; InputError if none is registered by that name."""
    if name not in _FIELDS:
        raise InputError(f"shape field '{name}': not registered in this process "
                         f"(registered: {', '.join(_FIELDS) or 'none'})")
    serial = _FIELDS.pop(name).serial
    del shapes.REGISTERED[name]
    for key in [key for key in _DIGESTS if key[0] == serial]:
        del _DIGESTS[key]


def registered_fields() -> dict[str, RegisteredField]:
    """The fields registered in this process, by name (a copy)."""
    return dict(_FIELDS)


def uses_registered(names) -> bool:
    """Whether any of ``names`` is a field registered in this process."""
    return any(name in _FIELDS for name in names)


def registered_identity(names) -> str:
    """Which registrations of this process the registered fields among ``names`` are ('' when none)."""
    return ";".join(f"{name}#{_FIELDS[name].serial}" for name in names if name in _FIELDS)


_DIGESTS: dict[tuple[int, str], str] = {}
"""Fingerprints by (serial, mesh key): a scene's hash is asked for often, its mesh read once."""


def registered_fingerprint(names, scene) -> str:
    """The fingerprints (:meth:`RegisteredField.fingerprint_at`) of the registered fields among
    ``names`` at the nodes and quadrature points of ``scene``'s mesh, joined ('' when there are none:
    a scene of the catalogue's fields reads no mesh for its hash)."""
    used = [_FIELDS[name] for name in names if name in _FIELDS]
    if not used:
        return ""
    if not _MESH_POINTS:
        raise RuntimeError("a scene with a registered shape field is hashed at its mesh's points: import "
                           "aquarom_fenics.api (or aquarom_fenics.geometry.fish) first")
    key, nodes, points = _MESH_POINTS[0](scene)
    for field in used:
        if (field.serial, key) not in _DIGESTS:
            _DIGESTS[(field.serial, key)] = field.fingerprint_at(nodes, points)
    return ";".join(f"{field.name}={_DIGESTS[(field.serial, key)]}" for field in used)
