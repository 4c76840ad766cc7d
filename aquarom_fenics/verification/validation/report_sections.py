"""The study sections of the validation report (a–e, stress tests, mesh convergence): Markdown lines."""
from __future__ import annotations

from aquarom_fenics.verification.validation.figures_accuracy import pareto_front, pareto_points, sorted_fits
from aquarom_fenics.verification.validation.report_format import (TOLERANCE_LIST, cases_above, energy_share, fmt,
                                                                   model_order, not_run, percent, short,
                                                                   show_figure, table)

def section_a(lines, study, out, report):
    title = "## a. FOM against ROM and PROM over mesh levels and actuation stiffnesses"
    if not study:
        return not_run(lines, title)
    labels = study["models"]
    models = {m: labels[m] for m in model_order(labels)}
    rows = study["rows"]
    completed = [row for row in rows if row["fom"].get("status") == "completed"]
    failed = [row for row in rows if row["fom"].get("status") != "completed"]
    amplitudes = [row["fom"]["tail_amplitude"] for row in completed]
    lines += [title, "",
              f"{len(rows)} cases: degree {study.get('degree', 1)}, levels {', '.join(map(str, study['levels']))} × k = "
              f"{', '.join(f'{k / 1e3:g}' for k in study['stiffnesses'])} kPa, horizon {study['duration']:g} s; "
              f"FOM tail amplitudes {fmt(min(amplitudes, default=None), '.2f', 100)}–"
              f"{fmt(max(amplitudes, default=None), '.2f', 100)} cm; {len(failed)} FOM run(s) stopped. "
              "Reduced models are built at ξ = 0 of the nominal fish (PROM p = 3, 5, 8: the shape sets of SO1, SO2, "
              "SO3) and compared with the FOM at ξ = 0; errors are model − FOM.", ""]
    for key, caption, kind in (("heatmap_relative", "Relative distance error heat maps", "relative"),
                               ("heatmap_absolute", "Absolute distance error heat maps", "absolute")):
        errors = [(abs(row["models"][m]["distance_error_relative"]), models[m], row) for row in rows for m in row["models"]
                  if row["models"][m].get("distance_error_relative") is not None]
        worst = max(errors, key=lambda e: e[0], default=None)
        sentence = (f"Each panel shows one reduced model's {kind} distance error over mesh level (columns) and actuation "
                    "stiffness (rows, with the FOM tail-amplitude range); hatched cells are FOM runs that stopped. ")
        if worst and kind == "relative":
            sentence += (f"The largest relative error is {100 * worst[0]:.1f}% ({worst[1]}, level {worst[2]['level']}, "
                         f"k = {worst[2]['stiffness'] / 1e3:g} kPa).")
        elif kind == "absolute":
            absolute = [(abs(row["models"][m]["distance_error_absolute"]), models[m], row) for row in rows
                        for m in row["models"] if row["models"][m].get("distance_error_absolute") is not None]
            largest = max(absolute, key=lambda e: e[0], default=None)
            if largest:
                sentence += (f"The largest absolute error is {1000 * largest[0]:.2f} mm ({largest[1]}, level "
                             f"{largest[2]['level']}, k = {largest[2]['stiffness'] / 1e3:g} kPa); absolute errors grow "
                             "with the distance swum, i.e. with k.")
        show_figure(lines, out, report, key, caption, sentence)
    balances = [abs(energy["numerical_dissipation_relative"]) for energy in (row["fom"].get("energy") for row in rows)
                if energy and energy.get("available") and energy.get("numerical_dissipation_relative") is not None]
    lines += ["### FOM reference runs", "",
              "Distance, tail amplitude, cost, Newton iterations and the time scheme's numerical dissipation "
              "(per-force energy balance, relative to the energy throughput, see the stress tests) of every FOM "
              "case; a stopped run gives the solver's message"
              + (f"; the numerical dissipation stays below {100 * max(balances):.2f}%." if balances else "."), ""]
    lines += table(["level", "cells", "k [kPa]", "status", "distance [cm]", "tail amplitude [cm]", "set-up [s]",
                    "solve [s]", "Newton mean / max", "numerical dissipation", "message"],
                   [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}", row["fom"].get("status"),
                     fmt(row["fom"].get("distance"), ".3f", 100), fmt(row["fom"].get("tail_amplitude"), ".3f", 100),
                     fmt(row["fom"].get("setup_time"), ".2f"), fmt(row["fom"].get("solve_time"), ".1f"),
                     f"{fmt((row['fom'].get('newton') or {}).get('mean'), '.2f')} / "
                     f"{fmt((row['fom'].get('newton') or {}).get('max'), '.0f')}",
                     energy_share(row["fom"].get("energy"), "numerical_dissipation_relative"),
                     short(row["fom"].get("message"))] for row in rows])
    lines += [""]
    for key, what, unit, scale, spec in (
            ("distance_error_relative", "Relative distance error", "%", 100, "+.2f"),
            ("distance_error_absolute", "Absolute distance error", "mm", 1000, "+.3f"),
            ("tail_amplitude_error_relative", "Relative tail-amplitude error", "%", 100, "+.2f"),
            ("tail_amplitude_error_absolute", "Absolute tail-amplitude error", "mm", 1000, "+.3f")):
        values = [abs(row["models"][m][key]) for row in rows for m in row["models"] if row["models"][m].get(key) is not None]
        per_model = {m: max((abs(row["models"][m][key]) for row in rows if row["models"].get(m, {}).get(key) is not None),
                            default=None) for m in models}
        sentence = (f"{what} [{unit}] of each reduced model against the FOM per case; the largest magnitudes are "
                    + ", ".join(f"{models[m]} {fmt(v, '.3g', scale)} {unit}" for m, v in per_model.items()) + ".")
        lines += [f"### {what} [{unit}]", "", sentence if values else f"{what}: no completed pair yet.", ""]
        lines += table(["level", "cells", "k [kPa]", "FOM A [cm]"] + [models[m] for m in models],
                       [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}",
                         fmt(row["fom"].get("tail_amplitude"), ".2f", 100)]
                        + [fmt(row["models"].get(m, {}).get(key), spec, scale)
                           if row["models"].get(m, {}).get("status") == "completed" else row["models"].get(m, {}).get("status", "—")
                           for m in models] for row in rows])
        lines += [""]
    lines += ["### Build and solve times [s]", "",
              f"Build (basis + reduced tensors) and solve time ({study['duration']:g} s horizon; in brackets the PROM "
              "solve with sensitivities) of each reduced model per case; the FOM column is its total wall time.", ""]
    lines += table(["level", "cells", "k [kPa]", "FOM"] + [f"{models[m]} build / solve" for m in models],
                   [[row["level"], row["cells"], f"{row['stiffness'] / 1e3:g}", fmt(row["fom"].get("wall_time"), ".1f")]
                    + [f"{fmt(row['models'].get(m, {}).get('build_time'), '.2f')} / "
                       f"{fmt(row['models'].get(m, {}).get('solve_time'), '.2f')}"
                       + (f" ({fmt(row['models'][m].get('solve_time_sensitivities'), '.2f')})"
                          if row["models"].get(m, {}).get("solve_time_sensitivities") else "") for m in models]
                    for row in rows])
    listed = cases_above(study)
    lines += ["", f"### Cases above ±{100 * TOLERANCE_LIST:g}%", ""]
    if listed:
        lines += [f"{len(listed)} model/case pairs have a distance error beyond ±{100 * TOLERANCE_LIST:g}%, with the "
                  "FOM tail amplitude and the cells of the case:", ""]
        lines += table(["model", "level", "cells", "k [kPa]", "FOM tail amplitude [cm]", "distance error",
                        "tail amplitude error"],
                       [[entry["model"], entry["level"], entry["cells"], f"{entry['stiffness'] / 1e3:g}",
                         fmt(entry["tail_amplitude"], ".2f", 100), percent(entry["error"], 1),
                         percent(entry["tail_amplitude_error"], 1)] for entry in listed])
    else:
        lines += [f"No completed case has a distance error beyond ±{100 * TOLERANCE_LIST:g}%."]
    lines += [""]


