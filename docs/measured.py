"""Measured tables of the README and the manual, made from the JSON files the measurements wrote.

The measurements (``scripts/validate.py``, ``scripts/rom_accuracy.py``, ``scripts/validate_gradient.py``,
``scripts/bench_*.py``, ``scripts/study.py``, ``aquarom optimize``) write JSON under ``results/``,
which is not tracked. ``docs/data/`` holds a snapshot of those files, each with a ``_snapshot``
record: where it was copied from, when and on which host, or, for a figure measured before its
file was kept, ``transcribed`` with the page it was read from. ``make docs`` rewrites every table
between the markers

    <!-- measured: NAME -->
    ...
    <!-- /measured -->

in the README and the manual's pages from the snapshot, so a re-measurement changes the pages and
nobody retypes a figure. ``python docs/generate.py --snapshot`` copies what ``results/`` holds
into the snapshot (``--results`` elsewhere) with the date and host recorded.
"""
from __future__ import annotations

import json
import platform
import re
import shutil
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
SNAPSHOT = Path(__file__).resolve().parent / "data"

SOURCES = {
    "validation/mesh_convergence.json": "scripts/validate.py --only mesh_convergence",
    "validation/stations.json": "scripts/validate.py --only stations",
    "validation/rom_accuracy.json": "scripts/rom_accuracy.py --meshes 2/1 2/2 2/3",
    "validation/prom_gradient.json": "scripts/validate_gradient.py --radius",
    "validation/stroke_accuracy.json": "scripts/stroke_accuracy.py",
    "validation/material_law.json": "scripts/validate_material_law.py",
    "validation/calibration.json": "scripts/validate.py --only calibration",
    "bench/fom.json": "scripts/bench_fom.py",
    "bench/prom.json": "scripts/bench_prom.py",
    "optimize/so1/summary.json": "aquarom optimize so1 --out results/optimize/so1 (empty cache)",
    "studies/so1/summary.json": "scripts/study.py --cases so1",
    "studies/so2/summary.json": "scripts/study.py --cases so2",
    "studies/so3/summary.json": "scripts/study.py --cases so3",
    "studies/so7/summary.json": "scripts/study.py --cases so7",
    "studies/so8/summary.json": "scripts/study.py --cases so8",
    "studies/so9/summary.json": "scripts/study.py --cases so9",
    "studies/co/w1_*/summary.json": "scripts/study.py --cases co",
    "studies/so1-trust-region/summary.json": "scripts/study.py --cases so1 --methods trust-region",
    "studies/so2-trust-region/summary.json": "scripts/study.py --cases so2 --methods trust-region",
    "studies/so3-trust-region/summary.json": "scripts/study.py --cases so3 --methods trust-region",
    "studies/so7-trust-region/summary.json": "scripts/study.py --cases so7 --methods trust-region",
    "studies/so8-trust-region/summary.json": "scripts/study.py --cases so8 --methods trust-region",
    "studies/so9-trust-region/summary.json": "scripts/study.py --cases so9 --methods trust-region",
    "studies/co-trust-region/w1_*/summary.json": "scripts/study.py --cases co --methods trust-region",
    "so1-fom/summary.json": "the README's walkthrough: aquarom simulate so1 --level 1 --out results/so1-fom",
    "so1-compare/compare.json": "the README's walkthrough: aquarom compare so1 --level 1 … --out results/so1-compare",
    "so1-compare/prom/summary.json": "the README's walkthrough: aquarom compare so1 --level 1 … --out results/so1-compare",
    "so1-opt/summary.json": "the README's walkthrough: aquarom optimize so1 --level 1 --out results/so1-opt",
}
"""Snapshot files (paths under ``results/`` and ``docs/data/`` alike) and the command that writes each."""

PAGES = ("README.md", "docs/validation.md", "docs/studies.md", "docs/theory/stations.md", "docs/theory/basis.md",
         "docs/theory/material-law.md")
"""Files whose measured tables ``make docs`` rewrites."""

MARKER = re.compile(r"(<!-- measured: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /measured -->)", re.S)


class SnapshotError(RuntimeError):
    """A snapshot file is missing or lacks what a table needs."""


# ---------------------------------------------------------------- the snapshot

