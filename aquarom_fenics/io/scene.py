"""Scene files: one TOML file that fully describes a study (SPEC §1).

Every section is a frozen dataclass whose fields carry the SPEC defaults. Loading checks every
key and value and raises :class:`InputError` with one line naming the file, the key and what
would be valid. ``Scene.hash`` identifies the resolved study (values, not formatting).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import shipped_scenes

SCENES_DIR = shipped_scenes()


def _positive(value) -> str | None:
    return None if value > 0 else "must be > 0"


def _non_negative(value) -> str | None:
    return None if value >= 0 else "must be >= 0"


def _one_of(*choices):
    def check(value) -> str | None:
        return None if value in choices else f"must be one of {', '.join(map(repr, choices))}"
    return check


def _spec(default, check=None, doc="", variable_length=False):
    """A scene field: its default, an optional validity check and a unit/meaning for the docs."""
    return field(default=default, metadata={"check": check, "doc": doc, "variable_length": variable_length})


def _interval_within(low, high):
    def check(value) -> str | None:
        lower, upper = value
        return None if low <= lower < upper <= high else f"must be [lower, upper] with {low} <= lower < upper <= {high}"
    return check


@dataclass(frozen=True)
class MeshSection:
    level: int = _spec(3, _one_of(1, 2, 3, 4, 5), "refinement level of the built-in block (1: ~1.3k … 5: ~25k cells)")
    degree: int = _spec(1, _one_of(1, 2), "Lagrange degree of the displacement (1: linear, 2: quadratic tetrahedra)")
    file: str = _spec("", None, "external mesh (.msh or .inp), relative to the scene file; overrides level")
    scale: float = _spec(1.0, _positive, "factor applied to the file's coordinates (to metres)")
    translate: tuple[float, float, float] = _spec((0.0, 0.0, 0.0), None, "shift after scaling [m]")
    length: float = _spec(0.20, _positive, "block length L along x [m]")
    width: float = _spec(0.04, _positive, "block width W along y [m]")
    height: float = _spec(0.10, _positive, "block height H along z [m]")


@dataclass(frozen=True)
class MaterialSection:
    young_modulus: float = _spec(260e3, _positive, "E [Pa]")
    poisson_ratio: float = _spec(0.4, lambda v: None if -1 < v < 0.5 else "must be in (-1, 0.5)", "ν")
    density: float = _spec(1070.0, _positive, "ρ [kg/m³]")
    head_stiffness_factor: float = _spec(100.0, _positive, "head E = factor × E")
    rayleigh_alpha: float = _spec(3.1, _non_negative, "α_R [1/s] in C = α_R M + β_R K_0")
    rayleigh_beta: float = _spec(6.3e-6, _non_negative, "β_R [s]")
    mass: str = _spec("consistent", _one_of("consistent", "lumped"), "mass matrix")


@dataclass(frozen=True)
class RegionsSection:
    head_fraction: float = _spec(0.35, lambda v: None if 0 < v < 1 else "must be in (0, 1)", "head: centroid x ≥ -fraction·L")
    muscle_range: tuple[float, float] = _spec((-0.95, -0.35), _interval_within(-1.0, 0.0), "muscles: -a·L < centroid x < -b·L, as [-a, -b]")


@dataclass(frozen=True)
class ActuationSection:
    stiffness: float = _spec(6e4, _non_negative, "muscle stiffness k [Pa]")
    amplitude: float = _spec(0.2, _non_negative, "A in a_left = A sin(2π f t), a_right = -a_left")
    frequency: float = _spec(1.0, _positive, "f [Hz]")
    muscle_volume: str = _spec("shape", _one_of("shape", "nominal"), "muscle energy over the shape-varied (SPEC default) or nominal volume")


@dataclass(frozen=True)
class FluidSection:
    density: float = _spec(1000.0, _positive, "ρ_w [kg/m³]")
    thrust: bool = _spec(True, None, "Lighthill reactive thrust on the spine")
    drag: bool = _spec(True, None, "form drag on the skin")
    spine_force: str = _spec("source", _one_of("source", "lagrangian"), "spine force -d/dt(∂T_a/∂v) ('source') or with +∂T_a/∂x ('lagrangian', exchanges no energy by itself)")


@dataclass(frozen=True)
class ShapeSpec:
    name: str
    lower: float
    upper: float
    start: float = 0.0
    radius: float | None = None     # PROM validity radius; None: [reduction] validity_fraction × max |bound|


@dataclass(frozen=True)
class LinearConstraint:
    """lower ≤ Σ_k coefficients[k] ξ_k ≤ upper (either bound may be infinite)."""
    coefficients: tuple[tuple[str, float], ...]
    lower: float = -math.inf
    upper: float = math.inf


@dataclass(frozen=True)
class SolverSection:
    time_step: float = _spec(0.02, _positive, "time step h [s]")
    duration: float = _spec(2.0, lambda v: None if v >= 0.1 else "must be ≥ 0.1 s (the distance averages the last 0.1 s)", "horizon T [s]")
    integrator: str = _spec("generalized-alpha", _one_of("generalized-alpha", "newmark"), "time scheme (SPEC §6)")
    rho_infinity: float = _spec(0.8, lambda v: None if 0 <= v <= 1 else "must be in [0, 1]", "ρ∞ of generalized-α: spectral radius at h ω → ∞ (README: how it was chosen)")
    # SPEC §6 gives α_N = 0.005 for the source's Newmark; with it a high-frequency oscillation of the
    # spine nodes grows under the Lighthill forces on finer meshes (levels 4-5) and on thin optimal
    # designs, and the FOM stops near t = 1.9 s. α_N = 0.02 damps it (nominal distance -2 %).
    newmark_alpha: float = _spec(0.02, lambda v: None if 0 <= v < 0.5 else "must be in [0, 0.5)", "α_N of integrator = \"newmark\": γ = ½ + α_N, β = (1 + α_N)²/4 (SPEC: 0.005)")
    min_time_step: float = _spec(1e-3, _positive, "a step whose Newton fails is retried with h/2, h/4, … down to this [s]")
    tolerance: float = _spec(1e-6, _positive, "relative Newton tolerance")
    max_iterations: int = _spec(30, _positive, "Newton iterations per step")


@dataclass(frozen=True)
class ReductionSection:
    basis: str = _spec("default", _one_of("default", "paper"), "'paper' drops the actuation modes ψ, θ_ψ")
    vibration_modes: int = _spec(1, _positive, "number of vibration modes n_vm")
    modal_derivatives: bool = _spec(True, None, "static modal derivatives θ_ij")
    taylor_order: int = _spec(1, _one_of(1, 2), "order of the PROM's Taylor expansion in ξ")
    drop_tolerance: float = _spec(1e-8, _positive, "basis vectors whose remaining mass-norm is below this are dropped")
    validity_fraction: float = _spec(0.25, _positive, "PROM validity radius of a parameter as a fraction of its largest |bound| (a shape's own `radius` overrides it)")


@dataclass(frozen=True)
class OptimizerSection:
    method: str = _spec("paper", _one_of("paper", "trust-region"), "optimisation algorithm")
    max_iterations: int = _spec(100, _positive, "iterations (a safeguard: the optimisers stop on optimality_tolerance)")
    step_size: float = _spec(0.05, _positive, "γ in ξ ← ξ - γ W ∇L; W starts at 1/‖∇L_0‖_∞, so γ is the first step (paper)")
    barrier_weight: float = _spec(1e-3, _positive, "log-barrier weight (paper)")
    rebuild_threshold: float = _spec(0.15, _positive, "rebuild the PROM when any |ξ - ξ_c| exceeds this (paper)")
    n_rebuild: int = _spec(5, _positive, "rebuild the PROM every n iterations (paper)")
    step_tolerance: float = _spec(1e-3, _positive, "stop (stalled before optimality) when ‖Δξ‖ falls below")
    cost_tolerance: float = _spec(1e-4, _positive, "stop (stalled before optimality) when the predicted relative cost reduction falls below (trust-region)")
    initial_radius: float = _spec(1.0, lambda v: None if 0 < v <= 1 else "must be in (0, 1]", "trust radius as a fraction of the PROM validity radius (trust-region)")
    accept_ratio: float = _spec(0.1, lambda v: None if 0 <= v < 1 else "must be in [0, 1)", "accept a step when actual/predicted reduction exceeds this")
    optimality_tolerance: float = _spec(1e-2, _positive, "stop when the first-order measure ‖D r‖_∞ / |L| (KKT residual r, D the parameter ranges) falls below")
    active_tolerance: float = _spec(1e-2, _positive, "a bound or linear constraint is active when its slack is below this fraction of its range")
    starts: int = _spec(1, _positive, "optimisations from the start point and starts - 1 Latin-hypercube feasible points")
    seed: int = _spec(0, _non_negative, "seed of the Latin-hypercube starts")


@dataclass(frozen=True)
class CooptimizationSection:
    enabled: bool = _spec(False, None, "optimise the actuation amplitude A too")
    amplitude_bounds: tuple[float, float] = _spec((0.05, 0.4), _interval_within(0.0, math.inf), "bounds of A")
    weights: tuple[float, ...] = _spec((0.2, 0.3, 0.4, 0.5, 0.7, 0.9, 0.98), lambda v: None if v and all(0 <= w <= 1 for w in v) else "must be a non-empty list of numbers in [0, 1]", "w_1 sweep, w_2 = 1 - w_1", variable_length=True)
    energy_weight: float = _spec(1.0, _non_negative, "α in L = w_1 (-d) + w_2 α A²")


@dataclass(frozen=True)
class OutputSection:
    xdmf: bool = _spec(False, None, "write displacement time series as XDMF")
    render: bool = _spec(True, None, "render PNG pictures with pyvista")
    plots: bool = _spec(True, None, "write matplotlib PNG plots")


SECTIONS = {
    "mesh": MeshSection,
    "material": MaterialSection,
    "regions": RegionsSection,
    "actuation": ActuationSection,
    "fluid": FluidSection,
    "solver": SolverSection,
    "reduction": ReductionSection,
    "optimizer": OptimizerSection,
    "cooptimization": CooptimizationSection,
    "output": OutputSection,
}


@dataclass(frozen=True)
class Scene:
    name: str = "scene"
    description: str = ""
    source: str = "<defaults>"
    base_dir: str = "."
    mesh: MeshSection = MeshSection()
    material: MaterialSection = MaterialSection()
    regions: RegionsSection = RegionsSection()
    actuation: ActuationSection = ActuationSection()
    fluid: FluidSection = FluidSection()
    shapes: tuple[ShapeSpec, ...] = ()
    constraints: tuple[LinearConstraint, ...] = ()
    solver: SolverSection = SolverSection()
    reduction: ReductionSection = ReductionSection()
    optimizer: OptimizerSection = OptimizerSection()
    cooptimization: CooptimizationSection = CooptimizationSection()
    output: OutputSection = OutputSection()

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        """Read and validate a scene file; a bare name like ``so1`` means ``scenes/so1.toml``."""
        path = resolve_scene_path(path)
        try:
            data = tomllib.loads(path.read_text())
        except tomllib.TOMLDecodeError as error:
            raise InputError(f"scene {path}: malformed TOML ({error})") from None
        except UnicodeDecodeError:
            raise InputError(f"scene {path}: not a UTF-8 text file") from None
        except OSError as error:
            raise InputError(f"scene {path}: cannot be read ({error.strerror})") from None
        return scene_from_dict(data, source=str(path), base_dir=str(path.parent))

    @property
    def shape_names(self) -> list[str]:
        return [shape.name for shape in self.shapes]

    def validity_radii(self) -> list[float]:
        """PROM validity radius per shape parameter (SPEC §8)."""
        fraction = self.reduction.validity_fraction
        return [s.radius if s.radius is not None else fraction * max(abs(s.lower), abs(s.upper)) for s in self.shapes]

    @property
    def mesh_file(self) -> Path | None:
        if not self.mesh.file:
            return None
        return (Path(self.base_dir) / self.mesh.file).resolve()

    @property
    def n_steps(self) -> int:
        """Number of Newmark steps, round(T / h)."""
        return int(round(self.solver.duration / self.solver.time_step))

    def to_dict(self) -> dict[str, Any]:
        """The resolved scene (defaults filled), without where it was read from."""
        data = dataclasses.asdict(self)
        data.pop("source")
        data.pop("base_dir")
        if self.mesh_file is not None:
            data["mesh"]["file"] = str(self.mesh_file)
        return data

    @property
    def hash(self) -> str:
        """SHA-256 (16 hex digits) of the resolved scene and of the mesh file's content."""
        digest = hashlib.sha256(json.dumps(self.to_dict(), sort_keys=True, default=str).encode())
        if self.mesh_file is not None and self.mesh_file.exists():
            digest.update(self.mesh_file.read_bytes())
        return digest.hexdigest()[:16]

    def replace(self, section: str, **values) -> "Scene":
        """A copy with some values of one section changed (validated like a file)."""
        current = getattr(self, section)
        merged = dataclasses.asdict(current) | values
        return dataclasses.replace(self, **{section: _section_from_dict(SECTIONS[section], merged, f"scene {self.source}", section)})


