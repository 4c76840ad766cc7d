"""Study ``calibration`` (issue 52): `aquarom calibrate`'s fit on synthetic swims of the FOM.

The nominal fish (its shipped mesh) swims 2 s at parameter values away from the scene's; its head x,
tail y and centre-of-mass x, filmed at 240 Hz (frames at k/240 s: one in 24 falls on the 0.02 s time
grid, the others between its steps) with independent Gaussian noise of σ = 0.3 mm per frame and point,
are fitted from the scene's values. The FOM is sampled at the frames as the fit samples its models: cubic
Hermite interpolation of the positions and velocities on the time grid (``fit.sample_trajectory``).
Per case and parameter: the fitted value's error against the truth and the half-width of its 95 %
interval, both relative to the truth (the issue's targets: within 3 % and ±5 %); for one case, how often
the interval holds the truth over 20 draws of the noise (target: at least 18).

The protocol (one for every case) was chosen from the information matrix of the reduced model's
derivatives at the truth: the drag factor needs it (±23 % on 1 s at 50 Hz and 0.4 mm, about ±4 % here).
Real tracking noise is correlated between frames (the same blur, the same mis-placed marker over several
frames); the independent noise assumed here makes the intervals of real data at high frame rates optimistic.
"""
from __future__ import annotations

import time

import numpy as np

CASES = {
    "E, k": {"material.young_modulus": 1.2, "actuation.stiffness": 0.85},
    "E, rayleigh_alpha": {"material.young_modulus": 1.2, "material.rayleigh_alpha": 1.3},
    "k, drag_factor": {"actuation.stiffness": 0.85, "fluid.drag_factor": 1.4},
    "E, k, thrust_factor": {"material.young_modulus": 1.2, "actuation.stiffness": 0.85, "fluid.thrust_factor": 0.8},
}
"""Each case's parameters and their truth as a multiple of the scene's value."""

COVERAGE_CASE = "E, k"
DRAWS = 20
SCENE = "nominal"
DURATION = 2.0                     # s
FRAME_RATE = 240.0                 # Hz
NOISE = 3e-4                       # m
OBSERVED = ("head_x", "tail_y", "com_x")
TARGET_ERROR, TARGET_HALF_WIDTH, TARGET_COVERAGE = 0.03, 0.05, 18


def frame_times(duration: float | None = None, rate: float | None = None) -> np.ndarray:
    """The camera's frames k / rate, k = 1 … duration · rate [s] (DURATION and FRAME_RATE by default)."""
    duration, rate = duration or DURATION, rate or FRAME_RATE
    return np.arange(1, int(round(duration * rate)) + 1) / rate


def synthetic_swim(run, rng, source: str):
    """The FOM ``run``'s head x, tail y, com x at the frames (``fit.sample_trajectory``, as the fit samples
    the FOM) with independent noise N(0, NOISE²), as a SwimData."""
    from aquarom_fenics.calibration.fit import sample_trajectory
    from aquarom_fenics.io.swim_data import SwimData

    times = frame_times()
    clean = sample_trajectory(run.trajectory, times, OBSERVED)
    return SwimData(times, clean + NOISE * rng.standard_normal(clean.shape), OBSERVED, source)


def fit_case(scene, fish, keys: list[str], truth: np.ndarray, run, rng, source: str, models=None):
    """One noisy draw of the truth's swim fitted from the scene's values; its record and the models."""
    from aquarom_fenics.calibration.fit import FitSettings
    from aquarom_fenics.calibration.models import CalibrationModels, fit_swim
    from aquarom_fenics.calibration.parameters import scene_value

    data = synthetic_swim(run, rng, source)
    if models is None:
        models = CalibrationModels(scene, {}, data, keys, FitSettings(), progress=False, fish=fish)
    models.data, models.last_fom = data, None
    start = np.array([scene_value(scene, key) for key in keys])
    bounds = np.column_stack([start / 10, start * 10])
    started = time.perf_counter()
    result, stats, fom = fit_swim(models, start, bounds)
    error = result.values / truth - 1
    half_width = (stats.ci95[:, 1] - stats.ci95[:, 0]) / 2 / truth
    covered = (stats.ci95[:, 0] <= truth) & (truth <= stats.ci95[:, 1])
    record = {
        "converged": bool(result.converged), "iterations": result.iterations, "prom_rebuilds": result.rebuilds,
        "wall_time": time.perf_counter() - started, "noise_estimate_m": stats.noise,
        "not_identifiable": stats.unidentifiable,
        "correlation": stats.correlation.tolist(),
        "fom_residual_rms_m": fom["residual_rms"]["overall"],
        "prom_distance": fom["prom_distance"],
        "parameters": {key: {"truth": float(t), "value": float(v), "error": float(e), "ci95": [float(lo), float(hi)],
                             "half_width": float(w), "covered": bool(c)}
                       for key, t, v, e, (lo, hi), w, c in zip(keys, truth, result.values, error, stats.ci95,
                                                               half_width, covered)},
    }
    return record, models


