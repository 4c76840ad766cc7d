"""Cases of the validation (`make validate`): cached FOM, ROM/PROM, mesh and MPI runs.

A case is a scene plus the model settings that are not in the scene (model kind, ξ, ROM or
PROM, sensitivities, energy balance, MPI ranks). Its key is
:func:`aquarom_fenics.reduction.cache.entry_key` of the scene hash, those settings and the record
format (the software versions are part of every entry key); its record is one JSON file
``<kind>-<key>.json`` in the cases folder, written atomically when the case has an answer
(completed, or stopped by the solver with its message). A case that hits the time limit or raises
is reported but not cached, so that a rerun tries it again; a rerun with everything cached only
reads files.

Every record says ``status``: ``completed``, ``stopped`` (a clean solver stop: the message names
the time), ``non-finite`` (completed with NaN/inf numbers: a bug, never expected), ``time-limit``
or ``crashed`` (exception type and message).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.persistence import entry_key

CASE_FORMAT = 2
"""Version of the case records; part of every key (bump it when a record's content changes)."""

CACHED_STATUSES = ("completed", "stopped", "non-finite")
"""Outcomes that are answers of the model and therefore cached; time limits and crashes are not."""


@dataclass
class Case:
    """One run: ``kind`` is ``fom``, ``reduced``, ``mesh`` or ``mpi``; ``options`` holds plain JSON values."""

    kind: str
    label: str
    scene: Scene
    options: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        return entry_key("validation case", CASE_FORMAT, self.kind, self.scene.hash, self.options)

    @property
    def file_name(self) -> str:
        return f"{self.kind}-{self.key}.json"


def fom_case(label: str, scene: Scene, xi=None, energy: bool = True) -> Case:
    """The FOM (serial, in this process); ``energy`` keeps the states and computes the energy balance
    after the run (outside its timing; a few per cent of its cost)."""
    return Case("fom", label, scene, {"xi": _plain_xi(xi), "energy": bool(energy)})


def reduced_case(label: str, scene: Scene, parametric: bool, xi=None, sensitivities: bool = False) -> Case:
    """A ROM (``parametric`` False) or the scene's PROM built at ξ_c = 0, run at ξ."""
    return Case("reduced", label, scene, {"parametric": bool(parametric), "xi": _plain_xi(xi),
                                          "sensitivities": bool(sensitivities)})


def mesh_case(label: str, scene: Scene) -> Case:
    """The nominal fish's FOM run, first frequency and static peak-muscle deflection (mesh convergence)."""
    return Case("mesh", label, scene, {})


def mpi_case(label: str, scene: Scene, ranks: int) -> Case:
    """The FOM through ``mpirun -n ranks aquarom simulate`` in a subprocess."""
    return Case("mpi", label, scene, {"ranks": int(ranks)})


def _plain_xi(xi):
    return None if xi is None else [float(value) for value in xi]


def read_record(path: Path) -> dict | None:
    try:
        record = json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return record if record.get("status") in CACHED_STATUSES else None


def describe(record: dict) -> str:
    """One line: status and the main numbers of a record."""
    status = record.get("status")
    if status not in ("completed", "non-finite"):
        return f"{status}: {record.get('message')}"
    parts = [status]
    if record.get("distance") is not None:
        parts.append(f"d = {100 * record['distance']:.3f} cm")
    if record.get("tail_amplitude") is not None:
        parts.append(f"A = {100 * record['tail_amplitude']:.3f} cm")
    if record["kind"] == "reduced":
        parts.append(f"m = {record.get('size')}, build {record.get('build_time', 0):.2f} s, "
                     f"solve {record.get('solve_time', 0):.2f} s")
    else:
        parts.append(f"{record.get('wall_time', 0):.1f} s")
    if record["kind"] == "mesh":
        parts.append(f"f_1 = {record['first_frequency']:.3f} Hz, static tail y = "
                     f"{100 * record['static_tail_deflection']:.3f} cm")
    energy = record.get("energy") or {}
    if energy.get("available") and energy.get("numerical_dissipation_relative") is not None:
        parts.append(f"numerical dissipation {100 * energy['numerical_dissipation_relative']:+.2f}%, "
                     f"energy imbalance {100 * energy['relative_imbalance']:.1e}%")
    elif energy.get("available"):
        parts.append(f"no energy throughput (work of the forces {energy.get('throughput', 0.0):.3g} J)")
    elif energy:
        parts.append(f"energy balance {energy['message']}")
    return ", ".join(parts)
