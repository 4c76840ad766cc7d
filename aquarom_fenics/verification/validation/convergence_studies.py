"""Convergence studies of the validation: time step (study d) and mesh (SPEC §11)."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from aquarom_fenics.dynamics import trajectory
from aquarom_fenics.io.scene import Scene, SolverSection
from aquarom_fenics.verification.convergence import QUANTITIES, MeshCase, mesh_convergence, richardson
from aquarom_fenics.verification.validation.cases import fom_case, mesh_case, reduced_case
from aquarom_fenics.verification.validation.report_format import RATIO_RANGE
from aquarom_fenics.verification.validation.runner import Runner
from aquarom_fenics.verification.validation.settings import Settings, base_scene, fish_scene


@dataclass(frozen=True)
class ConvergenceScheme:
    """A time scheme of study d: its label, [solver] values, whether it is second order, and the
    smooth start-up τ [s] of the actuation (``[actuation] start_ramp``, 0: SPEC's law)."""

    tag: str
    solver: tuple          # ([solver] key, value) pairs
    second_order: bool
    start_ramp: float = 0.0

    def facts(self) -> dict:
        """integrator, ρ∞ or α_N and the start ramp, as written with each quantity."""
        values = {**vars(SolverSection()), **dict(self.solver)}
        key = "rho_infinity" if values["integrator"] == "generalized-alpha" else "newmark_alpha"
        return {"integrator": values["integrator"], key: values[key], "second_order": self.second_order,
                "start_ramp": self.start_ramp}


SMOOTH_START = 0.5
"""τ [s] of the smooth start-up run beside SPEC's actuation in study d."""


def convergence_schemes() -> tuple[ConvergenceScheme, ...]:
    """The default scheme (generalized-α, second order for any ρ∞), Newmark at its default α_N, and
    the default scheme with a smooth start of the actuation.

    With γ = ½ + α_N Newmark's error has an O(α_N h) term, so for α_N > 0 the ratios tend to 2
    as h → 0; how soon depends on α_N against h. SPEC's a = A sin(2π f t) from rest makes ȧ jump at
    t = 0, which rings stiff modes that h ≥ 0.0025 s does not resolve; with a(t) ~ t³ at the start
    (``start_ramp``) the same scheme shows its order."""
    defaults = SolverSection()
    default_tag = f"generalized-α ρ∞ = {defaults.rho_infinity:g}"
    return (ConvergenceScheme(default_tag, (), True),
            ConvergenceScheme(f"Newmark α_N = {defaults.newmark_alpha:g}", (("integrator", "newmark"),),
                              defaults.newmark_alpha == 0.0),
            ConvergenceScheme(f"{default_tag}, smooth start τ = {SMOOTH_START:g} s", (), True, SMOOTH_START))


def study_d(runner: Runner, settings: Settings) -> dict:
    """Successive-difference ratios of each model and scheme over ``settings.convergence_steps`` (the
    window of the validation issue), the default scheme continued to finer steps per model: a
    second-order scheme's ratios tend to 4 once h ω is small for every mode the run excites."""
    schemes = convergence_schemes()
    finer = dict(settings.finer_convergence_steps)
    degree, level = convergence_mesh(settings)
    families = {}
    for scheme in schemes:
        def scene(name="nominal", h=0.02, scheme=scheme):
            return base_scene(settings, name, level=level, degree=degree, time_step=h,
                              solver=dict(scheme.solver)).replace("actuation", start_ramp=scheme.start_ramp)

        def steps_of(model, scheme=scheme):
            return tuple(settings.convergence_steps) + (finer.get(model, ()) if scheme is schemes[0] else ())
        tag = scheme.tag
        families[(scheme, "FOM", f"FOM, {tag}")] = [fom_case(f"FOM h={h} {tag}", scene(h=h)) for h in steps_of("FOM")]
        families[(scheme, "ROM", f"ROM, {tag}")] = [reduced_case(f"ROM h={h} {tag}", scene(h=h), parametric=False)
                                                   for h in steps_of("ROM")]
        families[(scheme, "PROM", f"PROM p=3 sensitivities, {tag}")] = [
            reduced_case(f"PROM SO1 h={h} {tag} with sensitivities", scene("so1", h), parametric=True,
                         sensitivities=True) for h in steps_of("PROM")]
    cases = [case for family in families.values() for case in family]
    records = dict(zip((case.key for case in cases), runner.run("d", cases)))
    coarse = settings.convergence_steps[0]
    window = len(settings.convergence_steps)
    last_stroke = trajectory.last_stroke_start(settings.duration, cases[0].scene.actuation.frequency)
    result = {"study": "d", "degree": degree, "level": level, "duration": settings.duration,
              "time_steps": list(settings.convergence_steps), "finer_time_steps": finer, "grid_step": coarse,
              "schemes": [{"tag": scheme.tag} | scheme.facts() for scheme in schemes], "quantities": []}
    for (scheme, model, name), family in families.items():
        runs = [records[case.key] for case in family]
        steps = [case.scene.solver.time_step for case in family]
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
                                                        [s[1][:, index] for s in series], series[0][0], steps, window,
                                                        facts | {"quantity": f"d head_x / d {parameter}"},
                                                        last_stroke))
            gradients = [np.asarray(run["distance_gradient"]) for run in runs]
            result["quantities"].append(convergence(f"d distance / d ξ (PROM p=3, norm over parameters), {scheme.tag}",
                                                    gradients, None, steps, window,
                                                    facts | {"quantity": "d distance / d xi"}))
        else:
            for quantity, label in (("head_x", "head x"), ("tail_y", "tail y")):
                series = [on_grid(run["trajectory"]["time"], np.asarray(run["trajectory"][quantity]), coarse)
                          for run in runs]
                result["quantities"].append(convergence(f"{model} {label}, {scheme.tag}", [s[1] for s in series],
                                                        series[0][0], steps, window, facts | {"quantity": quantity},
                                                        last_stroke))
    return result