def resolve_scene_path(path: str | Path) -> Path:
    candidate = Path(path)
    if not candidate.exists() and candidate.suffix == "" and (SCENES_DIR / f"{candidate}.toml").exists():
        candidate = SCENES_DIR / f"{candidate}.toml"
    if not candidate.is_file():
        shipped = ", ".join(sorted(p.stem for p in SCENES_DIR.glob("*.toml")))
        raise InputError(f"scene {path}: file not found (give a path to a .toml file or one of: {shipped})")
    return candidate


def scene_from_dict(data: dict[str, Any], source: str = "<dict>", base_dir: str = ".") -> Scene:
    where = f"scene {source}"
    known = {"name", "description", "shapes", "constraints", *SECTIONS}
    for key in data:
        if key not in known:
            raise InputError(f"{where}: unknown key '{key}'; valid top-level keys: {', '.join(sorted(known))}")
    name = data.get("name", Path(source).stem)
    description = data.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise InputError(f"{where}: '{key}' must be a string, got {value!r}")
    if not _plain_file_name(name):
        raise InputError(f"{where}: name = {name!r} must be a plain folder name (printable, no '/' or '\\', "
                         "not '.' or '..', not starting with '-'): it names the default output folder")
    sections = {key: _section_from_dict(cls, _table(data, key, where), where, key) for key, cls in SECTIONS.items()}
    shapes = _shapes_from_dict(_table(data, "shapes", where), where)
    constraints = _constraints_from_list(data.get("constraints", []), shapes, where)
    return Scene(name=name, description=description, source=source, base_dir=base_dir,
                 shapes=shapes, constraints=constraints, **sections)


