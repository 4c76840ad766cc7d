"""`make validate`: validation studies of the FOM, ROM and PROM, stress tests and results/REPORT.md.

Studies (SPEC §11 "Validation studies", the validation issue):
  a       FOM vs ROM (default and the source's basis) vs PROM(3, 5, 8 parameters) on the mesh levels
          × actuation stiffnesses: errors of distance and tail amplitude, build and solve times;
          heat maps of the distance error over (cells, tail amplitude).
  b       cost against size: build (basis / tensors / rest) and solve time against cells, fitted
          power-law exponents (over every case of a; solve times are the minimum of 3 repeats).
  c       run time against error on the reference case: basis variants, time steps, Taylor order;
          one Pareto plot.
  d       time-step convergence: successive-difference ratios of head x, tail y (FOM, ROM) and of
          the PROM sensitivities at h = 0.02 … 0.0025, for the default scheme and Newmark;
          also written as <out>/time_convergence.json.
  e       MPI: the FOM with mpirun -n 1 and -n 2 on the 16k and 25k levels: speed-up, agreement.
  stress  numerical stability: 2×–5× actuation stiffness, h up to 0.1 s, Newmark α_N = 0, E/5, the PROM
          on the finest mesh; Newton iterations and the energy balance per case.
  mesh_convergence
          the nominal FOM for degree 1 on levels 1–5 and degree 2 on levels 1–3: distance, tail
          amplitude, first frequency, static peak-muscle tail deflection, wall time; Richardson
          reference per quantity (observed order, error estimate) and the cheapest (degree, level)
          within 3% of the reference distance (`aquarom_fenics.verification.convergence`).

Every case is cached in <out>/cases/<kind>-<key>.json (key: scene hash + model settings +
toolkit version), so a rerun computes only what is missing; each study writes <out>/<study>.json,
figures go to <out>/, and the report to results/REPORT.md (--report-only rewrites figures and
report from what is cached).

    .venv/bin/python scripts/validate.py --jobs 2        # everything, missing cases in 2 workers
    .venv/bin/python scripts/validate.py --quick         # levels 1–2, 0.4 s horizon (≈ 1–2 min)
    .venv/bin/python scripts/validate.py --only a,b      # selected studies
    .venv/bin/python scripts/validate.py --report-only   # figures and REPORT.md from the cache
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

SCRIPTS = Path(__file__).resolve().parent
REPOSITORY = SCRIPTS.parent
for path in (REPOSITORY, SCRIPTS):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

import validate_report as report  # noqa: E402
from validate_cases import (CasesCollected, Runner, compute_in_parallel, fom_case, machine,  # noqa: E402
                            mesh_case, mpi_case, power_law_fit, reduced_case)

STUDIES = ("a", "b", "c", "d", "e", "stress", "mesh_convergence")

REFERENCE_STIFFNESS = 6e4
"""k [Pa] of the reference fish (SPEC §5)."""

PROM_SCENES = {3: "so1", 5: "so2", 8: "so3"}
"""Number of shape parameters → shipped scene whose shape set the PROM carries."""


@dataclass(frozen=True)
class Settings:
    quick: bool
    levels: tuple[int, ...]
    stiffnesses: tuple[float, ...]          # Pa; calibrated on level 1 (amplitude ∝ k): 0.5–3.3 cm on level 3
    duration: float                          # s
    reference_level: int
    time_steps: tuple[float, ...]            # study c
    convergence_steps: tuple[float, ...]     # study d
    mpi_levels: tuple[int, ...]
    stress_level: int
    fine_prom_level: int
    time_limit: float                        # s per case
    mesh_series: tuple[tuple[int, tuple[int, ...]], ...]   # (degree, levels) of the mesh-convergence study


FULL = Settings(quick=False, levels=(1, 2, 3, 4, 5), stiffnesses=(1.2e4, 2.5e4, 4e4, 6e4, 7.5e4), duration=2.0,
                reference_level=3, time_steps=(0.04, 0.02, 0.01, 0.005), convergence_steps=(0.02, 0.01, 0.005, 0.0025),
                mpi_levels=(4, 5), stress_level=3, fine_prom_level=5, time_limit=1800.0,
                mesh_series=((1, (1, 2, 3, 4, 5)), (2, (1, 2, 3))))
QUICK = Settings(quick=True, levels=(1, 2), stiffnesses=(1.2e4, 6e4, 7.5e4), duration=0.4, reference_level=1,
                 time_steps=(0.04, 0.02, 0.01, 0.005), convergence_steps=(0.02, 0.01, 0.005, 0.0025),
                 mpi_levels=(1, 2), stress_level=1, fine_prom_level=2, time_limit=300.0,
                 mesh_series=((1, (1, 2, 3)), (2, (1,))))


# ---------------------------------------------------------------------------------------------
# Scenes


def base_scene(settings: Settings, name: str = "nominal", level: int | None = None,
               stiffness: float = REFERENCE_STIFFNESS, time_step: float = 0.02, solver: dict | None = None):
    """A shipped scene at the study's level (linear tetrahedra: the studies sweep the five levels of
    SPEC §11), stiffness, horizon and step; ``solver`` overrides [solver] values."""
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load(name)
    scene = scene.replace("mesh", level=level or settings.reference_level, degree=1)
    scene = scene.replace("actuation", stiffness=float(stiffness))
    scene = scene.replace("solver", duration=settings.duration, time_step=float(time_step), **(solver or {}))
    return scene.replace("output", plots=False, render=False, xdmf=False)


def kpa(stiffness: float) -> str:
    return f"{stiffness / 1e3:g} kPa"


# ---------------------------------------------------------------------------------------------
# a: accuracy over mesh levels × stiffnesses


def accuracy_models(settings: Settings, level: int, stiffness: float) -> list[tuple[str, str, object]]:
    """(model id, label, case) of the reduced models of study a at one (level, k)."""
    nominal = base_scene(settings, level=level, stiffness=stiffness)
    models = [("rom", "ROM", reduced_case(f"ROM L{level} k={kpa(stiffness)}", nominal, parametric=False)),
              ("rom-paper", "ROM, source's basis",
               reduced_case(f"ROM (source's basis) L{level} k={kpa(stiffness)}",
                            nominal.replace("reduction", basis="paper"), parametric=False))]
    for p, name in PROM_SCENES.items():
        scene = base_scene(settings, name, level=level, stiffness=stiffness)
        models.append((f"prom{p}", f"PROM, p = {p}",
                       reduced_case(f"PROM p={p} L{level} k={kpa(stiffness)}", scene, parametric=True,
                                    sensitivities=True)))
    return models


def study_a(runner: Runner, settings: Settings, stiffnesses=None, study="a") -> dict:
    stiffnesses = settings.stiffnesses if stiffnesses is None else stiffnesses
    grid, cases = [], []
    for level in settings.levels:
        for stiffness in stiffnesses:
            fom = fom_case(f"FOM L{level} k={kpa(stiffness)}", base_scene(settings, level=level, stiffness=stiffness))
            models = accuracy_models(settings, level, stiffness)
            grid.append((level, stiffness, fom, models))
            cases += [fom] + [case for _, _, case in models]
    records = dict(zip((case.key for case in cases), runner.run(study, cases)))
    rows = []
    model_labels = {}
    for level, stiffness, fom, models in grid:
        reference = records[fom.key]
        row = {"level": level, "stiffness": stiffness, "cells": reference.get("cells"),
               "fom": summary_of(reference), "models": {}}
        for model_id, label, case in models:
            model_labels[model_id] = label
            row["cells"] = row["cells"] or records[case.key].get("cells")
            row["models"][model_id] = summary_of(records[case.key]) | errors_against(reference, records[case.key])
        rows.append(row)
    cells = {}
    for row in rows:
        if row["cells"]:
            cells[str(row["level"])] = row["cells"]
    return {"study": study, "levels": list(settings.levels), "stiffnesses": list(stiffnesses), "cells": cells,
            "reference_level": settings.reference_level, "reference_stiffness": REFERENCE_STIFFNESS,
            "duration": settings.duration, "models": model_labels, "rows": rows}


SUMMARY_KEYS = ("status", "message", "distance", "tail_amplitude", "wall_time", "setup_time", "solve_time",
                "solve_time_sensitivities", "build_time", "build_basis", "build_tensors", "build_rest", "size",
                "parameters", "labels", "dropped", "cells", "dofs", "stopped_at", "newton", "compute_time",
                "computed_at")


ENERGY_KEYS = ("work_actuation", "work_thrust", "work_drag", "throughput", "dissipated", "dissipated_midpoint",
               "kinetic", "elastic", "imbalance_relative", "imbalance_midpoint_relative")


def summary_of(record: dict) -> dict:
    summary = {key: record.get(key) for key in SUMMARY_KEYS if key in record}
    if record.get("energy"):
        summary["energy"] = {key: record["energy"].get(key) for key in ENERGY_KEYS}
    return summary


def errors_against(reference: dict, record: dict) -> dict:
    """Errors of a model's distance and tail amplitude against the FOM (None when either stopped)."""
    errors = {}
    for name in ("distance", "tail_amplitude"):
        ok = reference.get("status") == "completed" and record.get("status") == "completed"
        value, ref = record.get(name), reference.get(name)
        errors[f"{name}_error_absolute"] = value - ref if ok else None
        errors[f"{name}_error_relative"] = (value - ref) / abs(ref) if ok and ref else None
    return errors