def section_b(lines, study, out, report):
    title = "## b. Cost against size"
    if not study:
        return not_run(lines, title)
    models = study["models"]
    solve = [f for f in study["fits"] if f["quantity"] == "solve" and f["model"] != "FOM" and f.get("exponent") is not None]
    build = [f for f in study["fits"] if f["quantity"] == "build" and f["model"] != "FOM" and f.get("exponent") is not None]
    sentence = (f"Degree {study.get('degree', 1)}. Build and solve wall time of every model against the number of cells (every case of study a: small "
                "markers; per-level median: lines), log-log, with the least-squares exponents in the legends. ")
    if solve and build:
        sentence += (f"Reduced solve exponents range {min(f['exponent'] for f in solve):.2f}–"
                     f"{max(f['exponent'] for f in solve):.2f} and build exponents "
                     f"{min(f['exponent'] for f in build):.2f}–{max(f['exponent'] for f in build):.2f}.")
    lines += [title, ""]
    show_figure(lines, out, report, "cost", "Cost against cells", sentence)
    lines += ["Least-squares exponents e of t = c · cells^e (build split into basis, reduced tensors and the rest: "
              "FOM set-up, spine rows, basis gathering).", ""]
    lines += table(["model", "quantity", "exponent e", "c [s]", "points"],
                   [[models.get(f["model"], f["model"]), f["quantity"], fmt(f.get("exponent"), ".3f"),
                     fmt(f.get("prefactor"), ".3g"), f.get("points", "—")] for f in sorted_fits(study)])
    lines += [""]