def snapshot_files(folder: Path = SNAPSHOT) -> list[Path]:
    """Every JSON file of the snapshot."""
    return sorted(path for pattern in SOURCES for path in folder.glob(pattern))


def load(relative: str, folder: Path = SNAPSHOT) -> dict:
    path = folder / relative
    if not path.is_file():
        raise SnapshotError(f"{path.relative_to(REPOSITORY) if path.is_relative_to(REPOSITORY) else path} is "
                            f"missing: run `{command_of(relative)}` and `python docs/generate.py --snapshot`")
    return json.loads(path.read_text())


def command_of(relative: str) -> str:
    for pattern, command in SOURCES.items():
        if Path(relative).match(pattern):
            return command
    return "the measurement"


def refresh(results: Path, folder: Path = SNAPSHOT, host: str | None = None) -> list[str]:
    """Copy every snapshot file that ``results`` holds into ``folder``, each with a ``_snapshot``
    record (the path it came from, the file's modification date, the host); return the paths copied.
    Files ``results`` does not hold keep their earlier snapshot."""
    copied = []
    for pattern in SOURCES:
        for source in sorted(results.glob(pattern)):
            relative = source.relative_to(results).as_posix()
            data = json.loads(source.read_text())
            data["_snapshot"] = {"copied_from": f"results/{relative}", "command": command_of(relative),
                                 "date": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(source.stat().st_mtime)),
                                 "host": host or platform.node()}
            target = folder / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(data, indent=1, sort_keys=False) + "\n")
            copied.append(relative)
    for sweep in ("studies/co/", "studies/co-trust-region/"):
        if any(name.startswith(sweep) for name in copied):
            kept = {name for name in copied if name.startswith(sweep)}
            for stale in folder.glob(f"{sweep}w1_*/summary.json"):
                if stale.relative_to(folder).as_posix() not in kept:
                    shutil.rmtree(stale.parent)
    return copied


def provenance(data: dict) -> str:
    """'measured on HOST, DATE' or 'transcribed from the pages on DATE' (the page is in the file)."""
    record = data.get("_snapshot", {})
    if record.get("transcribed"):
        return f"transcribed from the pages on {record['date']}"
    return f"measured on {record.get('host', '?')}, {str(record.get('date', '?'))[:10]}"


def sources_note(named: list[tuple[str, dict]]) -> str:
    """One sentence naming the snapshot files of a table, grouped by provenance."""
    groups: dict[str, list[str]] = {}
    for name, data in named:
        names = groups.setdefault(provenance(data), [])
        if f"`{name}`" not in names:
            names.append(f"`{name}`")
    return ("From `docs/data/` " + "; ".join(f"{', '.join(names)} ({what})" for what, names in groups.items())
            + ": `python docs/generate.py --snapshot` after a re-measurement replaces them.\n")


# ---------------------------------------------------------------- numbers as the pages write them

def cm(metres) -> str:
    return "n/a" if metres is None else f"{100 * metres:.3f}"


def percent(fraction) -> str:
    """A signed relative error in %: two decimals below 10 %, one above."""
    if fraction is None:
        return "n/a"
    value = 100 * fraction
    return f"{value:+.2f} %" if abs(value) < 10 else f"{value:+.1f} %"


def seconds(value) -> str:
    if value is None:
        return "n/a"
    return f"{value:.3f} s" if value < 1 else f"{value:.1f} s"


def span(values, unit=seconds) -> str:
    """'a–b s' over several runs, 'a s' over one."""
    values = sorted(v for v in values if v is not None)
    if not values:
        return ""
    if len(values) == 1 or values[0] == values[-1]:
        return unit(values[0])
    return f"{unit(values[0]).rsplit(' ', 1)[0]}–{unit(values[-1])}"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def default_mesh() -> tuple[int, int]:
    """(degree, level) of the shipped scenes (the nominal scene's mesh)."""
    from aquarom_fenics.io.scene import Scene

    mesh = Scene.load("nominal").mesh
    return mesh.degree, mesh.level


def default_station_count() -> int:
    from aquarom_fenics.io.scene import Scene

    return Scene.load("nominal").fluid.stations


# ---------------------------------------------------------------- the tables