# ---------------------------------------------------------------------------------------------
# b: cost against size


def study_b(runner: Runner, settings: Settings) -> dict:
    """Cost fits over every case of study a (all stiffnesses: several timings per level)."""
    accuracy = study_a(runner, settings, study="b")
    rows = accuracy["rows"]
    series, fits = {}, []

    def add(model, quantity, row_value):
        points = [(row["cells"], row_value(row)) for row in rows]
        points = [(cells, value) for cells, value in points if cells and value]
        series.setdefault(model, {})[quantity] = points
        fit = power_law_fit(*zip(*points)) if len(points) >= 2 else None
        fits.append({"model": model, "quantity": quantity, **(fit or {"exponent": None})})

    add("FOM", "build", lambda row: row["fom"].get("setup_time"))
    add("FOM", "solve", lambda row: row["fom"].get("solve_time") if row["fom"].get("status") == "completed" else None)
    for model_id in accuracy["models"]:
        def value(key, model_id=model_id):
            return lambda row: row["models"][model_id].get(key)
        for quantity, key in (("build", "build_time"), ("build: basis", "build_basis"),
                              ("build: tensors", "build_tensors"), ("build: rest", "build_rest"),
                              ("solve", "solve_time"), ("solve with sensitivities", "solve_time_sensitivities")):
            if any(row["models"][model_id].get(key) for row in rows):
                add(model_id, quantity, value(key))
    return {"study": "b", "stiffnesses": accuracy["stiffnesses"], "models": {"FOM": "FOM"} | accuracy["models"],
            "series": series, "fits": fits}