def section_c(lines, study, out, report):
    title = "## c. Run time against error (reference case)"
    if not study:
        return not_run(lines, title)
    points = pareto_points(study)
    front = pareto_front(points)
    default = next((p for p in study["points"] if p.get("default")), {})
    reference = study.get("reference", {})
    lines += [title, "",
              f"Reference: the FOM at h = {study['reference_time_step']} s (level {study['level']}, distance "
              f"{fmt(reference.get('distance'), '.3f', 100)} cm, {fmt(reference.get('wall_time'), '.1f')} s); the Taylor-order "
              f"points are the SO1 PROM at ξ = {', '.join(f'{k} {v:g}' for k, v in study['taylor_design'].items())} "
              "(every parameter at its validity radius) against the FOM at that design and the same fine step.", ""]
    show_figure(lines, out, report, "pareto", "Run time against error",
            f"Every variant's |distance error| against its wall time; the default (star) has "
            f"{percent(default.get('distance_error_relative'))} in {fmt(default.get('wall_time'), '.2f')} s, and the "
            f"Pareto front of the ξ = 0 variants is {', '.join(p.get('short') or p['label'] for p in front) or '—'}.")
    lines += table(["variant", "family", "status", "m", "wall time [s]", "build [s]", "solve [s]", "distance [cm]",
                    "error", "Pareto"],
                   [[p["label"] + (" **(default)**" if p.get("default") else ""), p["family"], p.get("status"),
                     p.get("size") or "—", fmt(p.get("wall_time"), ".2f"), fmt(p.get("build_time"), ".2f"),
                     fmt(p.get("solve_time"), ".2f"), fmt(p.get("distance"), ".3f", 100),
                     percent(p.get("distance_error_relative")),
                     "yes" if any(f["id"] == p["id"] for f in front) else ""] for p in study["points"]])
    lines += [""]


def section_d(lines, study, out, report):
    title = "## d. Time-step convergence"
    if not study:
        return not_run(lines, title)
    head = [q for q in study["quantities"] if "head x," in q["name"] and q.get("ratio") is not None]
    lines += [title, "",
              f"Degree {study.get('degree', 1)}, level {study['level']}, h = "
              f"{', '.join(f'{h:g}' for h in study['time_steps'])} s"
              + "".join(f"; {model} of the default scheme also at {', '.join(f'{h:g}' for h in steps)} s"
                        for model, steps in study.get("finer_time_steps", {}).items())
              + f"; differences are "
              f"maxima over the samples of the h = {study['grid_step']:g} s grid; a second-order scheme gives ratios ≈ 4. "
              "Newmark with γ = ½ + α_N is second order only for α_N = 0: for α_N > 0 an O(α_N h) error term "
              "makes the ratios fall towards 2 once it dominates. Schemes: "
              + "; ".join(scheme["tag"] for scheme in study.get("schemes", [])) + ".", ""]
    show_figure(lines, out, report, "convergence", "Time-step convergence",
            "Successive differences over time for head x (FOM, ROM) and the PROM sensitivities; "
            + ("head-x ratios " + "; ".join(f"{q['name']} " + ", ".join(fmt(r, ".2f") for r in q["ratios"])
                                            for q in head) + "." if head else ""))
    lines += table(["quantity", "status", "max |q_h − q_h/2| per pair", "ratios"],
                   [[q["name"], q.get("status"), ", ".join(f"{pair}: {fmt(value, '.3g')}" for pair, value in
                                                           zip(q.get("pairs", []), q.get("differences", [])))
                     or short(q.get("message")), ", ".join(fmt(r, ".2f") for r in q.get("ratios", []))]
                    for q in study["quantities"]])
    lines += [""]


