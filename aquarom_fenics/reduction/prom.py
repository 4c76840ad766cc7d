"""Parametric reduced-order model (SPEC §8): tensors, evaluation at ξ, file format.

    M_r(ξ) η̈ + C_r(ξ) η̇ + f_int,r(η; ξ) = f_thrust,r + f_drag,r + f_act,r

Every ξ-dependent tensor is a Taylor polynomial in Δξ = ξ - ξ_c around the design the PROM was
built on; the thrust is evaluated exactly on the reduced spine coordinates (its virtual mass is
quadratic in ξ, its geometry does not move with the catalog's shape variations).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.persistence import write_npz_atomic

FORMAT_VERSION = 1
ZIP_MAGIC = b"PK\x03\x04"       # first bytes of a .npz (zip) archive


@dataclass
class Taylor:
    """T(Δξ) = T0 + Σ_k Δξ_k T1[k] + ½ Σ_kl Δξ_k Δξ_l T2[k, l] (T1, T2 absent below the order)."""

    constant: np.ndarray
    first: np.ndarray | None = None
    second: np.ndarray | None = None

    def at(self, delta: np.ndarray) -> np.ndarray:
        value = np.array(self.constant, dtype=float)
        if self.first is not None and delta.size:
            value = value + np.tensordot(delta, self.first, axes=1)
        if self.second is not None and delta.size:
            value = value + 0.5 * np.tensordot(delta, np.tensordot(delta, self.second, axes=1), axes=1)
        return value

    def gradient(self, delta: np.ndarray) -> np.ndarray:
        """∂T/∂ξ_k at Δξ, shape (p, ...)."""
        if self.first is None:
            return np.zeros((delta.size,) + np.shape(self.constant))
        value = np.array(self.first, dtype=float)
        if self.second is not None:
            value = value + np.tensordot(delta, self.second, axes=1)
        return value


TAYLOR_FIELDS = ("mass", "stiffness_linear", "stiffness_quadratic", "stiffness_cubic",
                 "actuation_constant", "actuation_linear", "drag", "mass_moment_x", "total_mass")


@dataclass
class ReducedModel:
    """All a reduced simulation needs; arrays are plain numpy, identical on every rank."""

    scene_hash: str
    software_version: str
    shape_names: list[str]               # the PROM's parameters (none for a plain ROM)
    design_point: dict                   # the scene's shape parameters at the building point
    xi_center: np.ndarray               # ξ_c, the design the basis and tensors were built on
    validity_radius: np.ndarray          # per parameter, |ξ - ξ_c|_k inside which the PROM is trusted
    labels: list[str]                    # basis vector names
    basis: np.ndarray                    # V at the input-mesh nodes, (n_nodes, 3, m), Vᵀ M V = I
    dropped: list[str]                   # candidate vectors dropped as dependent
    frequencies: np.ndarray              # Hz, vibration modes of the basis
    mass: Taylor                         # M_r (m, m)
    stiffness_linear: Taylor             # K1 (m, m); also K_0,r of the Rayleigh damping
    stiffness_quadratic: Taylor          # K2 (m, m, m)
    stiffness_cubic: Taylor              # K3 (m, m, m, m)
    actuation_constant: Taylor           # b_j (2, m): ∂Π_act,j/∂u at rest for a_j = 1 (left, right)
    actuation_linear: Taylor             # B_j (2, m, m): ∂²Π_act,j/∂u² for a_j = 1
    drag: Taylor                         # g_r (m,), zero when drag is off
    mass_moment_x: Taylor                # Vᵀ ∫ρ φ·e_x dV_ξ (m,)
    total_mass: Taylor                   # ∫ρ dV_ξ ()
    spine_rows: np.ndarray               # (n_spine, 2, m): x-y rows of V at the spine nodes
    spine_rest_xy: np.ndarray            # (n_spine, 2) at ξ_c
    dorsal_z: np.ndarray                 # (n_segments,) z_dorsal - z_axis at ξ_c
    dorsal_z_gradient: np.ndarray        # (n_segments, p) ∂z_dorsal/∂ξ (U rows: exact)
    head_x_row: np.ndarray               # (m,) row of V at the head spine node's x dof
    tail_y_row: np.ndarray               # (m,) row of V at the tail node's y dof
    rayleigh: tuple[float, float]        # (α_R, β_R)
    fluid_density: float
    thrust: bool
    drag_on: bool
    cells: int
    dofs: int
    timings: dict = field(default_factory=dict)

    @property
    def size(self) -> int:
        return self.mass.constant.shape[0]

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

    # ------------------------------------------------------------------ file format
    def save(self, path: Path) -> None:
        """One .npz file: arrays plus a JSON header with scene hash, version, labels and timings."""
        arrays, header = {}, {"format_version": FORMAT_VERSION}
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, Taylor):
                for part in ("constant", "first", "second"):
                    if getattr(value, part) is not None:
                        arrays[f"{item.name}.{part}"] = getattr(value, part)
            elif isinstance(value, np.ndarray):
                arrays[item.name] = value
            else:
                header[item.name] = value
        arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_npz_atomic(path, arrays)     # unique temporary name, atomic replace: concurrent writers never collide

    @classmethod
    def load(cls, path: Path, scene_hash: str | None = None) -> "ReducedModel":
        """Read a PROM file; refuses another scene's or another version's file, naming the difference."""
        from aquarom_fenics import __version__

        path = Path(path)
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
        if header.get("format_version") != FORMAT_VERSION or header.get("software_version") != __version__:
            raise InputError(f"PROM file {path}: written by aquarom_fenics {header.get('software_version')} "
                             f"(format {header.get('format_version')}), this is {__version__} (format "
                             f"{FORMAT_VERSION}); rebuild it")
        if scene_hash is not None and header["scene_hash"] != scene_hash:
            raise InputError(f"PROM file {path}: built for scene hash {header['scene_hash']}, the scene's hash is "
                             f"{scene_hash} (a different scene or changed values); rebuild it")
        values = {}
        for item in fields(cls):
            if item.name in TAYLOR_FIELDS:
                values[item.name] = Taylor(*(arrays.get(f"{item.name}.{part}") for part in ("constant", "first", "second")))
            elif item.name in arrays:
                values[item.name] = arrays[item.name]
            else:
                values[item.name] = header[item.name]
        values["rayleigh"] = tuple(values["rayleigh"])
        return cls(**values)


def _first_bytes(path: Path, count: int) -> bytes:
    with open(path, "rb") as stream:
        return stream.read(count)
