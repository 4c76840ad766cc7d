"""Parametric reduced-order model (SPEC §8): tensors, evaluation at ξ, file format.

    M_r(ξ) η̈ + C_r(ξ) η̇ + f_int,r(η; ξ) = f_thrust,r + f_drag,r + f_act,r

Every ξ-dependent tensor is a Taylor polynomial in Δξ = ξ - ξ_c around the design the PROM was
built on; the thrust is evaluated exactly on the reduced station kinematics B V η (its virtual
mass is quadratic in ξ, its rest stations linear).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import get_args, get_type_hints

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.persistence import write_npz_atomic
from aquarom_fenics.physics.drag import DragTensors
from aquarom_fenics.physics.elastic import ElasticTensors
from aquarom_fenics.physics.inertia import InertiaTensors
from aquarom_fenics.physics.muscle import MuscleTensors
from aquarom_fenics.physics.thrust_reduced import ThrustTensors

FORMAT_VERSION = 5
"""2: the tensors grouped per force term (elastic, muscle, inertia, drag, thrust, observation);
3: the thrust's kinematic rows (stations) and the drag's reference-velocity row;
4: the tail's x row and the mass moment in y (tail x and centre-of-mass y observed);
5: the hash of what the build read (``Scene.prom_hash``), which identifies the PROM's scene."""
MAX_PROM_FILE_BYTES = 16 * 1024 ** 3
"""Largest PROM file read [bytes]."""
ZIP_MAGIC = b"PK\x03\x04"       # first bytes of a .npz (zip) archive


@dataclass
class Observation:
    """Rows of V giving the observed displacements [m] from η."""

    head_x_row: np.ndarray               # (m,) the head's average x (the head spine node's with stations = "nodes")
    tail_y_row: np.ndarray               # (m,) the tail station's average y (the tail node's with stations = "nodes")
    tail_x_row: np.ndarray               # (m,) the same point's x