# ---------------------------------------------------------------------------------------------
# c: run time against error


BASIS_VARIANTS = (
    ("basis-1mode-no-md", "1 mode, no modal derivative", dict(basis="paper", vibration_modes=1, modal_derivatives=False),
     "1 mode, no θ"),
    ("basis-source", "source's basis (1 mode + θ)", dict(basis="paper", vibration_modes=1, modal_derivatives=True),
     "source's basis"),
    ("basis-2modes-md", "2 modes + θ (source's basis with 2 modes)",
     dict(basis="paper", vibration_modes=2, modal_derivatives=True), "2 modes + θ"),
    ("basis-default", "default (1 mode + θ + ψ, θ_ψ)", dict(basis="default", vibration_modes=1, modal_derivatives=True),
     "default ROM"),
)
"""(id, label, [reduction] values, short label) of the basis variants of study c (ROM, h = 0.02 s)."""


def taylor_design(settings: Settings):
    """SO1 design at the validity radius of every parameter: the Taylor-order points of study c."""
    scene = base_scene(settings, "so1")
    return scene, scene.validity_radii()


def study_c(runner: Runner, settings: Settings) -> dict:
    finest = min(settings.time_steps)
    nominal = base_scene(settings)
    points, cases = [], []

    def point(point_id, label, family, case, reference, default=False, time_step=0.02, short=None):
        points.append({"id": point_id, "label": label, "family": family, "case": case, "reference": reference,
                       "default": default, "time_step": time_step, "short": short or label})
        cases.append(case)

    reference = fom_case(f"FOM reference h={finest}", base_scene(settings, time_step=finest))
    cases.append(reference)
    for h in settings.time_steps:
        if h != finest:
            point(f"fom-h{h}", f"FOM, h = {h} s", "FOM", fom_case(f"FOM h={h}", base_scene(settings, time_step=h)),
                  reference, time_step=h, short=f"FOM h={h:g}")
    for point_id, label, values, short in BASIS_VARIANTS:
        scene = nominal.replace("reduction", **values)
        point(point_id, f"ROM {label}", "basis", reduced_case(f"ROM {label}", scene, parametric=False), reference,
              default=point_id == "basis-default", short=short)
    for h in settings.time_steps:
        if h != 0.02:
            point(f"rom-h{h}", f"ROM, h = {h} s", "time step",
                  reduced_case(f"ROM h={h}", base_scene(settings, time_step=h), parametric=False), reference,
                  time_step=h, short=f"ROM h={h:g}")
    so1, radii = taylor_design(settings)
    taylor_reference = fom_case(f"FOM SO1 at ξ = radius, h={finest}", so1.replace("solver", time_step=finest), xi=radii)
    cases.append(taylor_reference)
    for order in (1, 2):
        scene = so1.replace("reduction", taylor_order=order)
        point(f"taylor{order}", f"PROM p = 3, Taylor order {order}, at ξ = radius", "Taylor order",
              reduced_case(f"PROM SO1 order {order} at ξ = radius", scene, parametric=True, xi=radii),
              taylor_reference, short=f"PROM order {order} (ξ = radius)")
    records = dict(zip((case.key for case in cases), runner.run("c", cases)))
    rows = []
    for entry in points:
        record, ref = records[entry["case"].key], records[entry["reference"].key]
        wall = record.get("wall_time") if record["kind"] == "fom" else (
            (record.get("build_time") or 0) + (record.get("solve_time") or 0) if record.get("build_time") else None)
        errors = errors_against(ref, record)
        rows.append({key: entry[key] for key in ("id", "label", "short", "family", "default", "time_step")}
                    | {"status": record.get("status"), "message": record.get("message"), "wall_time": wall,
                       "build_time": record.get("build_time"), "solve_time": record.get("solve_time"),
                       "size": record.get("size"), "labels": record.get("labels"),
                       "distance": record.get("distance"), "reference_distance": ref.get("distance"),
                       "reference": ref.get("label")} | errors)
    return {"study": "c", "level": settings.reference_level, "stiffness": REFERENCE_STIFFNESS,
            "reference_time_step": finest, "taylor_design": dict(zip(so1.shape_names, radii)),
            "reference": summary_of(records[reference.key]),
            "taylor_reference": summary_of(records[taylor_reference.key]), "points": rows}