def _plain_file_name(name: str) -> bool:
    """A name that stays one folder inside results/ (no path separators, not '.' or '..', printable)."""
    return (name.strip() not in ("", ".", "..") and not any(c in name for c in "/\\")
            and name.isprintable() and not name.startswith("-") and len(name) <= 100)


def _table(data, key, where) -> dict:
    table = data.get(key, {})
    if not isinstance(table, dict):
        raise InputError(f"{where}: [{key}] must be a table, got {table!r}")
    return table


def _section_from_dict(cls, table: dict, where: str, section: str):
    fields = {f.name: f for f in dataclasses.fields(cls)}
    values = {}
    for key, value in table.items():
        if key not in fields:
            raise InputError(f"{where}: unknown key [{section}] {key}; valid keys: {', '.join(fields)}")
        spec = fields[key]
        value = _coerce(value, spec.default, f"{where}: [{section}] {key}", spec.metadata["variable_length"])
        check = spec.metadata.get("check")
        problem = check(value) if check else None
        if problem:
            raise InputError(f"{where}: [{section}] {key} = {value!r} {problem}")
        values[key] = value
    return cls(**values)


def _coerce(value, default, where, variable_length=False):
    """Check ``value`` against the type of ``default`` (ints are accepted for floats)."""
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        raise InputError(f"{where} must be true or false, got {value!r}")
    if isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise InputError(f"{where} must be an integer, got {value!r}")
    if isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
            return float(value)
        raise InputError(f"{where} must be a finite number, got {value!r}")
    if isinstance(default, str):
        if isinstance(value, str):
            return value
        raise InputError(f"{where} must be a string, got {value!r}")
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or (not variable_length and len(value) != len(default)):
            size = "a list of numbers" if variable_length else f"a list of {len(default)} numbers"
            raise InputError(f"{where} must be {size}, got {value!r}")
        return tuple(_coerce(item, 0.0, where) for item in value)
    raise TypeError(f"unsupported default {default!r}")


