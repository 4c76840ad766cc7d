"""Stability studies of the validation: MPI runs (study e) and stress tests (SPEC §11)."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.verification.validation.cases import fom_case, mpi_case, reduced_case
from aquarom_fenics.verification.validation.runner import Runner
from aquarom_fenics.verification.validation.settings import PROM_SCENES, REFERENCE_STIFFNESS, Settings, base_scene


def study_e(runner: Runner, settings: Settings) -> dict:
    cases = [(level, ranks, mpi_case(f"mpirun -n {ranks} FOM L{level}",
                                     base_scene(settings, level=level, degree=settings.study_degree), ranks))
             for level in settings.mpi_levels for ranks in (1, 2)]
    records = runner.run("e", [case for _, _, case in cases])
    runs = []
    for (level, ranks, _), record in zip(cases, records):
        runs.append({"level": level, "ranks": ranks} | {key: record.get(key) for key in (
            "status", "message", "cells", "dofs", "wall_time", "process_time", "setup_time", "solve_time",
            "distance", "tail_amplitude", "mean_newton_iterations", "peak_memory_mb_rank0", "stopped_at")})
        runs[-1]["trajectory"] = record.get("trajectory")
    comparisons = []
    for level in settings.mpi_levels:
        serial, parallel = (next(r for r in runs if r["level"] == level and r["ranks"] == n) for n in (1, 2))
        entry = {"level": level, "cells": serial.get("cells") or parallel.get("cells")}
        if serial.get("wall_time") and parallel.get("wall_time"):
            entry["speedup"] = serial["wall_time"] / parallel["wall_time"]
            entry["speedup_solve"] = (serial["solve_time"] / parallel["solve_time"]
                                      if serial.get("solve_time") and parallel.get("solve_time") else None)
        if serial.get("trajectory") and parallel.get("trajectory"):
            length = min(len(serial["trajectory"]["time"]), len(parallel["trajectory"]["time"]))
            a, b = (np.asarray(r["trajectory"]["head_x"][:length]) for r in (serial, parallel))
            entry["head_x_max_difference"] = float(np.max(np.abs(a - b)))
            entry["compared_until"] = float(serial["trajectory"]["time"][length - 1])
        if serial.get("distance") is not None and parallel.get("distance") is not None:
            entry["distance_relative_difference"] = (parallel["distance"] - serial["distance"]) / abs(serial["distance"])
        entry["statuses"] = [serial.get("status"), parallel.get("status")]
        comparisons.append(entry)
    for run in runs:
        run.pop("trajectory", None)
    return {"study": "e", "degree": settings.study_degree, "levels": list(settings.mpi_levels), "runs": runs, "comparisons": comparisons}


def stress_scenes(settings: Settings, level: int | None = None, duration: float | None = None) -> list[tuple]:
    """(id, what is stressed, scene) of the FOM + ROM stress cases, on ``level`` (default the settings')."""
    scene = base_scene(settings, level=level or settings.stress_level)
    if duration is not None:
        scene = scene.replace("solver", duration=duration)
    return [
        ("reference", "reference settings (baseline of the energy balance)", scene),
        ("stiffness-2x", "actuation stiffness 2× (1.2e5 Pa)", scene.replace("actuation", stiffness=2 * REFERENCE_STIFFNESS)),
        ("stiffness-3.5x", "actuation stiffness 3.5× (2.1e5 Pa)", scene.replace("actuation", stiffness=3.5 * REFERENCE_STIFFNESS)),
        ("stiffness-5x", "actuation stiffness 5× (3e5 Pa)", scene.replace("actuation", stiffness=5 * REFERENCE_STIFFNESS)),
        ("h-0.05", "time step h = 0.05 s", scene.replace("solver", time_step=0.05)),
        ("h-0.1", "time step h = 0.1 s", scene.replace("solver", time_step=0.1)),
        ("alpha-0", "Newmark α_N = 0 (no numerical damping)",
         scene.replace("solver", integrator="newmark", newmark_alpha=0.0)),
        ("soft", "very soft material E/5 (52 kPa)", scene.replace("material", young_modulus=scene.material.young_modulus / 5)),
    ]


def study_stress(runner: Runner, settings: Settings) -> dict:
    entries, cases = [], []
    for case_id, description, scene in stress_scenes(settings):
        for model, case in (("FOM", fom_case(f"stress {case_id} FOM", scene, energy=True)),
                            ("ROM", reduced_case(f"stress {case_id} ROM", scene, parametric=False))):
            entries.append((case_id, description, model, case))
            cases.append(case)
    fine = base_scene(settings, PROM_SCENES[8], level=settings.fine_prom_level)
    fine_case = reduced_case(f"stress fine-mesh PROM p=8 L{settings.fine_prom_level}", fine, parametric=True,
                             sensitivities=True)
    entries.append(("fine-mesh-prom", f"PROM p = 8 built on the finest level ({settings.fine_prom_level})",
                    "PROM p=8", fine_case))
    cases.append(fine_case)
    records = dict(zip((case.key for case in cases), runner.run("stress", cases)))
    rows = []
    for case_id, description, model, case in entries:
        record = records[case.key]
        rows.append({"id": case_id, "description": description, "model": model} | stress_row(record))
    return {"study": "stress", "level": settings.stress_level, "duration": settings.duration, "rows": rows,
            "energy_note": "the per-force balance of aquarom_fenics.verification.energy: work of the actuation, "
                           "the Lighthill thrust (added-mass and velocity parts) and the drag; dissipation by the "
                           "Rayleigh damping and by the time scheme (from its step equations); what is left is "
                           "the Newton residual of the steps"}


def stress_row(record: dict) -> dict:
    """Outcome of a stress case: clean (converged, or stopped with a message naming the time) or not."""
    status, message = record.get("status"), record.get("message")
    clean = status == "completed" or (status == "stopped" and message is not None and "t = " in message)
    row = {"status": status, "message": message, "clean": bool(clean), "distance": record.get("distance"),
           "tail_amplitude": record.get("tail_amplitude"), "stopped_at": record.get("stopped_at"),
           "newton": record.get("newton"), "wall_time": record.get("wall_time") or (
               (record.get("build_time") or 0) + (record.get("solve_time") or 0)),
           "cells": record.get("cells"), "size": record.get("size"), "build_time": record.get("build_time"),
           "finite_tensors": record.get("finite_tensors"), "dropped": record.get("dropped"),
           "peak_rss_mb_process": record.get("peak_rss_mb_process")}
    if record.get("energy"):
        row["energy"] = record["energy"]
    return row