def section_mesh(lines, study, out, report):
    title = "## Mesh convergence of the FOM"
    if not study or not study.get("rows"):
        return not_run(lines, title)
    units = {"distance": ("cm", 100.0), "tail_amplitude": ("cm", 100.0), "first_frequency": ("Hz", 1.0),
             "static_tail_deflection": ("cm", 100.0), "tail_compliance": ("mm/N", 1e3)}
    lines += [title, "",
              "The nominal fish per element degree and mesh level: swimming distance, tail amplitude, first natural "
              "frequency (head clamped), static tail deflection with the muscles at their peak (head clamped) and the "
              "tail station's static x-compliance under a unit x-force on it (head clamped). "
              "Reference: Richardson extrapolation of the three finest cases of the highest degree with h = "
              "cells^(-1/3); its estimated error is the correction |f* − f_finest|. When the differences change sign "
              "(no order, shown as —) the finest value is the reference and the last difference its error.", ""]
    lines += table(["quantity", "reference", "observed order", "estimated error", "from degree"],
                   [[name, f"{fmt(ref['value'], '.4g', units[name][1])} {units[name][0]}",
                     fmt(ref.get("observed_order"), ".2f"), f"{fmt(ref['estimated_error'], '.2g', units[name][1])} "
                     f"{units[name][0]}", str(ref.get("degree"))] for name, ref in study["reference"].items()])
    lines += [""]
    lines += table(["degree", "level", "cells", "dofs", "distance [cm]", "error", "tail amplitude [cm]",
                    "f_1 [Hz]", "static tail y [cm]", "tail compliance [mm/N]", "wall time [s]"],
                   [[str(row["degree"]), str(row["level"]), str(row["cells"]), str(row["dofs"]),
                     fmt(row["distance"], ".4g", 100.0), percent(row["relative_error_distance"], 1),
                     fmt(row["tail_amplitude"], ".4g", 100.0), fmt(row["first_frequency"], ".4g"),
                     fmt(row["static_tail_deflection"], ".4g", 100.0), fmt(row.get("tail_compliance"), ".4g", 1e3),
                     fmt(row["wall_time"], ".1f")]
                    for row in study["rows"]])
    default = study.get("default")
    lines += ["", ("Cheapest (degree, level) within 3 % of the reference distance: "
                   f"degree {default['degree']}, level {default['level']} "
                   f"({percent(default['relative_error_distance'], 1)}, {default['wall_time']:.1f} s)."
                   if default else "No case is within 3 % of the reference distance."), ""]
    for failure in study.get("failed", []):
        lines += [f"- {failure['label']}: {failure['status']}, {short(failure.get('message'))}"]
    show_figure(lines, out, report, "mesh", "Mesh convergence", "FOM wall time against the error of each quantity.")


def section_stations(lines, study):
    title = "## Station count"
    if not study or not study.get("rows"):
        return not_run(lines, title)
    lines += [title, "",
              f"The nominal fish on degree {study['degree']}, level {study['level']} per station count N_s (the thrust "
              "acts through N_s + 1 stations, SPEC §5). Reference: Richardson extrapolation in the station spacing "
              "L/N_s of the three finest counts.", ""]
    reference = study.get("reference") or {}
    if "distance" in reference:
        ref = reference["distance"]
        lines += [f"Distance reference {fmt(ref['value'], '.4g', 100.0)} cm, observed order "
                  f"{fmt(ref.get('observed_order'), '.2f')}, estimated error {fmt(ref['estimated_error'], '.2g', 100.0)} cm.",
                  ""]
    lines += table(["N_s", "status", "distance [cm]", "error", "tail amplitude [cm]", "tail compliance [mm/N]"],
                   [[str(row["stations"]), row["status"], fmt(row.get("distance"), ".4g", 100.0),
                     percent(row.get("distance_error"), 1) if row.get("distance_error") is not None else "—",
                     fmt(row.get("tail_amplitude"), ".4g", 100.0), fmt(row.get("tail_compliance"), ".4g", 1e3)]
                    for row in study["rows"]])
    lines += [""]