def _reference_note(reference: dict, unit=None, short: bool = False) -> str:
    """'value ± error (order used p, observed q or none, F_s)' of a grid-convergence reference."""
    unit = unit or cm
    if reference.get("value") is None:
        return "none (no order observed that the finest level confirms)" if short else (
            f"none ({reference.get('reason', 'no order observed')})")
    observed = reference.get("observed_order")
    used = reference.get("order_used")
    how = (f"order {used:.2g} used, observed {observed:.2g}" if observed is not None
           else f"formal order {used:g}") if used is not None else (
           f"observed order {observed:.1f}" if observed is not None else "")
    safety = f", F_s = {reference['safety_factor']:g}" if reference.get("safety_factor") else ""
    return f"{unit(reference['value'])} ± {unit(reference['estimated_error'])}" + (f" ({how}{safety})" if how else "")


def _hz(value) -> str:
    return f"{value:.4f}"


def mesh_table(folder: Path = SNAPSHOT) -> str:
    """Mesh convergence of the nominal FOM: every case and the grid-convergence reference."""
    data = load("validation/mesh_convergence.json", folder)
    default = default_mesh()
    rows = []
    for row in data["rows"]:
        mark = "**" if (row["degree"], row["level"]) == default else ""
        rows.append([f"{mark}{row['degree']}{mark}", f"{mark}{row['level']}{mark}", row.get("cells", ""),
                     row.get("dofs", ""), f"{mark}{cm(row['distance'])}{mark}", percent(row["distance_error"]),
                     cm(row["tail_amplitude"]), percent(row.get("tail_amplitude_error")),
                     _hz(row["first_frequency"]) if "first_frequency" in row else "",
                     cm(row["static_tail_deflection"]) if "static_tail_deflection" in row else ""])
    reference = data["reference"]
    rows.append([f"reference (degree {reference['distance']['degree']})", "", "", "",
                 _reference_note(reference["distance"]), "", _reference_note(reference["tail_amplitude"]), "",
                 _reference_note(reference["first_frequency"], _hz) if "first_frequency" in reference else "",
                 _reference_note(reference["static_tail_deflection"]) if "static_tail_deflection" in reference else ""])
    return (table(["degree", "level", "cells", "dofs", "distance [cm]", "error", "tail amplitude [cm]", "error",
                   "f_1 [Hz]", "static tail y [cm]"], rows)
            + f"\n`{command_of('validation/mesh_convergence.json')}`. "
            + sources_note([("validation/mesh_convergence.json", data)]))


def stations_table(folder: Path = SNAPSHOT) -> str:
    """Convergence in the station count on one mesh."""
    data = load("validation/stations.json", folder)
    default = default_station_count()
    rows = []
    for row in data["rows"]:
        mark = "**" if row["stations"] == default else ""
        rows.append([f"{mark}{row['stations']}{mark}", f"{mark}{cm(row['distance'])}{mark}",
                     percent(row.get("distance_error")), cm(row.get("tail_amplitude"))])
    reference = data["reference"]["distance"]
    rows.append(["reference", _reference_note(reference), "", ""])
    return (table([f"N_s (degree {data['degree']}, level {data['level']})", "distance [cm]",
                   "error against the reference", "tail amplitude [cm]"], rows)
            + f"\n`{command_of('validation/stations.json')}`. " + sources_note([("validation/stations.json", data)]))


def _joined(values, unit=percent) -> str:
    return ", ".join(unit(v).replace(" %", "") for v in values) + " %"