def study_calibration(runner, settings) -> dict:
    """Every case of :data:`CASES` once, the coverage case over :data:`DRAWS` noise draws."""
    from aquarom_fenics.calibration.parameters import scene_value, with_values
    from aquarom_fenics.dynamics.simulate import simulate_fom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.io.scene import Scene

    if getattr(runner, "collect", False):
        return {}                              # no cached cases: this study runs in the main process only
    scene = Scene.load(SCENE).replace("solver", duration=DURATION)
    fish = load_fish(scene)
    cases = {}
    for number, (name, factors) in enumerate(CASES.items()):
        keys = list(factors)
        truth = np.array([factors[key] * scene_value(scene, key) for key in keys])
        run = simulate_fom(with_values(scene, dict(zip(keys, truth))), fish=fish, progress=False)
        rng = np.random.default_rng(1000 + number)
        record, models = fit_case(scene, fish, keys, truth, run, rng, f"synthetic {name}")
        record["passes"] = all(abs(p["error"]) <= TARGET_ERROR and p["half_width"] <= TARGET_HALF_WIDTH
                               for p in record["parameters"].values())
        cases[name] = record
        print(f"calibration {name}: " + ", ".join(f"{key.split('.')[1]} {100 * p['error']:+.2f} % "
                                                   f"(±{100 * p['half_width']:.2f} %)"
                                                   for key, p in record["parameters"].items()), flush=True)
        if name == COVERAGE_CASE:
            draws = [fit_case(scene, fish, keys, truth, run, np.random.default_rng(2000 + draw), "draw", models)[0]
                     for draw in range(DRAWS)]
            coverage = {key: int(sum(d["parameters"][key]["covered"] for d in draws)) for key in keys}
            cases[name]["coverage"] = {"draws": DRAWS, "covered": coverage,
                                       "errors": {key: [d["parameters"][key]["error"] for d in draws] for key in keys},
                                       "half_widths": {key: [d["parameters"][key]["half_width"] for d in draws]
                                                       for key in keys},
                                       "passes": all(count >= TARGET_COVERAGE for count in coverage.values())}
            print(f"calibration {name}: the truth inside the 95 % interval in "
                  + ", ".join(f"{key.split('.')[1]} {count}/{DRAWS}" for key, count in coverage.items()), flush=True)
    return {"scene": SCENE, "mesh": {"level": scene.mesh.level, "degree": scene.mesh.degree}, "duration": DURATION,
            "frame_rate_hz": FRAME_RATE, "time_step": scene.solver.time_step, "noise_m": NOISE,
            "targets": {"error": TARGET_ERROR, "half_width": TARGET_HALF_WIDTH, "coverage": TARGET_COVERAGE},
            "cases": cases}


def section_calibration(lines, study) -> None:
    """The report's table: per case and parameter the fitted value's error, its 95 % half-width, pass/fail;
    the coverage of the interval over the noise draws."""
    from aquarom_fenics.verification.validation.report_format import not_run, percent, table

    title = "## Calibration on synthetic swims"
    if not study or not study.get("cases"):
        not_run(lines, title)
        return
    lines += [title, "",
              f"`aquarom calibrate`'s fit (Levenberg–Marquardt on the PROM, the last Gauss–Newton iterations on the "
              f"FOM) of FOM swims of the {study['scene']} scene (level {study['mesh']['level']}, degree "
              f"{study['mesh']['degree']}, {study['duration']:g} s) at parameters away from the scene's, head x, tail y "
              f"and centre-of-mass x sampled at {study['frame_rate_hz']:g} Hz (time step {study['time_step']:g} s; the FOM "
              f"sampled between its steps by cubic Hermite interpolation, as the fit samples it) with independent "
              f"Gaussian noise σ = {1e3 * study['noise_m']:g} mm, fitted from the scene's values (real tracking noise "
              f"is correlated between frames: intervals from real data at a high frame rate are optimistic). Targets: within "
              f"{100 * study['targets']['error']:g} % of the truth, a 95 % interval within ±"
              f"{100 * study['targets']['half_width']:g} %.", ""]
    rows = []
    for name, case in study["cases"].items():
        for key, entry in case["parameters"].items():
            ok = abs(entry["error"]) <= study["targets"]["error"] and entry["half_width"] <= study["targets"]["half_width"]
            rows.append([name, key, f"{entry['truth']:.4g}", f"{entry['value']:.4g}", percent(entry["error"]),
                         f"±{100 * entry['half_width']:.2f}%", "yes" if entry["covered"] else "no",
                         "pass" if ok else "**FAIL**"])
    lines += table(["case", "parameter", "truth", "fitted", "error", "95 % half-width", "truth inside", "verdict"], rows)
    lines += [""]
    for name, case in study["cases"].items():
        coverage = case.get("coverage")
        if coverage:
            lines += [f"Coverage, case ({name}), {coverage['draws']} noise draws: the truth inside the 95 % interval "
                      + ", ".join(f"{key} {count}/{coverage['draws']}" for key, count in coverage["covered"].items())
                      + f" (target ≥ {study['targets']['coverage']})."]
        if case.get("not_identifiable"):
            lines += [f"Case ({name}): not identifiable: {'; '.join(case['not_identifiable'])}."]
    lines += [""]