def section_e(lines, study):
    title = "## e. MPI: the FOM with mpirun -n 1 and -n 2"
    if not study:
        return not_run(lines, title)
    speedups = [c for c in study["comparisons"] if c.get("speedup")]
    lines += [title, "",
              f"Degree {study.get('degree', 1)}. Wall time of `aquarom simulate` (the simulation, without interpreter start) and agreement of the two "
              "runs; " + (", ".join(f"level {c['level']}: speed-up {c['speedup']:.2f}, distance difference "
                                    f"{fmt(c.get('distance_relative_difference'), '.1e')}" for c in speedups) or
                          "no pair of completed runs yet") + ".", ""]
    lines += table(["level", "cells", "ranks", "status", "wall time [s]", "process [s]", "distance [cm]",
                    "tail amplitude [cm]", "Newton mean", "peak memory rank 0 [MB]", "message"],
                   [[r["level"], r.get("cells") or "—", r["ranks"], r.get("status"), fmt(r.get("wall_time"), ".1f"),
                     fmt(r.get("process_time"), ".1f"), fmt(r.get("distance"), ".4f", 100),
                     fmt(r.get("tail_amplitude"), ".4f", 100), fmt(r.get("mean_newton_iterations"), ".2f"),
                     fmt(r.get("peak_memory_mb_rank0"), ".0f"), short(r.get("message"), 80)] for r in study["runs"]])
    lines += ["", "Speed-up and agreement per level (head x compared sample by sample over the common time).", ""]
    lines += table(["level", "cells", "speed-up (total)", "speed-up (time integration)", "distance difference",
                    "max |Δ head x| [m]", "compared until [s]"],
                   [[c["level"], c.get("cells") or "—", fmt(c.get("speedup"), ".2f"), fmt(c.get("speedup_solve"), ".2f"),
                     fmt(c.get("distance_relative_difference"), ".2e"), fmt(c.get("head_x_max_difference"), ".2e"),
                     fmt(c.get("compared_until"), ".2f")] for c in study["comparisons"]])
    lines += [""]


def section_stress(lines, study, out, report):
    title = "## Stress tests of numerical stability"
    if not study:
        return not_run(lines, title)
    rows = study["rows"]
    unclean = [row for row in rows if not row.get("clean")]
    lines += [title, "",
              f"Level {study['level']}, horizon {study['duration']:g} s. A case passes when it converges or stops "
              "with a solver message naming the time (never a NaN, never a hang: a time limit per case); "
              f"{len(rows) - len(unclean)} of {len(rows)} cases pass.", ""]
    lines += table(["case", "model", "status", "clean", "distance [cm]", "tail amplitude [cm]", "Newton mean / max",
                    "wall time [s]", "message"],
                   [[row["description"], row["model"], row["status"], "yes" if row.get("clean") else "**no**",
                     fmt(row.get("distance"), ".3f", 100), fmt(row.get("tail_amplitude"), ".3f", 100),
                     f"{fmt((row.get('newton') or {}).get('mean'), '.2f')} / {(row.get('newton') or {}).get('max', '—')}",
                     fmt(row.get("wall_time"), ".1f"), short(row.get("message"))] for row in rows])
    fine = [row for row in rows if row["id"] == "fine-mesh-prom"]
    for row in fine:
        lines += ["", f"Fine-mesh PROM build: {row.get('cells')} cells, m = {row.get('size')}, build "
                  f"{fmt(row.get('build_time'), '.1f')} s, tensors finite: {row.get('finite_tensors')}, dropped vectors: "
                  f"{', '.join(row.get('dropped') or []) or 'none'}, process peak memory "
                  f"{fmt(row.get('peak_rss_mb_process'), '.0f')} MB."]
    energetic = [row for row in rows if row.get("energy")]
    available = [row for row in energetic if row["energy"].get("available")]
    if energetic:
        lines += ["", "### Energy balance (FOM)", "",
                  f"Work done on the fish against dissipated plus stored energy at the end of the run; {study['energy_note']}. "
                  "W_act + W_thrust + W_drag = D_Rayleigh + D_numerical + ΔE_kin + ΔE_el + Σ ρ_n: the works are "
                  "trapezoidal over each step (the thrust's added-mass part at the scheme's evaluation points), "
                  "D_numerical is what the step equations remove beyond the Rayleigh damping (zero up to O(Δu³) "
                  "for Newmark α_N = 0), and the imbalance Σ ρ_n, the Newton residual of the steps, checks that "
                  "the forces split here are the ones the integrator solved with. Shares are relative to the "
                  "energy throughput Σ_n Σ_F |ΔW_F,n| (the final works alone can be near zero: the muscles take "
                  "back over a cycle what they gave). A run that cut steps has no balance on the grid of h "
                  "(not available).", ""]
        lines += table(["case", "W_act [mJ]", "W_thrust [mJ]", "W_drag [mJ]", "throughput [mJ]", "D_Rayleigh [mJ]",
                        "D_numerical [mJ]", "ΔE_kin [mJ]", "ΔE_el [mJ]", "numerical dissipation", "imbalance"],
                       [[row["id"]] + [fmt(row["energy"].get(key), ".4g", 1e3) for key in (
                           "work_actuation", "work_thrust", "work_drag", "throughput", "dissipated_rayleigh",
                           "dissipated_numerical", "kinetic_change", "strain_change")]
                        + [energy_share(row["energy"], "numerical_dissipation_relative"),
                           energy_share(row["energy"], "relative_imbalance", ".1e")] for row in energetic])
        lines += [""]
    if available:
        worst = max(available, key=lambda row: abs(row["energy"]["relative_imbalance"] or 0))
        most = max(available, key=lambda row: abs(row["energy"].get("numerical_dissipation_relative") or 0))
        show_figure(lines, out, report, "energy", "Energy balance of the FOM stress cases",
                    f"Cumulative work in against dissipated + stored energy over time; the largest imbalance is "
                    f"{energy_share(worst['energy'], 'relative_imbalance', '.1e')} ({worst['id']}), the largest numerical "
                    f"dissipation {percent(most['energy'].get('numerical_dissipation_relative'), 3)} ({most['id']}).")
    lines += [""]


