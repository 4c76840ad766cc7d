"""The FOM's answer at a design, computed once: one content-addressed cache entry read by every study.

The optimiser's FOM check (:func:`fom_distance`), the design sweep and the Pareto sweep (through the
check) ask :func:`fom_answer`; an entry written by one is read by the others without a FOM run. A
validation FOM case, which needs the whole trajectory and so always runs, offers its answer to the
cache (:func:`offer_answer`) for them.
An entry (JSON, checksummed by :mod:`aquarom_fenics.io.persistence`) holds::

    design, scene_hash, fom_hash     the design (shape values by name) and the scene it was run on
    distance [m], tail_amplitude [m] the swimming distance and the tail's amplitude
    stop_reason                      "completed", or why the solver stopped
    computed_by                      model "fom", cells, dofs, steps, wall_time [s], versions

A stopped run is returned with its reason but not stored: as before this format, a stop is run
again next time (``stop_reason`` is therefore "completed" in every entry this module writes; an
entry with another reason would be read as a stopped answer).

Older entries: the sweep's (distance, tail amplitude, wall time, cells, steps, no stop reason) are
read as completed answers; the optimiser's (the distance only) are read by :func:`fom_distance`,
whose fields suffice, and are a cache miss for a caller that needs the tail amplitude (the sweep),
which recomputes the run and overwrites the entry in this format.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import SolverError
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.paths import cache_root
from aquarom_fenics.io import persistence      # write_json_atomic looked up at each store (a full disk can be simulated)
from aquarom_fenics.io.persistence import entry_key, get_or_compute, require_cache_writable, store
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.geometry.fish_cache import shared_fish

log = logging.getLogger("aquarom")

COMPLETED = "completed"


@dataclass(frozen=True)
class FomAnswer:
    """What the FOM answered at a design: distance and tail amplitude [m] (None for a stopped run,
    and the amplitude None in an old distance-only entry), the stop reason (``"completed"`` or why
    the solver stopped) and what computed it (model, cells, dofs, steps, wall time [s], versions).
    ``cached``: read from the FOM cache rather than computed by this call."""

    distance: float | None
    tail_amplitude: float | None
    stop_reason: str
    computed_by: dict = field(default_factory=dict)
    cached: bool = False

    @property
    def completed(self) -> bool:
        return self.stop_reason == COMPLETED


def fom_cache_path(scene: Scene, design: dict[str, float], amplitude: float | None) -> Path:
    """The FOM cache entry of a design (``Scene.fom_hash``, design and amplitude): scenes that
    differ only in what a FOM run does not read (optimiser, reduction, bounds) share it."""
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    return cache_root() / "fom" / f"{entry_key('fom', scene.fom_hash, sorted(design.items()))}.json"


def entry_of(answer: FomAnswer, scene: Scene, design: dict[str, float]) -> dict:
    """The JSON of a cache entry (the fields the module docstring lists)."""
    return {"design": design, "scene_hash": scene.hash, "fom_hash": scene.fom_hash, "distance": answer.distance,
            "tail_amplitude": answer.tail_amplitude, "stop_reason": answer.stop_reason,
            "computed_by": answer.computed_by}


def read_answer(path: Path, need_tail: bool = False) -> FomAnswer:
    """The answer of an entry, or ValueError when it cannot give what the caller needs: no
    distance, or (``need_tail``) no tail amplitude, as in the optimiser's older entries."""
    entry = json.loads(Path(path).read_text())
    if not isinstance(entry, dict):
        raise ValueError("not a FOM cache entry")
    reason = entry.get("stop_reason", COMPLETED)
    distance, amplitude = entry.get("distance"), entry.get("tail_amplitude")
    if reason == COMPLETED and distance is None:
        raise ValueError("an entry without the distance")
    if reason == COMPLETED and need_tail and amplitude is None:
        raise ValueError("an entry without the tail amplitude (written by an older optimiser's FOM check)")
    computed_by = entry.get("computed_by") or {name: entry[name] for name in ("cells", "steps", "wall_time")
                                               if name in entry}
    return FomAnswer(distance, amplitude, reason, computed_by, cached=True)


def cached_answer(scene: Scene, design: dict[str, float], amplitude: float | None = None,
                  need_tail: bool = False) -> FomAnswer | None:
    """The answer the FOM cache holds for the design, or None (no entry, or one :func:`read_answer`
    refuses); nothing is computed."""
    try:
        return read_answer(fom_cache_path(scene, design, amplitude), need_tail)
    except (OSError, ValueError):
        return None


def answer_of(result) -> FomAnswer:
    """The answer of a finished FOM run (a :class:`~aquarom_fenics.dynamics.simulate.SimulationResult`)."""
    from aquarom_fenics.io.versions import software_versions

    computed_by = {"model": "fom", "cells": result.n_cells, "dofs": result.n_dofs,
                   "steps": len(result.trajectory) - 1, "wall_time": result.wall_time,
                   "versions": software_versions()}
    if not result.completed:
        return FomAnswer(None, None, result.error or "stopped", computed_by)
    return FomAnswer(result.distance, result.tail_amplitude, COMPLETED, computed_by)


def run_fom(scene: Scene, design: dict[str, float], fish: Fish | None, progress: bool) -> FomAnswer:
    """One FOM run at the design (the scene's amplitude), as an answer; the fish of the scene from
    :func:`~aquarom_fenics.geometry.fish_cache.shared_fish` when none is given."""
    require_cache_writable("fom")
    return answer_of(simulate_fom(scene, design, fish=fish or shared_fish(scene), progress=progress))


def offer_answer(scene: Scene, design: dict[str, float], result) -> bool:
    """Store the answer of a serial FOM run made elsewhere (a validation case) when it completed and
    the cache has no entry for the design yet; True when stored. A cache that cannot be written
    is passed over with a log line: the run's own output does not depend on it."""
    path = fom_cache_path(scene, design, None)
    if not result.completed or path.exists():
        return False
    answer = answer_of(result)
    try:
        store(path, lambda target: persistence.write_json_atomic(target, entry_of(answer, scene, design)))
    except OSError as error:
        log.info("FOM cache: the answer at %s not stored (%s)", design, error)
        return False
    return True


def fom_answer(scene: Scene, design: dict[str, float], amplitude: float | None = None, fish: Fish | None = None,
               need_tail: bool = False, progress: bool = False, comm=None) -> FomAnswer:
    """The FOM's answer at a design, from the FOM cache or computed and stored there (completed
    runs only). ``amplitude`` replaces the scene's actuation amplitude; ``need_tail``: an entry
    without the tail amplitude is a miss; ``comm``: the MPI communicator of a collective run."""
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    return get_or_compute(fom_cache_path(scene, design, None), lambda: run_fom(scene, design, fish, progress),
                          save=lambda value, path: persistence.write_json_atomic(path, entry_of(value, scene, design)),
                          load=lambda path: read_answer(path, need_tail), comm=comm, label=f"FOM at {design}",
                          store_if=lambda value: value.completed)


def fom_distance(scene: Scene, fish: Fish, design: dict[str, float], amplitude: float | None) -> float:
    """Swimming distance [m] of the FOM at a design (:func:`fom_answer` on every MPI rank, with a
    progress bar on rank 0); SolverError when the run stopped."""
    answer = fom_answer(scene, design, amplitude, fish=fish, progress=MPI.COMM_WORLD.rank == 0, comm=MPI.COMM_WORLD)
    if not answer.completed:
        raise SolverError(f"FOM at {design} stopped: {answer.stop_reason}")
    return answer.distance