# ---------------------------------------------------------------------------------------------
# d: time-step convergence


@dataclass(frozen=True)
class ConvergenceScheme:
    """A time scheme of study d: its label, [solver] values and whether it is second order."""

    tag: str
    solver: tuple          # ([solver] key, value) pairs
    second_order: bool

    def facts(self) -> dict:
        """integrator and ρ∞ or α_N, as written with each quantity."""
        from aquarom_fenics.io.scene import SolverSection

        values = {**vars(SolverSection()), **dict(self.solver)}
        key = "rho_infinity" if values["integrator"] == "generalized-alpha" else "newmark_alpha"
        return {"integrator": values["integrator"], key: values[key], "second_order": self.second_order}


def convergence_schemes() -> tuple[ConvergenceScheme, ...]:
    """The default scheme (generalized-α, second order for any ρ∞) and Newmark at its default α_N.

    With γ = ½ + α_N Newmark's error has an O(α_N h) term, so for α_N > 0 the ratios tend to 2
    as h → 0; how soon depends on α_N against h."""
    from aquarom_fenics.io.scene import SolverSection

    defaults = SolverSection()
    return (ConvergenceScheme(f"generalized-α ρ∞ = {defaults.rho_infinity:g}", (), True),
            ConvergenceScheme(f"Newmark α_N = {defaults.newmark_alpha:g}", (("integrator", "newmark"),),
                              defaults.newmark_alpha == 0.0))