def accuracy_table(folder: Path = SNAPSHOT) -> str:
    """The README's accuracy table: FOM against mesh and station limits, ROM and PROM against the FOM."""
    mesh = load("validation/mesh_convergence.json", folder)
    stations = load("validation/stations.json", folder)
    rom = load("validation/rom_accuracy.json", folder)
    gradient = load("validation/prom_gradient.json", folder)
    degree, level = default_mesh()
    rows = []
    series = [row for row in mesh["rows"] if row["degree"] == mesh["reference"]["distance"]["degree"]]
    at_default = next(row for row in mesh["rows"] if (row["degree"], row["level"]) == (degree, level))
    reference = mesh["reference"]
    rows.append([f"FOM on degree {degree}, level {level} against the mesh-converged reference (degree "
                 f"{series[0]['degree']}, levels {series[0]['level']}–{series[-1]['level']}: "
                 f"{', '.join(cm(row['distance']) for row in series)} cm; reference "
                 f"{_reference_note(reference['distance'])} cm, "
                 f"tail amplitude {_reference_note(reference['tail_amplitude'], short=True)})",
                 percent(at_default["distance_error"]), percent(at_default.get("tail_amplitude_error")),
                 "`validation/mesh_convergence.json`"])
    count = default_station_count()
    station_row = next(row for row in stations["rows"] if row["stations"] == count)
    rows.append([f"FOM with N_s = {count} against its station-converged value on degree {stations['degree']}, level "
                 f"{stations['level']} (N_s = {', '.join(str(row['stations']) for row in stations['rows'])}: "
                 f"{', '.join(cm(row['distance']) for row in stations['rows'])} cm)",
                 percent(station_row.get("distance_error")), "", "`validation/stations.json`"])
    nominal = [row for row in rom["nominal"] if row["degree"] == degree]
    rows.append([f"ROM (built at the design) against the FOM; degree {degree}, levels "
                 f"{', '.join(str(row['level']) for row in nominal)}",
                 _joined(row["default"]["distance_relative"] for row in nominal),
                 _joined(row["default"]["tail_amplitude_relative"] for row in nominal),
                 "`validation/rom_accuracy.json`"])
    scene = gradient["scene"].upper()
    for name in dict.fromkeys(row["parameter"] for row in gradient["radius_rows"]):
        pair = [row for row in gradient["radius_rows"] if row["parameter"] == name]
        rows.append([f"PROM ({scene}, built at ξ = 0) against the FOM at {name} = "
                     + " / ".join(f"{row['value']:+g}" for row in pair) + " (its validity radius), degree "
                     f"{gradient['degree']}, level {gradient['level']}",
                     " / ".join(percent(row["relative_error"]).replace(" %", "") for row in pair) + " %", "",
                     "`validation/prom_gradient.json`"])
    if gradient["rows"]:
        rows.append([f"{scene} PROM's distance gradient against FOM central differences (ε = {gradient['step']:g}; "
                     f"{', '.join(row['parameter'] for row in gradient['rows'])})",
                     _joined(row["relative_difference"] for row in gradient["rows"]), "",
                     "`validation/prom_gradient.json`"])
    notes = sources_note([(f"validation/{name}.json", data) for name, data in
                          (("mesh_convergence", mesh), ("stations", stations), ("rom_accuracy", rom),
                           ("prom_gradient", gradient))])
    return table(["comparison", "distance", "tail amplitude", "file"], rows) + "\n" + notes


def cost_table(folder: Path = SNAPSHOT) -> str:
    """The README's cost table: FOM serial and on two ranks, PROM build, reduced solve, SO1's optimisation."""
    fom = load("bench/fom.json", folder)
    prom = load("bench/prom.json", folder)
    optimize = load("optimize/so1/summary.json", folder)
    degree, level = default_mesh()
    rows = []
    cases = sorted({(run["degree"], run["level"]) for run in fom["runs"] if run["degree"] == degree and "failed" not in run})
    for case in cases:
        runs = [run for run in fom["runs"] if (run["degree"], run["level"]) == case and "failed" not in run
                and run.get("blas_threads", 1) == 1]
        dofs = next(run["dofs"] for run in runs)
        label = "FOM at the default" if case == (degree, level) else "FOM"
        rows.append([f"{label}, degree {case[0]}, level {case[1]} ({dofs} dofs)",
                     span(run["wall_time_simulation"] for run in runs if run["ranks"] == 1),
                     span(run["wall_time_simulation"] for run in runs if run["ranks"] == 2)])
    so1 = [run for run in prom["runs"] if run["scene"] == "so1" and run["degree"] == degree]
    if so1:
        rows.append([f"PROM build, SO1 (p = {so1[0]['parameters']}, m = {so1[0]['reduced_size']}), "
                     + " / ".join(f"level {run['level']}" for run in so1),
                     " / ".join(seconds(run["build_time"]) for run in so1), ""])
        at_default = [run for run in so1 if run["level"] == level]
        for run in at_default:
            rows.append([f"reduced solve, SO1, with sensitivities, level {level} (fastest / median of 20)",
                         f"{seconds(run['solve_time_with_sensitivities'])} / "
                         f"{seconds(run['solve_time_with_sensitivities_median'])}", ""])
    timings = optimize["timings"]
    rows.append([f"`aquarom optimize so1` at the default, empty cache: optimisation ({optimize['prom_builds']} PROM "
                 "builds) / FOM check", f"{seconds(timings['total'])} / {seconds(timings['fom_check'])}", ""])
    notes = sources_note([("bench/fom.json", fom), ("bench/prom.json", prom), ("optimize/so1/summary.json", optimize)])
    return table(["run", "serial", "`mpirun -n 2`"], rows) + "\n" + notes