def fish_mesh_checks(study) -> list[list[str]]:
    """The shipped fish's "must show" rows: [check, measured, required, verdict]."""
    required = f"within {100 * study.get('tolerance', 0.01):g}%" if study else "within 1%"
    reference = (study or {}).get("distance_reference") or {}
    if not study or reference.get("value") in (None, 0.0) or not study.get("rows"):
        measured = "not run" if not study else "fewer than 3 levels completed"
        return [["fish: estimated error of the reference distance", measured, required, "—"]]
    tolerance = study.get("tolerance", 0.01)
    estimated = reference["estimated_error"] / abs(reference["value"])
    finest = max(study["rows"], key=lambda row: row["cells"])
    verdict = {True: "pass", False: "**FAIL**"}
    return [["fish: estimated error of the reference distance", f"{percent(estimated)} ({reference['method']})",
             required, verdict[estimated <= tolerance]],
            [f"fish: finest level ({finest['cells']} cells) against the reference distance",
             percent(finest["distance_error"]), required, verdict[abs(finest["distance_error"]) <= tolerance]]]


def section_fish_mesh(lines, study):
    title = "## Mesh convergence of the shipped fish"
    if not study or not study.get("rows"):
        not_run(lines, title)
        for failure in (study or {}).get("failed", []):
            lines += [f"- {failure['label']}: {failure['status']}, {short(failure.get('message'))}", ""]
        return
    reference = study["distance_reference"]
    lines += [title, "",
              "The shipped fish (`scenes/fish.toml`, quadratic tetrahedra) on its shipped meshes "
              "`meshes/fish_l<level>.msh` (recipe `meshes/fish.toml`): the quantities of the block's study above. "
              f"Reference distance: {fmt(reference['value'], '.4g', 100.0)} cm ± "
              f"{fmt(reference['estimated_error'], '.2g', 100.0)} cm ({reference['method']}).", ""]
    lines += table(["level", "cells", "dofs", "distance [cm]", "error", "tail amplitude [cm]", "f_1 [Hz]",
                    "static tail y [cm]", "wall time [s]"],
                   [[str(row["level"]), str(row["cells"]), str(row["dofs"]), fmt(row["distance"], ".4g", 100.0),
                     percent(row["distance_error"], 2), fmt(row["tail_amplitude"], ".4g", 100.0),
                     fmt(row["first_frequency"], ".4g"), fmt(row["static_tail_deflection"], ".4g", 100.0),
                     fmt(row["wall_time"], ".1f")] for row in study["rows"]])
    lines += [""]
    for failure in study.get("failed", []):
        lines += [f"- {failure['label']}: {failure['status']}, {short(failure.get('message'))}"]
