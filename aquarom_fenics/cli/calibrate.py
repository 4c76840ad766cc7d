"""``aquarom calibrate``: fit scene parameters to a measured swim on the reduced model, check the result
with the FOM, and write calibration.json, fit.png and calibrated.toml (``calibration.fit``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.cli.inputs import check_time_runs, checked, load_scene, run_design, say
from aquarom_fenics.cli.outputs import claim_output, shown
from aquarom_fenics.errors import InputError, SolverError

DEFAULT_RANGE = 10.0
"""Without LO:HI a parameter is fitted within [θ_start / 10, 10 θ_start]."""


def parse_fit(items: list[str] | None, scene) -> tuple[list[str], np.ndarray, np.ndarray]:
    """--fit KEY[=LO:HI] … → (keys, start values, bounds (q, 2)), each refusal one line."""
    from aquarom_fenics.calibration.parameters import check_fit, check_keys, scene_value
    from aquarom_fenics.io.scene import parse_number

    if not items:
        raise InputError("--fit is required: a scene key to fit, e.g. --fit material.young_modulus "
                         "(repeatable; KEY=LO:HI bounds it)")
    keys, bounds = [], []
    for item in items:
        key, _, interval = item.partition("=")
        key = key.strip()
        if key == "time_offset":
            raise InputError("--fit time_offset: not supported yet; shift the data's time_s column to the model's "
                             "start (t = 0 when the muscles start)")
        keys.append(key)
        check_keys([key])
        start = scene_value(scene, key)
        if not start > 0:
            raise InputError(f"--fit {key}: its scene value is {start:g}; a fitted parameter starts from a value > 0")
        if interval:
            low_text, colon, high_text = interval.partition(":")
            if not colon:
                raise InputError(f"--fit {item}: bounds are LO:HI, e.g. {key}={start / 2:g}:{2 * start:g}")
            low, high = parse_number(low_text, f"--fit {key} LO"), parse_number(high_text, f"--fit {key} HI")
            if not 0 < low < high:
                raise InputError(f"--fit {item}: bounds must be 0 < LO < HI")
            if not low <= start <= high:
                raise InputError(f"--fit {item}: the scene's value {start:g} is outside [{low:g}, {high:g}]")
        else:
            low, high = start / DEFAULT_RANGE, start * DEFAULT_RANGE
        bounds.append((low, high))
    check_keys(keys)
    check_fit(keys, scene)
    return keys, np.array([scene_value(scene, key) for key in keys]), np.array(bounds, dtype=float)


def calibrate_inputs(args):
    """The scene, the fitted keys and bounds, the data checked against the scene, the time grid."""
    from aquarom_fenics.io.swim_data import read_swim

    scene = load_scene(args)
    keys, start, bounds = parse_fit(args.fit, scene)
    if args.data is None:
        raise InputError("--data is required: the measured swim, a CSV of time_s and head_x_m, tail_y_m, com_x_m")
    if args.max_iterations < 1:
        raise InputError(f"--max-iterations {args.max_iterations}: must be at least 1")
    check_time_runs(args, scene)
    length = scene.mesh.length
    if scene.mesh.file:
        from aquarom_fenics.geometry.fish import load_fish

        length = load_fish(scene).tags.box.length
    args.swim = read_swim(args.data, scene.solver.duration, len(keys), length)
    args.fit_plan = (keys, start, bounds)
    return scene, {}


@checked(calibrate_inputs)
def run_calibrate(args, scene, xi) -> int:
    from aquarom_fenics.calibration.fit import FitSettings
    from aquarom_fenics.calibration.models import CalibrationModels, fit_swim
    from aquarom_fenics.calibration.report import write_outputs

    data, (keys, start, bounds) = vars(args).pop("swim"), vars(args).pop("fit_plan")
    out = claim_output(args, args.out or Path("results") / "calibrate" / scene.name)
    settings = FitSettings(max_iterations=args.max_iterations)
    models = CalibrationModels(scene, run_design(scene, xi), data, keys, settings, not args.no_progress)
    result, stats, fom = fit_swim(models, start, bounds, reporter(keys, data, "PROM"), reporter(keys, data, "FOM"))
    write_outputs(out, scene, args.data, data, result, stats, fom, settings)
    for key, value, (low, high) in zip(keys, result.values, stats.ci95):
        say(f"{key} = {value:.6g}, 95 % interval [{low:.6g}, {high:.6g}]")
    if stats.unidentifiable:
        say("warning: the data cannot tell apart: " + "; ".join(stats.unidentifiable))
    say(f"FOM at the fitted values: residual RMS {1e3 * fom['residual_rms']['overall']:.4f} mm; the PROM there "
        f"within {100 * max(fom['prom_distance'].values()):.2f} % of the FOM (of each point's range)")
    say(f"outputs in {shown(args, out)}/ (calibration.json, fit.png, calibrated.toml)")
    if not result.converged:
        raise SolverError(f"the fit did not converge in {result.iterations} iterations; its best point is in "
                          f"{out / 'calibration.json'} (converged: false)")
    return 0


def reporter(keys: list[str], data, model: str):
    """One line per iteration: the model, the residual RMS and θ."""
    def report(iteration: int, cost: float, values: np.ndarray):
        shown_values = ", ".join(f"{key.split('.')[1]} {value:.6g}" for key, value in zip(keys, values))
        say(f"{model} iteration {iteration}: residual RMS {1e3 * np.sqrt(2 * cost / data.values.size):.4f} mm; "
            f"{shown_values}")
    return report