def _active(bounds: list[str]) -> str:
    """'lower: z_tail; upper: z_head, y_thin' of ["z_tail = lower", ...]."""
    sides = {}
    for row in bounds:
        name, _, side = row.partition(" = ")
        sides.setdefault(side or "constraint", []).append(name if side else row)
    return "; ".join(f"{side}: {', '.join(names)}" for side, names in sorted(sides.items())) or "none"


def _stop(summary: dict) -> str:
    reason = "optimality" if summary["converged"] else summary["stop_reason"].split(" (")[0].split(":")[0]
    return f"{reason} ({summary['iterations']})"


def _builds(summary: dict) -> str:
    return f"{summary['prom_builds']} ({summary.get('prom_builds_reused_from_cache', 0)})"


def _fom_check_time(summary: dict) -> str:
    value = summary["timings"].get("fom_check")
    return "cached" if value is None else f"{value:.1f}"


STUDY_CASES = ("so1", "so2", "so3", "so7", "so8", "so9")
"""The shape studies on the default mesh that the studies page shows."""

STUDY_METHODS = {"paper": "", "trust-region": "-trust-region"}
"""Each optimiser's suffix of a case's folder under studies/ (``scripts/study.py --methods``)."""


def study_summaries(case: str, folder: Path = SNAPSHOT) -> list[tuple[str, str, dict]]:
    """(method, snapshot path, summary) of a case: the paper method's is required, the trust
    region's shown when measured."""
    found = []
    for method, suffix in STUDY_METHODS.items():
        relative = f"studies/{case}{suffix}/summary.json"
        if method == "paper" or (folder / relative).is_file():
            found.append((method, relative, load(relative, folder)))
    return found


def study_table(folder: Path = SNAPSHOT) -> str:
    """SO1–SO3 and SO7–SO9 of ``scripts/study.py``: one row per case and optimiser from its summary.json."""
    rows, notes = [], []
    for case in STUDY_CASES:
        for method, relative, summary in study_summaries(case, folder):
            check = summary["fom_check"]
            optimum = ", ".join(f"{name} {value:+.3f}" for name, value in sorted(summary["optimum"].items()))
            prom = summary["prom_distance_optimal"]
            error = None if check["optimal_distance"] is None else prom / check["optimal_distance"] - 1.0
            multistart = summary.get("multistart")
            starts = "1" if multistart is None else (f"{multistart['starts']} (best {multistart['best_start']}; "
                                                     f"{len(multistart['distinct_optima'])} distinct optima)")
            rows.append([case.upper(), method, optimum, _active(summary["bounds_active"]), _stop(summary), starts,
                         _builds(summary), f"{summary['timings']['total']:.1f}", _fom_check_time(summary),
                         f"{cm(check['start_distance'])} → {cm(check['optimal_distance'])}",
                         f"{cm(prom)} ({percent(error)})", "n/a" if check["ratio"] is None else f"{check['ratio']:.2f}"])
            notes.append((relative, summary))
    header = ["case", "method", "optimum", "active bounds", "stop (iterations)", "starts", "PROM builds (from the cache)",
              "optimisation [s]", "FOM check [s]", "FOM start → optimal [cm]", "PROM optimal [cm] (error)", "ratio"]
    return table(header, rows) + "\n" + sources_note(notes)


