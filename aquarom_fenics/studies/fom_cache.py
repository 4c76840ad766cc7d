"""The FOM's answer at a design, computed once: the swimming distance [m] in a content-addressed cache entry."""
from __future__ import annotations

import json
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import SolverError
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.paths import cache_root
from aquarom_fenics.io.persistence import entry_key, get_or_compute, require_cache_writable, write_json_atomic
from aquarom_fenics.io.scene import Scene


def fom_cache_path(scene: Scene, design: dict[str, float], amplitude: float | None) -> Path:
    """The FOM cache entry of a design's distance (``Scene.fom_hash``, design and amplitude): scenes
    that differ only in what a FOM run does not read (optimiser, reduction, bounds) share it."""
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    return cache_root() / "fom" / f"{entry_key('fom', scene.fom_hash, sorted(design.items()))}.json"


def fom_distance(scene: Scene, fish: Fish, design: dict[str, float], amplitude: float | None) -> float:
    """Swimming distance of the FOM at a design, cached by ``Scene.fom_hash``, design and amplitude."""
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    path = fom_cache_path(scene, design, None)

    def simulate() -> float:
        require_cache_writable("fom")
        result = simulate_fom(scene, design, fish=fish, progress=MPI.COMM_WORLD.rank == 0)
        if not result.completed:
            raise SolverError(f"FOM at {design} stopped: {result.error}")
        return result.distance

    def save(distance: float, path: Path) -> None:
        write_json_atomic(path, {"design": design, "scene_hash": scene.hash, "fom_hash": scene.fom_hash,
                                 "distance": distance})

    return get_or_compute(path, simulate, save, load=lambda path: json.loads(path.read_text())["distance"],
                          comm=MPI.COMM_WORLD, label=f"FOM at {design}")