def _shapes_from_dict(table: dict, where: str) -> tuple[ShapeSpec, ...]:
    from aquarom_fenics.geometry.shapes import shape_names

    valid = shape_names()
    shapes = []
    for name, spec in table.items():
        if name not in valid:
            raise InputError(f"{where}: unknown shape variation '{name}'; valid names: {', '.join(valid)}")
        if not isinstance(spec, dict):
            raise InputError(f"{where}: [shapes] {name} must be a table like {{ bounds = [-0.5, 0.5], start = 0.0 }}")
        for key in spec:
            if key not in ("bounds", "start", "radius"):
                raise InputError(f"{where}: unknown key [shapes.{name}] {key}; valid keys: bounds, start, radius")
        if "bounds" not in spec:
            raise InputError(f"{where}: [shapes] {name} needs bounds = [lower, upper]")
        lower, upper = _coerce(spec["bounds"], (0.0, 0.0), f"{where}: [shapes] {name} bounds")
        start = _coerce(spec.get("start", 0.0), 0.0, f"{where}: [shapes] {name} start")
        if lower > upper:
            raise InputError(f"{where}: [shapes] {name} bounds = [{lower}, {upper}]: lower bound above upper")
        if not lower <= start <= upper:
            raise InputError(f"{where}: [shapes] {name} start = {start} outside its bounds [{lower}, {upper}]")
        radius = None
        if "radius" in spec:
            radius = _coerce(spec["radius"], 0.0, f"{where}: [shapes] {name} radius")
            if radius <= 0:
                raise InputError(f"{where}: [shapes] {name} radius = {radius} must be > 0")
        shapes.append(ShapeSpec(name, lower, upper, start, radius))
    return tuple(shapes)