def co_table(folder: Path = SNAPSHOT) -> str:
    """The CO Pareto sweep of ``scripts/study.py --cases co``: one row per optimiser and weight w1 (the
    trust region's when measured)."""
    rows, notes = [], []
    for method, suffix in STUDY_METHODS.items():
        paths = sorted(folder.glob(f"studies/co{suffix}/w1_*/summary.json"), key=lambda p: float(p.parent.name[3:]))
        if not paths and method == "paper":
            raise SnapshotError("docs/data/studies/co/w1_*/summary.json are missing: run `scripts/study.py --cases co` "
                                "and `python docs/generate.py --snapshot`")
        for path in paths:
            summary = json.loads(path.read_text())
            check = summary["fom_check"]
            optimum = dict(summary["optimum"])
            amplitude = optimum.pop("amplitude", None)
            shape = ", ".join(f"{name} {value:+.3f}" for name, value in sorted(optimum.items())) or "not recorded"
            timings = summary["timings"]
            rows.append([method, path.parent.name[3:], "n/a" if amplitude is None else f"{amplitude:.3f}", shape,
                         _stop(summary), _builds(summary),
                         f"{timings['total']:.0f} ({timings.get('tail_screens', 0):.0f})", _fom_check_time(summary),
                         f"{cm(check['optimal_distance'])} ({cm(summary['prom_distance_optimal'])})",
                         "n/a" if check["ratio"] is None else f"{check['ratio']:.2f}"])
            notes.append((f"studies/co{suffix}/w1_*/summary.json", summary))
    header = ["method", "w1", "A", "shape at the optimum", "stop (iterations)", "PROM builds (from the cache)",
              "optimisation [s] (of it the tail screens)", "FOM check [s]", "FOM optimal (PROM) [cm]", "ratio"]
    return table(header, rows) + "\n" + sources_note(notes)


def _reduced_error(entry: dict | None) -> str:
    """'distance error (tail amplitude error)' of a reduced run, or why it stopped."""
    if entry is None:
        return ""
    if not entry.get("completed"):
        return "stopped"
    return f"{percent(entry['distance_relative'])} ({percent(entry['tail_amplitude_relative'])})"


def stroke_table(folder: Path = SNAPSHOT) -> str:
    """ROM and PROM errors over the CO amplitudes at the nominal shape and the CO corner, without and with
    the stroke vectors (``scripts/stroke_accuracy.py``)."""
    data = load("validation/stroke_accuracy.json", folder)
    bases = [basis for basis in ("without", "stroke") if basis in data["bases"]]
    rows = []
    for row in data["rows"]:
        if not row["fom_completed"]:
            rows.append([row["shape"], f"{row['amplitude']:g}", "stopped"] + [""] * (2 * len(bases)))
            continue
        cells = [row["shape"], f"{row['amplitude']:g}", f"{cm(row['fom_distance'])} ({cm(row['fom_tail_amplitude'])})"]
        for basis in bases:
            cells += [_reduced_error(row[basis]["rom"]), _reduced_error(row[basis]["prom"])]
        rows.append(cells)
    names = {"without": "without the stroke vectors", "stroke": "with them"}
    header = ["shape", "A", "FOM distance (tail amplitude) [cm]"]
    for basis in bases:
        header += [f"ROM {names[basis]}", f"PROM {names[basis]}"]
    sizes = {basis: sorted({row[basis]["prom_size"] for row in data["rows"] if basis in row}) for basis in bases}
    stroke = data["bases"].get("stroke", {}).get("stroke_amplitude")
    note = (f"Errors of the distance (of the tail amplitude) against the FOM; PROM sizes m = "
            + ", ".join(f"{'/'.join(map(str, sizes[basis]))} {names[basis]}" for basis in bases)
            + (f", stroke_amplitude = {stroke:g}" if stroke else "") + ". "
            + f"`{command_of('validation/stroke_accuracy.json')}`. "
            + sources_note([("validation/stroke_accuracy.json", data)]))
    return table(header, rows) + "\n" + note


def _strain(run: dict) -> str:
    """'ε_max % (region, t s)' of a run of ``validation/material_law.json``."""
    if run.get("max_principal_strain") is None:
        return "n/a"
    return f"{100 * run['max_principal_strain']:.1f} % ({run['strain_region']}, {run['strain_time']:.2f} s)"


def _law_run(run: dict) -> str:
    if not run.get("completed"):
        return "stopped"
    return f"{cm(run['distance'])} ({cm(run['tail_amplitude'])})"


def _reduced_law_error(run: dict | None) -> str:
    """'error (tail amplitude error)' of a reduced model against the FOM of its law."""
    if not run:
        return "n/a"
    if "size" not in run:
        return "build failed"
    if run.get("distance_error") is None:
        return "stopped"
    return f"{percent(run['distance_error'])} ({percent(run['tail_amplitude_error'])})"


