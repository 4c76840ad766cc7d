"""Scene files: one TOML file that fully describes a study (SPEC §1).

Every section is a frozen dataclass whose fields carry the SPEC defaults
(:mod:`aquarom_fenics.io.scene_sections`). Loading checks every key and value and raises
:class:`InputError` with one line naming the file, the key and what would be valid.
``Scene.hash`` identifies the resolved study (values, not formatting); ``Scene.to_toml`` writes
a file that loads back to the same scene and hash.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import is_regular_file, read_text_file, require_regular_file
from aquarom_fenics.parallel.settings import ClusterSettings, cluster_from_table
from aquarom_fenics.io.paths import shipped_meshes, shipped_scenes
from aquarom_fenics.io.scene_sections import (SECTIONS, ActuationSection, CooptimizationSection, FluidSection,
                                              LinearConstraint, MaterialSection, MeshSection, MuscleSpec,
                                              OptimizerSection, OutputSection, ReductionSection, RegionsSection,
                                              ShapeSpec, SolverSection, at_legacy, legacy_values)
from aquarom_fenics.io.scene_gait import GaitVariable, check_gait_bounds, gait_from_table, resolve_gait
from aquarom_fenics.io.scene_muscles import (check_actuation, default_muscles, muscles_from_list, scene_vibration_modes,
                                             start_ramp_time, stroke_amplitude, warn_abrupt_start)

SCENES_DIR = shipped_scenes()

FOM_SECTIONS = ("mesh", "material", "regions", "actuation", "fluid", "solver")
"""The sections a FOM run reads (with the shape names): ``Scene.fom_hash`` keys the FOM cache."""
PROM_SECTIONS = (*FOM_SECTIONS, "reduction")
"""The sections a PROM build reads (with the muscles, the gait and the shapes but their starts):
``Scene.prom_hash`` keys the PROM cache."""


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
    muscles: tuple[MuscleSpec, ...] = ()
    """The ``[[muscles]]`` tables; empty: the antagonist pair of ``[regions] muscles`` (:attr:`actuated_muscles`)."""
    shapes: tuple[ShapeSpec, ...] = ()
    constraints: tuple[LinearConstraint, ...] = ()
    gait: tuple[GaitVariable, ...] = ()
    """The ``[gait]`` table's design variables (io/scene_gait.py), their starts resolved."""
    solver: SolverSection = SolverSection()
    reduction: ReductionSection = ReductionSection()
    optimizer: OptimizerSection = OptimizerSection()
    cooptimization: CooptimizationSection = CooptimizationSection()
    output: OutputSection = OutputSection()
    cluster: ClusterSettings = ClusterSettings()
    """Where many-run commands (``aquarom sweep``) send their work; not part of the study (the
    hashes and ``to_dict`` leave it out)."""

    def __post_init__(self):
        check_actuation(self)       # across sections: muscles against the head, the time step and E

    @classmethod
    def load(cls, path: str | Path) -> "Scene":
        """Read and validate a scene file; a bare name like ``so1`` means ``scenes/so1.toml``."""
        path = resolve_scene_path(path)
        text = read_text_file(path, "scene", MAX_SCENE_BYTES, nesting="toml")
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise InputError(f"scene {path}: malformed TOML ({error})") from None
        except RecursionError:
            raise InputError(f"scene {path}: nested too deeply to read; a scene needs at most 3 levels") from None
        return scene_from_dict(data, source=str(path), base_dir=str(path.parent))

    @property
    def actuated_muscles(self) -> tuple[MuscleSpec, ...]:
        """The muscles the models drive: the ``[[muscles]]`` tables, or the default antagonist pair."""
        return self.muscles or default_muscles(self.regions)

    @property
    def shape_names(self) -> list[str]:
        return [shape.name for shape in self.shapes]

    @property
    def gait_names(self) -> list[str]:
        return [variable.name for variable in self.gait]

    def validity_radii(self) -> list[float]:
        """PROM validity radius per shape parameter (SPEC §8)."""
        fraction = self.reduction.validity_fraction
        return [s.radius if s.radius is not None else fraction * max(abs(s.lower), abs(s.upper)) for s in self.shapes]

    @property
    def mesh_file(self) -> Path | None:
        if not self.mesh.file:
            return None
        path = Path(self.base_dir) / self.mesh.file
        try:
            return path.resolve()
        except (RuntimeError, OSError):        # a symbolic-link loop: kept as given, refused when read
            return path.absolute()

    @property
    def n_steps(self) -> int:
        """Number of Newmark steps, round(T / h)."""
        return int(round(self.solver.duration / self.solver.time_step))

    def to_dict(self) -> dict[str, Any]:
        """The resolved scene (defaults filled), without where it was read from."""
        data = dataclasses.asdict(self)
        data.pop("source")
        data.pop("base_dir")
        data.pop("cluster")
        if not self.muscles:
            data.pop("muscles")       # the scenes without [[muscles]] keep their hash
        if not self.gait:
            data.pop("gait")          # and those without [gait]
        if self.mesh_file is not None:
            data["mesh"]["file"] = str(self.mesh_file)
        return data

    @property
    def hash(self) -> str:
        """SHA-256 (16 hex digits) of the resolved scene and of the mesh file's content, or of the
        block's meshing recipe ``meshes/block.toml`` (a key added later is left out at the value
        scenes computed with before it: :func:`legacy_values`)."""
        return self._digest_text(self._hashed_text())

    def _hashed_text(self) -> str:
        """The JSON text of :meth:`_hashed_dict`, made once per scene (a frozen value: a builder asks for
        the hash a few times per PROM build, and ``asdict`` is most of its cost)."""
        text = self.__dict__.get("_hashed_text_memo")
        if text is None:
            text = json.dumps(self._hashed_dict(), sort_keys=True, default=str)
            object.__setattr__(self, "_hashed_text_memo", text)
        return text

    @property
    def fom_hash(self) -> str:
        """The hash of what a FOM run at a given design reads: mesh (and file), material, regions,
        actuation, fluid, solver and the shape names; not the bounds, reduction, optimiser or output."""
        return self._digest(self._selected(FOM_SECTIONS) | {"shapes": [shape.name for shape in self.shapes]})

    @property
    def prom_hash(self) -> str:
        """The hash of what a PROM build reads: the FOM's sections, [reduction] (its "auto" values resolved:
        the stroke amplitude holds what it reads of [cooptimization]), the muscles, the gait and the shapes'
        names, bounds and radii; not the name, description, shape starts, constraints, [optimizer],
        [cooptimization], [output] or [reduction] atlas_scale, atlas_change and atlas_check (where the atlas cuts its cells, not what a PROM
        is), so that scenes differing only there share their PROMs."""
        shapes = [{key: value for key, value in dataclasses.asdict(shape).items() if key != "start"}
                  for shape in self.shapes]
        selected = self._selected(PROM_SECTIONS, "gait")
        selected["reduction"].pop("atlas_scale", None)
        selected["reduction"].pop("atlas_change", None)
        selected["reduction"].pop("atlas_check", None)
        return self._digest(selected | {"shapes": shapes})

    def _selected(self, sections: tuple[str, ...], *optional: str) -> dict[str, Any]:
        """The hashed values of ``sections``, and of the muscles and ``optional`` parts when the scene has them
        (read back from the scene's hashed text, made once)."""
        data = json.loads(self._hashed_text())
        return {key: data[key] for key in (*sections, "muscles", *optional) if key in data}

    def _hashed_dict(self) -> dict[str, Any]:
        data = self.to_dict()
        if self.mesh_file is not None:   # the file by its name: its content is hashed (:meth:`_digest`), and
            data["mesh"]["file"] = self.mesh_file.name   # one scene in two checkouts keeps one hash and cache
        data["actuation"]["start_ramp"] = start_ramp_time(self)   # "auto" by the τ it gives: the pair's 0.0
        modes = scene_vibration_modes(self)      # "auto" by the count it gives where the scene decides it: the pair's 1
        data["reduction"]["vibration_modes"] = data["reduction"]["vibration_modes"] if modes is None else modes
        data["reduction"]["stroke_amplitude"] = stroke_amplitude(self)      # "auto" by its A_s: the block's 0 (legacy)
        for section, cls in SECTIONS.items():
            for key, legacy in legacy_values(cls).items():
                if at_legacy(data[section][key], legacy):
                    del data[section][key]
        return data

    def _digest(self, data: dict) -> str:
        return self._digest_text(json.dumps(data, sort_keys=True, default=str))

    def _digest_text(self, text: str) -> str:
        """SHA-256 (16 hex digits) of ``text`` with the registered shape fields and the mesh's content."""
        from aquarom_fenics.geometry.shape_registry import registered_fingerprint

        digest = hashlib.sha256(text.encode())
        digest.update(registered_fingerprint(self.shape_names, self).encode())  # a registered field on this mesh
        if self.mesh_file is None:
            digest.update((shipped_meshes() / "block.toml").read_bytes())  # the block's meshing recipe
        elif self.mesh_file.exists() or self.mesh_file.is_symlink():
            from aquarom_fenics.io.readback import MAX_MESH_FILE_BYTES

            require_regular_file(self.mesh_file, "mesh file", MAX_MESH_FILE_BYTES)   # no FIFO, device or link loop
            digest.update(self.mesh_file.read_bytes())
        return digest.hexdigest()[:16]

    def to_toml(self) -> str:
        """The TOML text of the resolved scene (every section, defaults written out): the inverse of
        :meth:`load`, read back with the same hash (an external mesh is written as its absolute path)."""
        data = self.to_dict()
        lines = [f"name = {_toml_value(self.name)}", f"description = {_toml_value(self.description)}"]
        for section in SECTIONS:
            lines.append(f"\n[{section}]")
            lines += [f"{key} = {_toml_value(value)}" for key, value in data[section].items()]
        if self.shapes:
            lines.append("\n[shapes]")
        for shape in self.shapes:
            radius = "" if shape.radius is None else f", radius = {_toml_value(shape.radius)}"
            lines.append(f"{shape.name} = {{ bounds = [{_toml_value(shape.lower)}, {_toml_value(shape.upper)}], "
                         f"start = {_toml_value(shape.start)}{radius} }}")
        if self.gait:
            lines.append("\n[gait]")
        for variable in self.gait:
            lines.append(f"{variable.name} = {{ bounds = [{_toml_value(variable.lower)}, {_toml_value(variable.upper)}], "
                         f"start = {_toml_value(variable.start)} }}")
        for muscle in self.muscles:
            lines += ["\n[[muscles]]"] + [f"{key} = {_toml_value(value)}" for key, value in
                                           dataclasses.asdict(muscle).items() if value is not None]
        for constraint in self.constraints:
            lines.append("\n[[constraints]]")
            lines.append("coefficients = { " + ", ".join(f"{name} = {_toml_value(value)}"
                                                          for name, value in constraint.coefficients) + " }")
            lines += [f"{bound} = {_toml_value(getattr(constraint, bound))}" for bound in ("lower", "upper")
                      if math.isfinite(getattr(constraint, bound))]
        if self.cluster != ClusterSettings():
            lines.append("\n[cluster]")
            lines += [f"{key} = {_toml_value(value)}" for key, value in dataclasses.asdict(self.cluster).items()
                      if value != getattr(ClusterSettings(), key)]
        return "\n".join(lines) + "\n"

    def replace(self, section: str, **values) -> "Scene":
        """A copy with some values of one section changed (validated like a file)."""
        current = getattr(self, section)
        merged = dataclasses.asdict(current) | values
        return dataclasses.replace(self, **{section: _section_from_dict(SECTIONS[section], merged, f"scene {self.source}", section)})