@dataclass
class ReducedModel:
    """All a reduced simulation needs; arrays are plain numpy, identical on every rank."""

    scene_hash: str                      # the scene it was built with (``Scene.hash``)
    prom_hash: str                       # what its build read of that scene (``Scene.prom_hash``)
    software_version: str
    shape_names: list[str]               # the PROM's parameters (none for a plain ROM)
    design_point: dict                   # the scene's shape parameters at the building point
    xi_center: np.ndarray               # ξ_c, the design the basis and tensors were built on
    validity_radius: np.ndarray          # per parameter, |ξ - ξ_c|_k inside which the PROM is trusted
    labels: list[str]                    # basis vector names
    basis: np.ndarray                    # V at the input-mesh nodes, (n_nodes, 3, m), Vᵀ M V = I
    dropped: list[str]                   # candidate vectors dropped as dependent
    frequencies: np.ndarray              # Hz, vibration modes of the basis
    elastic: ElasticTensors              # f_int,r
    muscle: MuscleTensors                # f_act,r (zero tensors when the muscles are off)
    inertia: InertiaTensors              # M_r, C_r and the centre of mass
    drag: DragTensors | None             # f_drag,r, None when drag is off
    thrust: ThrustTensors | None            # f_thrust,r, None when thrust is off
    observation: Observation
    cells: int
    dofs: int
    timings: dict = field(default_factory=dict)
    head_elastic: ElasticTensors | None = None   # the head cells' share of ``elastic`` (calibration of its factor)

    @property
    def size(self) -> int:
        return self.inertia.mass.constant.shape[0]

    @property
    def n_parameters(self) -> int:
        return len(self.shape_names)

    def delta(self, xi: np.ndarray) -> np.ndarray:
        """Δξ = ξ - ξ_c, refused beyond the validity radius."""
        xi = np.asarray(xi, dtype=float)
        self.refuse_outside_radius(self.shape_names, xi, self.xi_center, self.validity_radius)
        return xi - self.xi_center

    @staticmethod
    def refuse_outside_radius(names, xi, center, radius) -> None:
        """InputError naming the parameters with |ξ - ξ_c|_k beyond their validity radius."""
        outside = np.abs(xi - center) > radius * (1 + 1e-12)
        if np.any(outside):
            values = [f"{name}={value:g}" for name, value, out in zip(names, xi, outside) if out]
            raise InputError(
                f"design {', '.join(values)} is outside the PROM's validity radius "
                f"{', '.join(f'{r:g}' for r, o in zip(radius, outside) if o)} around its building "
                f"point {dict(zip(names, np.round(center, 6).tolist()))}; build a PROM nearer")

    def term_arrays(self) -> dict[str, np.ndarray]:
        """Every array of the per-term tensors by dotted name, e.g. "elastic.linear.constant"."""
        arrays = {}
        for name in ("elastic", "muscle", "inertia", "drag", "thrust"):
            if getattr(self, name) is not None:
                _flatten(getattr(self, name), name + ".", arrays, {})
        return arrays

    # ------------------------------------------------------------------ file format
    def save(self, path: Path) -> None:
        """One .npz file: arrays under dotted names ("elastic.linear.constant") plus a JSON header with
        the format version, scene and PROM hashes, software version, labels, scalars and timings."""
        arrays, header = {}, {"format_version": FORMAT_VERSION}
        _flatten(self, "", arrays, header)
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_npz_atomic(path, arrays)     # unique temporary name, atomic replace: concurrent writers never collide

    @classmethod
    def load(cls, path: Path, scene_hash: str | None = None, prom_hash: str | None = None) -> "ReducedModel":
        """Read a PROM file; refuses another format's or another version's file, and with ``prom_hash``
        (``Scene.prom_hash``) one built from other values than a PROM reads of the scene (with ``scene_hash``,
        ``Scene.hash``, one built from another scene file or other values anywhere in it), naming the difference."""
        from aquarom_fenics import __version__

        from aquarom_fenics.io.readback import require_regular_file

        path = Path(path)
        if path.exists() or path.is_symlink():
            require_regular_file(path, "PROM file", MAX_PROM_FILE_BYTES)      # no FIFO, device or link loop
        if path.is_file() and _first_bytes(path, 4) != ZIP_MAGIC:
            content = "an empty file" if path.stat().st_size == 0 else "not a .npz archive"
            raise InputError(f"PROM file {path}: {content}, not a PROM file (write one with `aquarom build SCENE`)")
        try:
            with np.load(path) as data:
                arrays = {key: data[key] for key in data.files}
            header = json.loads(arrays.pop("header").tobytes().decode())
        except FileNotFoundError:
            raise InputError(f"PROM file {path}: not found (build one with `aquarom build SCENE`)") from None
        except Exception as error:  # zip, JSON and key errors of a damaged file
            raise InputError(f"PROM file {path}: unreadable ({type(error).__name__}: {error})") from None
        if isinstance(header, dict) and header.get("format_version") != FORMAT_VERSION:
            raise InputError(f"PROM file {path}: format version {header.get('format_version')} (aquarom_fenics "
                             f"{header.get('software_version')}), this version reads format {FORMAT_VERSION}; "
                             "rebuild it with `aquarom build SCENE`")
        problem = _header_problem(header)
        if problem:
            raise InputError(f"PROM file {path}: damaged header ({problem}); rebuild it with `aquarom build SCENE`")
        if header.get("software_version") != __version__:
            raise InputError(f"PROM file {path}: written by aquarom_fenics {header.get('software_version')}, "
                             f"this is {__version__}; rebuild it with `aquarom build SCENE`")
        if scene_hash is not None and header["scene_hash"] != scene_hash:
            raise InputError(f"PROM file {path}: built for scene hash {header['scene_hash']}, the scene's hash is "
                             f"{scene_hash} (a different scene or changed values); rebuild it")
        if prom_hash is not None and header["prom_hash"] != prom_hash:
            raise InputError(f"PROM file {path}: built for other scene values (PROM hash {header['prom_hash']}, this "
                             f"scene's {prom_hash}: the mesh, material, regions, muscles, actuation, fluid, solver, "
                             "reduction, shapes or gait differ); rebuild it with `aquarom build SCENE`")
        try:
            model = _unflatten(cls, "", arrays, header)
        except (KeyError, TypeError, ValueError) as missing:
            raise InputError(f"PROM file {path}: unreadable (missing array or value {missing}); "
                             "rebuild it with `aquarom build SCENE`") from None
        problem = _array_problem(model, arrays)
        if problem:
            raise InputError(f"PROM file {path}: the header does not match its arrays ({problem}); "
                             "rebuild it with `aquarom build SCENE`")
        return model