def study_d(runner: Runner, settings: Settings) -> dict:
    steps = settings.convergence_steps
    families = {}
    for scheme in convergence_schemes():
        def scene(name="nominal", h=0.02, scheme=scheme):
            return base_scene(settings, name, time_step=h, solver=dict(scheme.solver))
        tag = scheme.tag
        families[(scheme, "FOM", f"FOM, {tag}")] = [fom_case(f"FOM h={h} {tag}", scene(h=h)) for h in steps]
        families[(scheme, "ROM", f"ROM, {tag}")] = [reduced_case(f"ROM h={h} {tag}", scene(h=h), parametric=False)
                                                   for h in steps]
        families[(scheme, "PROM", f"PROM p=3 sensitivities, {tag}")] = [
            reduced_case(f"PROM SO1 h={h} {tag} with sensitivities", scene("so1", h), parametric=True,
                         sensitivities=True) for h in steps]
    cases = [case for family in families.values() for case in family]
    records = dict(zip((case.key for case in cases), runner.run("d", cases)))
    coarse = steps[0]
    result = {"study": "d", "level": settings.reference_level, "duration": settings.duration,
              "time_steps": list(steps), "grid_step": coarse,
              "schemes": [{"tag": scheme.tag} | scheme.facts() for scheme in convergence_schemes()], "quantities": []}
    for (scheme, model, name), family in families.items():
        runs = [records[case.key] for case in family]
        facts = {"model": model} | scheme.facts()
        if any(run.get("status") != "completed" for run in runs):
            result["quantities"].append({"name": name, **facts, "status": "incomplete",
                                         "message": "; ".join(f"h={h}: {run.get('status')} {run.get('message') or ''}"
                                                              for h, run in zip(steps, runs))})
            continue
        if model == "PROM":
            parameter_names = runs[0].get("parameter_names") or []
            series = [on_grid(run["trajectory"]["time"], np.asarray(run["head_x_sensitivity"]), coarse) for run in runs]
            for index, parameter in enumerate(parameter_names):
                result["quantities"].append(convergence(f"d head x / d ξ[{parameter}] (PROM p=3), {scheme.tag}",
                                                        [s[1][:, index] for s in series], series[0][0], steps,
                                                        facts | {"quantity": f"d head_x / d {parameter}"}))
            gradients = [np.asarray(run["distance_gradient"]) for run in runs]
            result["quantities"].append(convergence(f"d distance / d ξ (PROM p=3, norm over parameters), {scheme.tag}",
                                                    gradients, None, steps, facts | {"quantity": "d distance / d xi"}))
        else:
            for quantity, label in (("head_x", "head x"), ("tail_y", "tail y")):
                series = [on_grid(run["trajectory"]["time"], np.asarray(run["trajectory"][quantity]), coarse)
                          for run in runs]
                result["quantities"].append(convergence(f"{model} {label}, {scheme.tag}", [s[1] for s in series],
                                                        series[0][0], steps, facts | {"quantity": quantity}))
    return result