def convergence_mesh(settings: Settings) -> tuple[int, int]:
    """(degree, level) of study d: the settings' or, when None, the shipped nominal scene's."""
    if settings.convergence_mesh is not None:
        return settings.convergence_mesh
    mesh = Scene.load("nominal").mesh
    return mesh.degree, mesh.level


def time_convergence_summary(study: dict) -> dict:
    """The ratios of study d per scheme, model and quantity (results/validation/time_convergence.json)."""
    summary = {"degree": study.get("degree", 1), "level": study["level"], "duration": study["duration"],
               "time_steps": study["time_steps"], "finer_time_steps": study.get("finer_time_steps", {}),
               "ratio_range_second_order": list(RATIO_RANGE), "schemes": []}
    for scheme in study["schemes"]:
        entries = [q for q in study["quantities"] if q["integrator"] == scheme["integrator"]
                   and q.get("rho_infinity") == scheme.get("rho_infinity")
                   and q.get("newmark_alpha") == scheme.get("newmark_alpha")
                   and q.get("start_ramp", 0.0) == scheme.get("start_ramp", 0.0)]
        models = {}
        for entry in entries:
            models.setdefault(entry["model"], {})[entry.get("quantity", entry["name"])] = (
                {key: entry.get(key) for key in ("pairs", "ratios", "window_ratios", "finest_ratio", "differences",
                                                 "last_stroke_start", "last_stroke_window_ratios")}
                if entry["status"] == "completed" else {"status": entry["status"], "message": entry.get("message")})
        summary["schemes"].append(scheme | {"models": models})
    return summary


def on_grid(time, values, step):
    """Samples of ``values`` at the multiples of ``step`` (the coarsest run's samples)."""
    time = np.asarray(time)
    stride = int(round(step / (time[1] - time[0])))
    return time[::stride], np.asarray(values)[::stride]


def convergence(name, values, time, steps, window, facts: dict, last_stroke_start: float | None = None) -> dict:
    """Successive differences ‖q_h - q_h/2‖_∞ and their ratios (≈ 4 for a second-order scheme):
    ``window_ratios`` over the first ``window`` steps, ``finest_ratio`` of the last three. For a time
    series with ``last_stroke_start`` also ``last_stroke_window_ratios``, the same with the maxima
    taken over t ≥ that time (the periodic gait, after the start's transient)."""
    gaps = [np.abs(np.asarray(a) - np.asarray(b)) for a, b in zip(values, values[1:])]
    differences = [float(np.max(gap)) for gap in gaps]
    ratios = successive_ratios(differences)
    in_window = max(window - 2, 0)
    entry = {"name": name, **facts, "status": "completed", "steps": list(steps), "differences": differences,
             "ratios": ratios, "window_ratios": ratios[:in_window],
             "ratio": ratios[0] if ratios else None, "finest_ratio": ratios[-1] if ratios else None,
             "pairs": [f"{a:g}–{b:g}" for a, b in zip(steps, steps[1:])]}
    if time is not None:
        entry["time"] = np.asarray(time).tolist()
        entry["difference_series"] = [gap.tolist() for gap in gaps]
        if last_stroke_start is not None:
            late = np.asarray(time) >= last_stroke_start - 1e-12
            entry["last_stroke_start"] = last_stroke_start
            entry["last_stroke_window_ratios"] = successive_ratios([float(np.max(gap[late])) for gap in gaps])[:in_window]
    return entry


