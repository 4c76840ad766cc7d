"""results/REPORT.md of `make validate` from the study files <out>/<study>.json.

Plain JSON in, Markdown out: no FEniCS import, so that the report can be rewritten
(``validate.py --report-only``) and tested without running a model. A study that has not been run
yet appears as such; every figure and table comes with one sentence saying what it shows,
computed from the numbers.
"""
from __future__ import annotations

import re
import time
from pathlib import Path

from aquarom_fenics.io.persistence import write_text_atomic
from aquarom_fenics.verification.validation.calibration import section_calibration
from aquarom_fenics.verification.validation.figures_accuracy import sorted_fits
from aquarom_fenics.verification.validation.report_format import (BUILD_EXPONENT_MAX, FIGURES, RATIO_RANGE,
                                                                   RUN_LIMITS, SOLVE_EXPONENT_MAX, TOLERANCE_LIST,
                                                                   TOLERANCE_REFERENCE, cases_above, fmt, link,
                                                                   load_studies, percent, reference_row, table)
from aquarom_fenics.verification.validation.report_sections import (fish_mesh_checks, section_a, section_b,
                                                                     section_c, section_d, section_e,
                                                                     section_fish_mesh, section_mesh,
                                                                     section_stations, section_stress)


def checks(studies: dict, out: Path) -> list[list[str]]:
    """The issue's "must show" items: [check, measured, required, verdict]."""
    rows = []

    def verdict(ok):
        return "—" if ok is None else ("pass" if ok else "**FAIL**")

    present = all((out / FIGURES[name]).exists() for name in ("heatmap_relative", "heatmap_absolute", "pareto"))
    rows.append(["heat maps and Pareto plot written", "yes" if present else "missing", "exist", verdict(present)])
    a = studies.get("a")
    row = reference_row(a) if a else None
    if row:
        rom, paper = row["models"].get("rom", {}), row["models"].get("rom-paper", {})
        error = rom.get("distance_error_relative")
        ok = None if error is None else abs(error) <= TOLERANCE_REFERENCE
        rows.append([f"default ROM distance error, {row['cells']} cells, k = {row['stiffness'] / 1e3:g} kPa",
                     f"{percent(error)} (source's basis: {percent(paper.get('distance_error_relative'))})",
                     f"within ±{100 * TOLERANCE_REFERENCE:g}%", verdict(ok)])
        listed = cases_above(a)
        rows.append([f"cases above ±{100 * TOLERANCE_LIST:g}% (all models)", str(len(listed)), "listed in §a", "—"])
    else:
        rows.append(["default ROM distance error at the reference case", "not run", f"within ±{100 * TOLERANCE_REFERENCE:g}%", "—"])
    d = studies.get("d")
    if d:
        for quantity in d["quantities"]:
            if "head x," not in quantity["name"]:
                continue
            second_order = quantity.get("second_order", quantity.get("newmark_alpha", 0.0) == 0.0)
            required = f"{RATIO_RANGE[0]:g}–{RATIO_RANGE[1]:g}" if second_order else "→ 2 (first order: γ = ½ + α_N)"
            window = [r for r in quantity.get("window_ratios", [quantity.get("ratio")]) if r is not None]
            if not window:
                rows.append([f"time-step ratios, {quantity['name']}", quantity.get("status", "—"), required,
                             verdict(False) if second_order else "—"])
                continue
            ok = all(RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1] for ratio in window)
            finest = quantity.get("finest_ratio")
            shown = ", ".join(fmt(ratio, ".2f") for ratio in window)
            if finest is not None and len(quantity.get("ratios", [])) > len(window):
                shown += f" (finest pair {quantity['pairs'][-1]} s: {fmt(finest, '.2f')})"
            if quantity.get("last_stroke_window_ratios"):       # shown, not judged: the target is the whole run
                shown += (f"; last stroke only (t ≥ {quantity['last_stroke_start']:g} s): "
                          + ", ".join(fmt(ratio, ".2f") for ratio in quantity["last_stroke_window_ratios"]))
            rows.append([f"time-step ratios, {quantity['name']}", shown, required,
                         verdict(ok) if second_order else "—"])
    b = studies.get("b")
    if b:
        for fit in sorted_fits(b):
            if fit["model"] == "FOM" or fit["quantity"] not in ("solve", "build"):
                continue
            limit = SOLVE_EXPONENT_MAX if fit["quantity"] == "solve" else BUILD_EXPONENT_MAX
            exponent = fit.get("exponent")
            ok = None if exponent is None else (exponent < limit if fit["quantity"] == "solve" else exponent <= limit)
            rows.append([f"{b['models'].get(fit['model'], fit['model'])} {fit['quantity']} time ∝ cells^e",
                         fmt(exponent, ".3f"), ("< " if fit["quantity"] == "solve" else "≤ ") + f"{limit:g}",
                         verdict(ok)])
    rows += fish_mesh_checks(studies.get("fish_mesh_convergence"))
    for run in (studies.get("history") or [])[-3:]:
        if run.get("quick"):
            continue
        kind = "all cached" if run["cases"].get("computed", 0) == 0 else "from empty" if run.get("from_empty") else None
        limit = RUN_LIMITS.get(kind)
        rows.append([f"`make validate` run of {run['date']} ({run['cases'].get('computed', 0)} computed, "
                     f"{run['cases'].get('cached', 0)} cached, {run.get('cores')} cores)",
                     f"{run['wall_time'] / 60:.1f} min", f"≤ {limit / 60:g} min ({kind})" if limit else
                     "(partial rerun)", verdict(run["wall_time"] <= limit) if limit else "—"])
    return rows