def _constraints_from_list(items, shapes, where) -> tuple[LinearConstraint, ...]:
    if not isinstance(items, list):
        raise InputError(f"{where}: constraints must be an array of tables ([[constraints]])")
    names = [shape.name for shape in shapes]
    constraints = []
    for number, item in enumerate(items, start=1):
        here = f"{where}: constraint {number}"
        if not isinstance(item, dict):
            raise InputError(f"{here} must be a table with coefficients, lower and/or upper")
        for key in item:
            if key not in ("coefficients", "lower", "upper"):
                raise InputError(f"{here}: unknown key '{key}'; valid keys: coefficients, lower, upper")
        coefficients = item.get("coefficients")
        if not isinstance(coefficients, dict) or not coefficients:
            raise InputError(f"{here}: coefficients must be a table like {{ z_tail = 1.0 }}")
        for name in coefficients:
            if name not in names:
                raise InputError(f"{here}: '{name}' is not a shape variation of this scene ({', '.join(names)})")
        pairs = tuple((name, _coerce(value, 0.0, f"{here} coefficient {name}")) for name, value in coefficients.items())
        lower = _coerce(item.get("lower", -math.inf), 0.0, f"{here} lower") if "lower" in item else -math.inf
        upper = _coerce(item.get("upper", math.inf), 0.0, f"{here} upper") if "upper" in item else math.inf
        if lower > upper:
            raise InputError(f"{here}: lower {lower} above upper {upper}")
        constraints.append(LinearConstraint(pairs, lower, upper))
    return tuple(constraints)


def parse_xi_assignments(assignments: list[str] | None, scene: Scene) -> dict[str, float]:
    """``["z_tail=0.1", …]`` → ``{"z_tail": 0.1}``; names must be shapes of the scene, each given once.

    A value outside the scene's bounds is accepted (any design can be simulated) with a warning.
    """
    values = {}
    for text in assignments or []:
        name, sep, number = text.partition("=")
        if not sep:
            raise InputError(f"--xi {text}: expected name=value, e.g. --xi y_thin=0.05")
        name = name.strip()
        if name not in scene.shape_names:
            valid = ", ".join(scene.shape_names) or "none: the scene has no [shapes]"
            raise InputError(f"--xi {text}: '{name}' is not a shape variation of scene {scene.name} (valid: {valid})")
        try:
            value = float(number)
        except ValueError:
            raise InputError(f"--xi {text}: '{number}' is not a number") from None
        if not math.isfinite(value):
            raise InputError(f"--xi {text}: '{number.strip()}' is not a finite number")
        if name in values:
            raise InputError(f"--xi {text}: {name} is given twice (first {name}={values[name]:g}); give it once")
        shape = next(s for s in scene.shapes if s.name == name)
        if not shape.lower <= value <= shape.upper:
            logging.getLogger("aquarom").warning("--xi %s is outside the scene's bounds [%g, %g] of %s",
                                                 text, shape.lower, shape.upper, name)
        values[name] = value
    return values