def successive_ratios(differences: list[float]) -> list[float | None]:
    """d_k / d_{k+1} of successive differences (None where d_{k+1} = 0)."""
    return [first / second if second > 0 else None for first, second in zip(differences, differences[1:])]


def study_mesh_convergence(runner: Runner, settings: Settings) -> dict:
    """Mesh convergence of the nominal FOM per element degree and level; Richardson reference."""
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


FISH_TOLERANCE = 0.01
"""The shipped fish's mesh convergence: its reference distance is known to 1 % (estimated error), and
its finest level lies within 1 % of it."""


def study_fish_mesh_convergence(runner: Runner, settings: Settings) -> dict:
    """Mesh convergence of the shipped fish (``scenes/fish.toml``, degree 2) over its shipped levels
    (``meshes/fish_l<level>.msh``): the quantities of the block's study and a Richardson reference."""
    levels = list(settings.fish_levels)
    cases = [mesh_case(f"fish, degree 2, level {level}", fish_scene(settings, level)) for level in levels]
    records = runner.run("fish_mesh_convergence", cases)
    fields = MeshCase.__dataclass_fields__
    measured = [replace(MeshCase(**{name: record[name] for name in fields}), level=level)
                for level, record in zip(levels, records) if record["status"] == "completed"]
    failed = [{"label": record["label"], "status": record["status"], "message": record.get("message")}
              for record in records if record["status"] != "completed"]
    result = {"levels": levels, "tolerance": FISH_TOLERANCE, "failed": failed}
    if len(measured) < 3:
        return result | {"rows": [], "reference": {}}
    study = mesh_convergence(measured) | result
    study["distance_reference"] = distance_reference(study["reference"]["distance"], study["rows"])
    for row in study["rows"]:
        row["distance_error"] = row["distance"] / study["distance_reference"]["value"] - 1.0
    return study


def distance_reference(richardson_reference: dict, rows: list[dict]) -> dict:
    """The reference distance of a convergence series: Richardson's when the series shows an order;
    otherwise (differences that stall or change sign, as re-meshed unstructured levels give once
    converged) the finest level's distance, with the spread of the three finest levels as its error."""
    if richardson_reference.get("value") is not None:
        return {"value": richardson_reference["value"], "estimated_error": richardson_reference["estimated_error"],
                "method": f"Richardson, observed order {richardson_reference['observed_order']:.2f}"}
    finest = sorted(rows, key=lambda row: row["cells"])[-3:]
    values = [row["distance"] for row in finest]
    return {"value": values[-1], "estimated_error": max(values) - min(values),
            "method": "finest level, error: the spread of the three finest levels (no Richardson order: "
                      f"{richardson_reference.get('reason', 'none')})"}


def study_stations(runner: Runner, settings: Settings) -> dict:
    """Convergence in the station count N_s on one mesh (SPEC §5, "Measured"): the nominal fish's
    quantities per N_s and, per quantity, Richardson's reference in the station spacing L/N_s."""
    degree, level = settings.station_mesh
    counts = list(settings.station_counts)
    cases = [mesh_case(f"degree {degree}, level {level}, N_s = {count}",
                       base_scene(settings, level=level, degree=degree).replace("fluid", stations=count))
             for count in counts]
    records = runner.run("stations", cases)
    rows = [{"stations": count, **{name: record.get(name) for name in QUANTITIES}, "status": record["status"]}
            for count, record in zip(counts, records)]
    completed = [row for row in rows if row["status"] == "completed"]
    reference = {}
    if len(completed) >= 3:
        # richardson's h = cells^(-1/3): pass N_s³ so that h is the station spacing in units of L
        spacing_cells = [row["stations"] ** 3 for row in completed]
        # the spine's line integral: the trapezoid rule is second order in L/N_s, the rear-station rule first
        formal = 2.0 if base_scene(settings).fluid.spine_rule == "trapezoid" else 1.0
        reference = {name: richardson(spacing_cells, [row[name] for row in completed], formal) for name in QUANTITIES}
        for row in rows:
            if row["status"] == "completed" and reference["distance"]["value"] is not None:
                row["distance_error"] = row["distance"] / reference["distance"]["value"] - 1.0
    return {"degree": degree, "level": level, "rows": rows, "reference": reference}