def _toml_value(value) -> str:
    """A TOML literal of a scene value (booleans, numbers, strings and lists of them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)    # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    raise TypeError(f"no TOML literal for {value!r}")


MAX_SCENE_BYTES = 4 * 1024 ** 2
"""Largest scene file read [bytes] (a scene is a few kB)."""


def resolve_scene_path(path: str | Path) -> Path:
    """The scene file of a path or a shipped scene's name (a folder of that name does not hide
    the shipped scene: a folder is no scene file)."""
    candidate = Path(path)
    shipped_file = SCENES_DIR / f"{candidate}.toml"
    if candidate.suffix == "" and len(candidate.parts) == 1 and is_regular_file(shipped_file) \
            and not is_regular_file(candidate):
        return shipped_file
    if not is_regular_file(candidate):
        shipped = ", ".join(sorted(p.stem for p in SCENES_DIR.glob("*.toml")))
        require_regular_file(candidate, "scene", MAX_SCENE_BYTES, f"give a path to a .toml file or one of: {shipped}")
    return candidate


def scene_from_dict(data: dict[str, Any], source: str = "<dict>", base_dir: str = ".") -> Scene:
    where = f"scene {source}"
    known = {"name", "description", "shapes", "constraints", "muscles", "gait", "cluster", *SECTIONS}
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
    muscles = muscles_from_list(data["muscles"], sections["regions"], where) if "muscles" in data else ()
    cluster = cluster_from_table(data.get("cluster", {}), where, base_dir)
    gait = resolve_gait(gait_from_table(_table(data, "gait", where), where),
                        muscles or default_muscles(sections["regions"]), sections["actuation"], sections["regions"],
                        sections["cooptimization"], sections["solver"].time_step, where)
    scene = Scene(name=name, description=description, source=source, base_dir=base_dir, muscles=muscles,
                  shapes=shapes, constraints=constraints, gait=gait, cluster=cluster, **sections)
    check_gait_bounds(scene)
    warn_abrupt_start(scene)
    return scene


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
        coerce = spec.metadata.get("coerce")
        value = (coerce(value, f"{where}: [{section}] {key}") if coerce else
                 _coerce(value, spec.default, f"{where}: [{section}] {key}", spec.metadata["variable_length"]))
        check = spec.metadata.get("check")
        problem = check(value) if check else None
        if problem:
            raise InputError(f"{where}: [{section}] {key} = {value!r} {problem}")
        values[key] = value
    settings = cls(**values)
    if section == "optimizer" and settings.key_conflict():     # keys that do not go together
        raise InputError(f"{where}: {settings.key_conflict()}")
    return settings


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