def material_table(folder: Path = SNAPSHOT) -> str:
    """SVK against Neo-Hookean on the FOM with the largest principal strains, and the reduced model's error
    on each law (``scripts/validate_material_law.py``)."""
    data = load("validation/material_law.json", folder)
    rows = []
    for case in data["cases"]:
        svk, neo = case["svk"], case["neo-hookean"]
        model = case.get("neo-hookean_reduced", {}).get("model", "")
        rows.append([case["case"], _law_run(svk), _strain(svk), _law_run(neo), _strain(neo),
                     f"{percent(case['distance_difference'])} ({percent(case['tail_amplitude_difference'])})",
                     model.upper(), _reduced_law_error(case.get("svk_reduced")),
                     _reduced_law_error(case.get("neo-hookean_reduced"))])
    header = ["design", "SVK distance (tail amplitude) [cm]", "SVK ε_max (where, when)",
              "Neo-Hookean distance (tail amplitude) [cm]", "Neo-Hookean ε_max (where, when)",
              "Neo-Hookean − SVK", "reduced model", "its error on SVK", "its error on Neo-Hookean"]
    note = (f"ε_max: the largest principal Green–Lagrange strain (limit {100 * data['strain_limit']:g} %); the "
            "reduced models' errors are against the FOM of the same law. "
            f"`{command_of('validation/material_law.json')}`. " + sources_note([("validation/material_law.json", data)]))
    return table(header, rows) + "\n" + note


def calibration_table(folder: Path = SNAPSHOT) -> str:
    """`aquarom calibrate`'s fit of synthetic FOM swims (``scripts/validate.py --only calibration``): per case and
    parameter the error against the truth and the 95 % interval's half-width; the interval's coverage."""
    data = load("validation/calibration.json", folder)
    targets = data["targets"]
    rows = []
    for name, case in data["cases"].items():
        for key, entry in case["parameters"].items():
            ok = abs(entry["error"]) <= targets["error"] and entry["half_width"] <= targets["half_width"]
            rows.append([name, key, f"{entry['truth']:.4g}", f"{entry['value']:.4g}", percent(entry["error"]),
                         f"±{100 * entry['half_width']:.2f} %", "pass" if ok else "**fail**"])
    notes = []
    for name, case in data["cases"].items():
        coverage = case.get("coverage")
        if coverage:
            notes.append(f"The truth inside the 95 % interval over {coverage['draws']} noise draws of case ({name}): "
                         + ", ".join(f"{key} {count} times" for key, count in coverage["covered"].items())
                         + f" (target: at least {targets['coverage']}).")
    note = (f"The {data['scene']} scene (degree {data['mesh']['degree']}, level {data['mesh']['level']}), "
            f"{data['duration']:g} s swims of the FOM at the truth, head x, tail y and centre-of-mass x sampled at "
            f"{data['frame_rate_hz']:g} Hz (time step {data['time_step']:g} s: most frames fall between its steps; "
            f"the FOM sampled there as the fit samples it, by cubic Hermite interpolation) with independent noise "
            f"σ = {1e3 * data['noise_m']:g} mm on every frame, fitted from the scene's values. Real tracking noise is "
            "correlated between frames: intervals from real data at a high frame rate are optimistic. "
            f"Targets: within {100 * targets['error']:g} % of the truth, the 95 % interval within "
            f"±{100 * targets['half_width']:g} %. " + " ".join(notes) + " "
            + f"`{command_of('validation/calibration.json')}`. " + sources_note([("validation/calibration.json", data)]))
    return table(["case", "parameter", "truth", "fitted", "error", "95 % half-width", "targets"], rows) + "\n" + note


def shape_order(scene: str, values: dict) -> list[str]:
    """The names of ``values`` in the order of the shipped scene's [shapes] (as the commands print them)."""
    from aquarom_fenics.io.scene import Scene

    order = [name for name in Scene.load(scene).shape_names if name in values]
    return order + [name for name in values if name not in order]