HEADER_TEXT_LISTS = ("shape_names", "labels", "dropped")
"""Header keys that are lists of names."""


def _header_problem(header) -> str:
    """What makes a PROM header unusable (not an object, a name list or the scene hash missing or of
    the wrong type), or an empty string."""
    if not isinstance(header, dict):
        return f"a JSON object is needed, got {type(header).__name__}"
    for key in ("scene_hash", "prom_hash"):
        if not isinstance(header.get(key), str):
            return f"{key} must be a string, got {header.get(key)!r:.40}"
    for key in HEADER_TEXT_LISTS:
        value = header.get(key)
        if not isinstance(value, list) or not all(isinstance(name, str) for name in value):
            return f"{key} must be a list of names, got {value!r:.40}"
    if len(set(header["shape_names"])) != len(header["shape_names"]):
        return "shape_names names a parameter twice"
    if not isinstance(header.get("design_point"), dict):
        return f"design_point must be an object, got {header.get('design_point')!r:.40}"
    return ""


def _array_problem(model: "ReducedModel", arrays: dict) -> str:
    """How the header's counts disagree with the arrays (p = len(shape_names) parameters, m =
    len(labels) basis vectors), or an empty string: ξ_c and the radii have p entries, V is
    (n, 3, m), every Taylor term's first and second derivatives are (p, …) and (p, p, …) of its
    constant, every ξ-gradient of the thrust ends in p."""
    p, m = len(model.shape_names), len(model.labels)
    for name in ("xi_center", "validity_radius"):
        value = np.asarray(getattr(model, name))
        if value.shape != (p,):
            return f"{name} has shape {value.shape}, shape_names {p} parameter(s)"
    basis = np.asarray(model.basis)
    if basis.ndim != 3 or basis.shape[1:] != (3, m):
        return f"basis has shape {basis.shape}, labels {m} vector(s)"
    for key, value in arrays.items():
        if not isinstance(value, np.ndarray):
            continue
        stem, _, kind = key.rpartition(".")
        constant = arrays.get(f"{stem}.constant")
        if kind == "first" and constant is not None and value.shape != (p, *constant.shape):
            return f"{key} has shape {value.shape}, expected {(p, *constant.shape)} for shape_names {p}"
        if kind == "second" and constant is not None and value.shape != (p, p, *constant.shape):
            return f"{key} has shape {value.shape}, expected {(p, p, *constant.shape)}"
        if key.endswith("_gradient") and (value.ndim == 0 or value.shape[-1] != p):
            return f"{key} has shape {value.shape}, its last axis must be shape_names' {p}"
    mass = np.asarray(model.inertia.mass.constant)
    if mass.shape != (m, m):
        return f"inertia.mass.constant has shape {mass.shape}, labels {m} vector(s)"
    return ""


def _flatten(record, prefix: str, arrays: dict, header: dict) -> None:
    """Arrays of a (nested) dataclass under dotted names; every other value, and None, in the header."""
    for item in fields(record):
        name, value = prefix + item.name, getattr(record, item.name)
        if is_dataclass(value):
            _flatten(value, name + ".", arrays, header)
        elif isinstance(value, np.ndarray):
            arrays[name] = value
        else:
            header[name] = value


def _unflatten(cls, prefix: str, arrays: dict, header: dict):
    """The inverse of :func:`_flatten` for the dataclass ``cls``."""
    hints = get_type_hints(cls)
    values = {}
    for item in fields(cls):
        name = prefix + item.name
        if name in arrays:
            values[item.name] = arrays[name]
        elif name in header:
            values[item.name] = header[name]
        else:
            record_type = _record_type(hints[item.name])
            if record_type is None:          # an array (or value) the file lacks
                raise KeyError(name)
            values[item.name] = _unflatten(record_type, name + ".", arrays, header)
    return cls(**values)


def _record_type(hint):
    """The dataclass of a field annotated ``Record`` or ``Record | None``."""
    arguments = get_args(hint)
    if not arguments:
        return hint if is_dataclass(hint) else None
    return next((arg for arg in arguments if is_dataclass(arg)), None)


def _first_bytes(path: Path, count: int) -> bytes:
    with open(path, "rb") as stream:
        return stream.read(count)