def time_convergence_summary(study: dict) -> dict:
    """The ratios of study d per scheme, model and quantity (results/validation/time_convergence.json)."""
    summary = {"level": study["level"], "duration": study["duration"], "time_steps": study["time_steps"],
               "ratio_range_second_order": [3.5, 4.5], "schemes": []}
    for scheme in study["schemes"]:
        entries = [q for q in study["quantities"] if q["integrator"] == scheme["integrator"]
                   and q.get("rho_infinity") == scheme.get("rho_infinity")
                   and q.get("newmark_alpha") == scheme.get("newmark_alpha")]
        models = {}
        for entry in entries:
            models.setdefault(entry["model"], {})[entry.get("quantity", entry["name"])] = (
                {"ratios": entry["ratios"], "differences": entry["differences"]} if entry["status"] == "completed"
                else {"status": entry["status"], "message": entry.get("message")})
        summary["schemes"].append(scheme | {"models": models})
    return summary


def on_grid(time, values, step):
    """Samples of ``values`` at the multiples of ``step`` (the coarsest run's samples)."""
    time = np.asarray(time)
    stride = int(round(step / (time[1] - time[0])))
    return time[::stride], np.asarray(values)[::stride]


def convergence(name, values, time, steps, facts: dict) -> dict:
    """Successive differences ‖q_h - q_h/2‖_∞ and their ratio (≈ 4 for a second-order scheme)."""
    differences = [float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(values, values[1:])]
    ratios = [first / second if second > 0 else None for first, second in zip(differences, differences[1:])]
    entry = {"name": name, **facts, "status": "completed", "differences": differences,
             "ratios": ratios,
             "ratio": ratios[0] if ratios else None, "pairs": [f"{a:g}–{b:g}" for a, b in zip(steps, steps[1:])]}
    if time is not None:
        entry["time"] = np.asarray(time).tolist()
        entry["difference_series"] = [np.abs(np.asarray(a) - np.asarray(b)).tolist() for a, b in zip(values, values[1:])]
    return entry


# ---------------------------------------------------------------------------------------------
# e: MPI


def study_e(runner: Runner, settings: Settings) -> dict:
    cases = [(level, ranks, mpi_case(f"mpirun -n {ranks} FOM L{level}", base_scene(settings, level=level), ranks))
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
    return {"study": "e", "levels": list(settings.mpi_levels), "runs": runs, "comparisons": comparisons}


# ---------------------------------------------------------------------------------------------
# Stress tests


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
            "energy_note": "the balance includes the work of the actuation, the Lighthill thrust and the drag; "
                           "dissipation is the Rayleigh damping (trapezoidal rule over the stored samples)"}


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


# ---------------------------------------------------------------------------------------------
# Driver


def study_mesh_convergence(runner: Runner, settings: Settings) -> dict:
    """Mesh convergence of the nominal FOM per element degree and level; Richardson reference."""
    from aquarom_fenics.verification.convergence import MeshCase, mesh_convergence

    cases = [mesh_case(f"degree {degree}, level {level}",
                       base_scene(settings, level=level).replace("mesh", degree=degree))
             for degree, levels in settings.mesh_series for level in levels]
    records = runner.run("mesh_convergence", cases)
    fields = MeshCase.__dataclass_fields__
    measured = [MeshCase(**{name: record[name] for name in fields}) for record in records
                if record["status"] == "completed"]
    failed = [{"label": record["label"], "status": record["status"], "message": record.get("message")}
              for record in records if record["status"] != "completed"]
    return mesh_convergence(measured) | {"failed": failed}


STUDY_FUNCTIONS = {"a": study_a, "b": study_b, "c": study_c, "d": study_d, "e": study_e, "stress": study_stress,
                   "mesh_convergence": study_mesh_convergence}


