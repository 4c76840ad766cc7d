"""``aquarom calibrate``: fit scene parameters to a measured swim on the reduced model, check the result
with the FOM, and write calibration.json, fit.png and calibrated.toml (``calibration.fit``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.cli.inputs import check_time_runs, checked, load_scene, run_design, say
from aquarom_fenics.cli.outputs import claim_output, shown
from aquarom_fenics.errors import InputError, SolverError

FOM_ITERATIONS = 6
"""The fit's iterations on the FOM at most (``calibration.fit.refine_on_fom``)."""

DEFAULT_RANGE = 10.0
"""Without LO:HI a parameter is fitted within [θ_start / 10, 10 θ_start]."""
OFFSET_PERIODS = 0.25
"""Without LO:HI the time offset is fitted within ± this many actuation periods (a larger shift is ambiguous by
a whole stroke), and no later than the data's last time allows within the scene's duration."""


def parse_fit(items: list[str] | None, scene) -> tuple[list[str], np.ndarray, np.ndarray]:
    """--fit KEY[=LO:HI] … → (keys, start values, bounds (q, 2)), each refusal one line."""
    from aquarom_fenics.calibration.parameters import TIME_OFFSET, check_fit, check_keys, scene_value
    from aquarom_fenics.io.command_values import parse_number

    if not items:
        raise InputError("--fit is required: a scene key to fit, e.g. --fit material.young_modulus "
                         "(repeatable; KEY=LO:HI bounds it)")
    keys, bounds = [], []
    for item in items:
        key, _, interval = item.partition("=")
        key = key.strip()
        keys.append(key)
        check_keys([key])
        if key == TIME_OFFSET:
            bounds.append(offset_bounds(item, interval, scene))
            continue
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


def offset_bounds(item: str, interval: str, scene) -> tuple[float, float]:
    """--fit time_offset[=LO:HI] → (LO, HI) [s], LO ≤ 0 ≤ HI (the fit starts at 0); default ± a quarter period."""
    from aquarom_fenics.io.command_values import parse_number

    if not interval:
        half = OFFSET_PERIODS / scene.actuation.frequency
        return -half, half
    low_text, colon, high_text = interval.partition(":")
    if not colon:
        raise InputError(f"--fit {item}: bounds are LO:HI in seconds, e.g. time_offset=-0.05:0.05")
    low, high = parse_number(low_text, "--fit time_offset LO"), parse_number(high_text, "--fit time_offset HI")
    if not low <= 0 <= high or not low < high:
        raise InputError(f"--fit {item}: bounds must be LO ≤ 0 ≤ HI with LO < HI (the fit starts at no offset)")
    return low, high


def cap_offset(keys: list[str], bounds: np.ndarray, data, duration: float) -> None:
    """The time offset's upper bound at the scene's duration less the data's last time: the model is sampled
    at t + τ and ends at the duration (one line when nothing positive or negative is left to fit)."""
    from aquarom_fenics.calibration.parameters import TIME_OFFSET

    if TIME_OFFSET not in keys:
        return
    row = keys.index(TIME_OFFSET)
    bounds[row, 1] = min(bounds[row, 1], duration - data.time[-1])
    if not bounds[row, 0] < bounds[row, 1]:
        raise InputError(f"--fit time_offset: the data end at {data.time[-1]:g} s, the scene's duration is {duration:g} s "
                         "and the offset's lower bound is 0: no shift left to fit; lengthen [solver] duration")


def calibrate_inputs(args):
    """The scene, the fitted keys and bounds, the data checked against the scene, the time grid."""
    from aquarom_fenics.io.swim_data import read_swim

    scene = load_scene(args)
    keys, start, bounds = parse_fit(args.fit, scene)
    if args.data is None:
        raise InputError("--data is required: the measured swim, a CSV of time_s and any of head_x_m, tail_y_m, "
                         "com_x_m, tail_x_m, com_y_m")
    if args.max_iterations < 1:
        raise InputError(f"--max-iterations {args.max_iterations}: must be at least 1")
    check_time_runs(args, scene)
    length = scene.mesh.length
    if scene.mesh.file:
        from aquarom_fenics.geometry.fish import load_fish

        length = load_fish(scene).tags.box.length
    args.swim = read_swim(args.data, scene.solver.duration, len(keys), length)
    cap_offset(keys, bounds, args.swim, scene.solver.duration)
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
    prom_report = IterationReport(keys, data, "PROM", settings.max_iterations, not args.no_progress)
    fom_report = IterationReport(keys, data, "FOM", FOM_ITERATIONS, not args.no_progress)
    try:
        result, stats, fom = fit_swim(models, start, bounds, prom_report, fom_report, FOM_ITERATIONS)
    finally:
        prom_report.close()
        fom_report.close()
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


class IterationReport:
    """One line per iteration (the model, the residual RMS and θ) and a progress bar of the iterations (at most
    ``total``) on a terminal, unless ``shown`` is False (--no-progress)."""

    def __init__(self, keys: list[str], data, model: str, total: int, shown: bool):
        from aquarom_fenics.dynamics.simulate import progress_bar

        self.keys, self.data, self.model = keys, data, model
        self.bar = progress_bar(total, f"fit ({model})", shown, unit="iteration")

    def __call__(self, iteration: int, cost: float, values: np.ndarray) -> None:
        rms = 1e3 * np.sqrt(2 * cost / self.data.values.size)
        shown_values = ", ".join(f"{key.rpartition('.')[2]} {value:.6g}" for key, value in zip(self.keys, values))
        say(f"{self.model} iteration {iteration}: residual RMS {rms:.4f} mm; {shown_values}")
        if self.bar is not None:
            self.bar.set_postfix_str(f"RMS {rms:.4f} mm", refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