def write_report(out: Path, report: Path, studies_summary: Path | None = None) -> Path:
    """REPORT.md from the study files in ``out`` (and the optimisation summary when present)."""
    out, report = Path(out), Path(report)
    studies = load_studies(out)
    run = studies.get("run", {})
    lines = ["# Validation report", "",
             f"Generated {time.strftime('%Y-%m-%d %H:%M:%S')} from `{link(out, report)}/` by "
             "`scripts/validate.py` (`make validate`)."]
    if run:
        machine = run.get("machine", {})
        versions = ", ".join(f"{name} {value}" for name, value in run.get("versions", {}).items())
        lines += ["", f"- Last run: {run.get('date')}, {run.get('wall_time', 0) / 60:.1f} min, cases "
                  + ", ".join(f"{n} {what}" for what, n in run.get("cases", {}).items())
                  + f"; studies {', '.join(run.get('studies', []))}" + (" (**quick mode**)" if run.get("quick") else ""),
                  f"- Machine: {machine.get('cores')} cores, {machine.get('cpu')}, "
                  f"{fmt(machine.get('memory_gib'), '.1f')} GiB, {machine.get('platform')}",
                  f"- Versions: {versions}"]
    lines += ["", "## Checks", "",
              "The acceptance items of the validation issue, computed from the results below."
              + (" Quick mode: levels 1–2 and a 0.4 s horizon, so the exponent fits rest on two levels and on solves "
                 "of a few hundredths of a second; they are smoke tests, not measurements." if run.get("quick") else ""),
              ""]
    lines += table(["check", "measured", "required", "verdict"], checks(studies, out))
    lines += [""]
    section_a(lines, studies.get("a"), out, report)
    section_b(lines, studies.get("b"), out, report)
    section_c(lines, studies.get("c"), out, report)
    section_d(lines, studies.get("d"), out, report)
    section_e(lines, studies.get("e"))
    section_stress(lines, studies.get("stress"), out, report)
    section_mesh(lines, studies.get("mesh_convergence"), out, report)
    section_stations(lines, studies.get("stations"))
    section_fish_mesh(lines, studies.get("fish_mesh_convergence"))
    section_calibration(lines, studies.get("calibration"))
    _section_validity(lines, out / "prom_validity.md", report)
    _section_optimisation(lines, studies_summary or report.parent / "studies" / "summary.md", report)
    lines += ["## Reproduce", "", "    make validate                                   # every study, cached per case",
              "    .venv/bin/python scripts/validate.py --quick    # smoke run: levels 1–2, 0.4 s horizon",
              "    .venv/bin/python scripts/validate.py --only c,d # selected studies",
              "    .venv/bin/python scripts/validate.py --report-only", "",
              f"Cases are cached in `{link(out / 'cases', report)}/` (one JSON file per case, keyed by the scene "
              "hash, the model settings and the software versions); delete a file to recompute that case.", ""]
    report.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(report, "\n".join(lines))
    return report


def _embedded(path: Path, report: Path) -> str:
    """A Markdown file's text with its relative links made relative to the report, headings demoted."""
    text = path.read_text()
    prefix = link(path.parent, report)

    def relink(match):
        target = match.group(2)
        if re.match(r"^(https?:|/|#)", target):
            return match.group(0)
        return f"{match.group(1)}({prefix}/{target})" if prefix != "." else match.group(0)

    text = re.sub(r"(\]\s*)\(([^)\s]+)\)", relink, text)
    return re.sub(r"^(#+)", r"\1##", text, flags=re.MULTILINE).strip()


def _section_validity(lines, path: Path, report: Path):
    """The PROM validity-radius study (scripts/validate_prom_radius.py), when it has been run."""
    if path.exists():
        lines += ["## PROM validity radius", "",
                  f"From `{link(path, report)}` (`scripts/validate_prom_radius.py`): the SO1 PROM built at ξ = 0 "
                  "against the FOM along each shape direction.", "", _embedded(path, report), ""]


def _section_optimisation(lines, summary: Path, report: Path):
    lines += ["## Optimisation studies", ""]
    if not summary.exists():
        lines += [f"*No optimisation summary yet* (`make study` writes `{link(summary, report)}`).", ""]
        return
    lines += [f"From `{link(summary, report)}`: the optimisation table of the shape studies.", "",
              _embedded(summary, report), ""]