def run(settings: Settings, out: Path, report_path: Path, studies=STUDIES, recompute_failed=False,
        time_limit: float | None = None, stream=None, jobs: int = 1) -> dict:
    """Every selected study (missing cases first in ``jobs`` workers when jobs > 1), figures, report."""
    started = time.perf_counter()
    time_limit = time_limit or settings.time_limit
    runner = Runner(out, time_limit, recompute_failed=recompute_failed, stream=stream, concurrent_jobs=1)
    parallel = 0
    if jobs > 1:
        collector = Runner(out, time_limit, recompute_failed=recompute_failed, stream=stream, collect=True)
        for study in studies:
            try:
                STUDY_FUNCTIONS[study](collector, settings)
            except CasesCollected:
                pass
        parallel = compute_in_parallel(runner, collector.collected, jobs)
    from aquarom_fenics.io.outputs import software_versions
    from aquarom_fenics.io.persistence import write_json_atomic

    functions = STUDY_FUNCTIONS
    for study in studies:
        study_started = time.perf_counter()
        print(f"== study {study} ==", file=runner.stream, flush=True)
        result = functions[study](runner, settings)
        result["settings"] = asdict(settings)
        result["written_at"] = time.strftime("%Y-%m-%d %H:%M:%S")
        result["study_time"] = time.perf_counter() - study_started
        write_json_atomic(out / f"{study}.json", result)
        if study == "d":
            write_json_atomic(out / "time_convergence.json", time_convergence_summary(result))
    info = {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "versions": software_versions(), "machine": machine(),
            "quick": settings.quick, "studies": list(studies), "cases": dict(runner.counts), "jobs": jobs,
            "computed_in_parallel": parallel, "compute_time": runner.compute_time, "command": " ".join(sys.argv)}
    figures = report.make_figures(out)
    info["wall_time"] = time.perf_counter() - started
    write_json_atomic(out / "run.json", info)
    history_path = out / "run_history.json"
    history = json.loads(history_path.read_text()) if history_path.exists() else []
    history.append({"date": info["date"], "wall_time": info["wall_time"], "cases": info["cases"],
                    "quick": settings.quick, "studies": list(studies), "cores": info["machine"]["cores"], "jobs": jobs,
                    "from_empty": runner.counts["cached"] == 0 and runner.counts["computed"] > 0
                    and tuple(studies) == STUDIES})
    write_json_atomic(history_path, history[-20:])
    report.write_report(out, report_path)
    print(f"{sum(runner.counts.values())} cases: " + ", ".join(f"{n} {what}" for what, n in runner.counts.items())
          + f"; {info['wall_time']:.1f} s; figures {len(figures)}; report {report_path}", file=runner.stream, flush=True)
    return info


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="levels 1–2, three stiffnesses, 0.4 s horizon (smoke run)")
    parser.add_argument("--only", help=f"comma-separated studies among {', '.join(STUDIES)} (default all)")
    parser.add_argument("--out", type=Path, help="results folder (default results/validation, "
                                                 "results/validation-quick with --quick)")
    parser.add_argument("--report", type=Path, help="report file (default results/REPORT.md, <out>/REPORT.md with --quick)")
    parser.add_argument("--report-only", action="store_true", help="rewrite figures and report from the cached results")
    parser.add_argument("--recompute-failed", action="store_true", help="recompute cached cases that did not complete")
    parser.add_argument("--time-limit", type=float, help="seconds per case (default 1800, 300 with --quick)")
    parser.add_argument("--jobs", type=int, default=1,
                        help="compute the missing cases in this many worker processes first (the MPI study e "
                             "always runs alone afterwards); timings are then taken with that many cases at once")
    args = parser.parse_args(argv)
    settings = QUICK if args.quick else FULL
    out = args.out or REPOSITORY / "results" / ("validation-quick" if args.quick else "validation")
    report_path = args.report or (out / "REPORT.md" if args.quick else REPOSITORY / "results" / "REPORT.md")
    if args.report_only:
        report.make_figures(out)
        report.write_report(out, report_path)
        print(f"wrote {report_path}")
        return 0
    studies = STUDIES
    if args.only:
        studies = tuple(name.strip() for name in args.only.split(",") if name.strip())
        unknown = [name for name in studies if name not in STUDIES]
        if unknown:
            parser.error(f"--only: unknown studies {', '.join(unknown)}; valid: {', '.join(STUDIES)}")
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    run(settings, out, report_path, studies, args.recompute_failed, args.time_limit, jobs=args.jobs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
