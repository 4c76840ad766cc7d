"""Studies a–c of the validation: accuracy over mesh levels × stiffnesses, cost against size, run
time against error (SPEC §11)."""
from __future__ import annotations

from aquarom_fenics.studies.estimate import power_law_fit
from aquarom_fenics.verification.compare import deviation
from aquarom_fenics.verification.validation.cases import fom_case, reduced_case
from aquarom_fenics.verification.validation.runner import Runner
from aquarom_fenics.verification.validation.settings import (PROM_SCENES, REFERENCE_STIFFNESS, Settings, base_scene,
                                                             kpa)


def accuracy_models(settings: Settings, level: int, stiffness: float) -> list[tuple[str, str, object]]:
    """(model id, label, case) of the reduced models of study a at one (level, k)."""
    nominal = base_scene(settings, level=level, stiffness=stiffness, degree=settings.study_degree)
    models = [("rom", "ROM", reduced_case(f"ROM L{level} k={kpa(stiffness)}", nominal, parametric=False)),
              ("rom-paper", "ROM, source's basis",
               reduced_case(f"ROM (source's basis) L{level} k={kpa(stiffness)}",
                            nominal.replace("reduction", basis="paper"), parametric=False))]
    for p, name in PROM_SCENES.items():
        scene = base_scene(settings, name, level=level, stiffness=stiffness, degree=settings.study_degree)
        models.append((f"prom{p}", f"PROM, p = {p}",
                       reduced_case(f"PROM p={p} L{level} k={kpa(stiffness)}", scene, parametric=True,
                                    sensitivities=True)))
    return models


def study_a(runner: Runner, settings: Settings, stiffnesses=None, study="a") -> dict:
    stiffnesses = settings.stiffnesses if stiffnesses is None else stiffnesses
    grid, cases = [], []
    for level in settings.levels:
        for stiffness in stiffnesses:
            fom = fom_case(f"FOM L{level} k={kpa(stiffness)}",
                           base_scene(settings, level=level, stiffness=stiffness, degree=settings.study_degree))
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
    return {"study": study, "degree": settings.study_degree, "levels": list(settings.levels), "stiffnesses": list(stiffnesses), "cells": cells,
            "reference_level": settings.reference_level, "reference_stiffness": REFERENCE_STIFFNESS,
            "duration": settings.duration, "models": model_labels, "rows": rows}


SUMMARY_KEYS = ("status", "message", "distance", "tail_amplitude", "wall_time", "setup_time", "solve_time",
                "solve_time_sensitivities", "build_time", "build_basis", "build_tensors", "build_rest", "size",
                "parameters", "labels", "dropped", "cells", "dofs", "stopped_at", "newton", "compute_time",
                "computed_at")


ENERGY_KEYS = ("available", "message", "work_actuation", "work_thrust", "work_drag", "throughput",
               "dissipated_rayleigh", "dissipated_numerical", "kinetic_change", "strain_change", "relative_imbalance",
               "numerical_dissipation_relative")
"""Fields of a FOM record's energy balance kept in the study rows (the series stay in the case record)."""


def summary_of(record: dict) -> dict:
    summary = {key: record.get(key) for key in SUMMARY_KEYS if key in record}
    if record.get("energy"):
        summary["energy"] = {key: record["energy"][key] for key in ENERGY_KEYS if key in record["energy"]}
    return summary


def errors_against(reference: dict, record: dict) -> dict:
    """Errors of a model's distance and tail amplitude against the FOM (None when either stopped)."""
    ok = reference.get("status") == "completed" and record.get("status") == "completed"
    errors = {}
    for name in ("distance", "tail_amplitude"):
        absolute, relative = deviation(record[name], reference[name]) if ok else (None, None)
        errors[f"{name}_error_absolute"], errors[f"{name}_error_relative"] = absolute, relative
    return errors


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
    return {"study": "b", "degree": accuracy["degree"], "stiffnesses": accuracy["stiffnesses"], "models": {"FOM": "FOM"} | accuracy["models"],
            "series": series, "fits": fits}


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