def walkthrough_table(folder: Path = SNAPSHOT) -> str:
    """What the README's walkthrough prints, from the files its commands wrote (SO1, level 1)."""
    fom = load("so1-fom/summary.json", folder)
    compare = load("so1-compare/compare.json", folder)
    prom = load("so1-compare/prom/summary.json", folder)
    optimum = load("so1-opt/summary.json", folder)
    design = ", ".join(f"{name} = {value:g}" for name, value in compare["design"].items() if value)
    dropped = f"; left out: {', '.join(prom['basis_dropped'])} …" if prom.get("basis_dropped") else ""
    errors = compare["errors"]
    check = optimum["fom_check"]
    rows = [
        ["`mesh`", f"{fom['cells']} cells ({fom['dofs']} degrees of freedom), then the head, muscles, skin and spine "
                   "with their cells and nodes"],
        ["`simulate`", f"`distance {cm(fom['distance'])} cm, tail amplitude {cm(fom['tail_amplitude'])} cm` "
                       f"({fom['steps']} steps)"],
        ["`build`", f"`m = {prom['reduced_size']} ({', '.join(prom['basis'])}), p = {len(prom['xi'])}{dropped}`"],
        ["`compare`", f"`distance FOM {cm(compare['fom']['distance'])} cm, PROM {cm(compare['prom']['distance'])} cm "
                      f"({percent(errors['distance_relative'])}); tail amplitude "
                      f"{percent(errors['tail_amplitude_relative'])}` at {design or 'the start design'}"],
        ["`optimize`", "optimum `" + ", ".join(f"{name} = {optimum['optimum'][name]:.4g}"
                                               for name in shape_order(optimum["scene"], optimum["optimum"]))
                       + f"`, {optimum['prom_builds']} PROM builds; `FOM check: start {cm(check['start_distance'])} cm, "
                       f"optimal {cm(check['optimal_distance'])} cm (PROM {cm(check['prom_optimal_distance'])} cm), "
                       f"ratio {check['ratio']:.2f}`"]]
    notes = sources_note([("so1-fom/summary.json", fom), ("so1-compare/compare.json", compare),
                          ("so1-compare/prom/summary.json", prom), ("so1-opt/summary.json", optimum)])
    return table(["step", "prints"], rows) + "\n" + notes


TABLES = {"walkthrough": walkthrough_table, "accuracy": accuracy_table, "costs": cost_table, "mesh-convergence": mesh_table,
          "station-convergence": stations_table, "studies": study_table, "studies-co": co_table,
          "stroke-accuracy": stroke_table, "material-law": material_table, "calibration": calibration_table}


# ---------------------------------------------------------------- the pages

def render_page(text: str, folder: Path = SNAPSHOT) -> str:
    """``text`` with every measured block rewritten from the snapshot."""
    def block(match) -> str:
        name = match.group("name")
        if name not in TABLES:
            raise SnapshotError(f"unknown measured table {name!r}; known: {', '.join(TABLES)}")
        return match.group(1) + TABLES[name](folder) + match.group(4)

    return MARKER.sub(block, text)


def measured_blocks(text: str) -> dict[str, str]:
    """Name → body of every measured block of a page."""
    return {match.group("name"): match.group("body") for match in MARKER.finditer(text)}


FIGURE = re.compile(r"(?<![\w.])[-+−]?\d+(?:\.\d+)?(?![\w.])")


def figures(text: str) -> list[str]:
    """The numbers a text quotes, as written ('−' read as '-')."""
    return [figure.replace("−", "-") for figure in FIGURE.findall(text)]


def unsupported_figures(page_text: str, folder: Path = SNAPSHOT) -> dict[str, list[str]]:
    """Per measured block of a page: the figures it quotes that the snapshot's table does not hold
    (one entry per quote beyond the table's own count)."""
    problems = {}
    for name, body in measured_blocks(page_text).items():
        expected = figures(TABLES[name](folder))
        extra = []
        for figure in figures(body):
            if figure in expected:
                expected.remove(figure)
            else:
                extra.append(figure)
        if extra:
            problems[name] = extra
    return problems


def write_pages(repository: Path = REPOSITORY, folder: Path = SNAPSHOT) -> list[str]:
    """Rewrite the measured blocks of every page in PAGES; return the pages that changed."""
    changed = []
    for name in PAGES:
        path = repository / name
        text = path.read_text()
        new = render_page(text, folder)
        if new != text:
            path.write_text(new)
            changed.append(name)
    return changed
