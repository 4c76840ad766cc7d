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
    from aquarom_fenics.calibration.parameters import check_keys, scene_value
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
    from aquarom_fenics.calibration.fit import FitSettings, calibrate, refine_on_fom, statistics
    from aquarom_fenics.calibration.parameters import OBSERVED
    from aquarom_fenics.calibration.report import write_outputs

    data, (keys, start, bounds) = vars(args).pop("swim"), vars(args).pop("fit_plan")
    out = claim_output(args, args.out or Path("results") / "calibrate" / scene.name)
    settings = FitSettings(max_iterations=args.max_iterations)
    models = CalibrationModels(scene, run_design(scene, xi), data, keys, settings, not args.no_progress)
    columns = [OBSERVED.index(name) for name in data.observables]
    result = calibrate(data, columns, keys, start, bounds, models.build, settings, models.reporter(data, "PROM"))
    result = refine_on_fom(data, result, bounds, models.fom, models.prom_jacobian, report=models.reporter(data, "FOM"))
    stats = statistics(result)
    fom = models.fom_check(result.values)
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


class CalibrationModels:
    """The PROM (rebuilt when a parameter moved beyond the settings' fraction) and the FOM of a calibration."""

    def __init__(self, scene, design: dict, data, keys: list[str], settings, progress: bool):
        from aquarom_fenics.geometry.fish import load_fish

        self.scene, self.design, self.data, self.keys = scene, design, data, keys
        self.settings, self.progress = settings, progress
        self.fish = load_fish(scene)
        self.prom = self.built = self.built_at = None
        self.last_fom = None

    def build(self, values: dict):
        """(PROM, scene it was built on) at ``values``."""
        from aquarom_fenics.calibration.parameters import with_values
        from aquarom_fenics.reduction.reductor import build_prom

        self.built = with_values(self.scene, values)
        self.prom = build_prom(self.built, xi_center=self.design, fish=self.fish, parametric=False)
        self.built_at = np.array(list(values.values()), dtype=float)
        return self.prom, self.built

    def prom_run(self, theta: np.ndarray):
        """The PROM's observed points (n, k) and Jacobian (n k, q) at the data's times, at θ."""
        from aquarom_fenics.calibration.fit import sample_at
        from aquarom_fenics.calibration.parameters import OBSERVED, simulate_parameters

        if np.any(np.abs(theta - self.built_at) > self.settings.rebuild_fraction * np.abs(self.built_at)):
            self.build(dict(zip(self.keys, theta)))
        swim = simulate_parameters(self.prom, self.built, dict(zip(self.keys, theta)))
        model, derivative = sample_at(swim, self.data.time, [OBSERVED.index(name) for name in self.data.observables])
        return model, derivative.reshape(-1, len(self.keys))

    def prom_jacobian(self, theta: np.ndarray) -> np.ndarray:
        return self.prom_run(theta)[1]

    def fom(self, theta: np.ndarray) -> np.ndarray:
        """The FOM's observed points at the data's times at θ (kept for the check of the last point)."""
        from aquarom_fenics.calibration.parameters import with_values
        from aquarom_fenics.calibration.report import fom_model

        run, model = fom_model(with_values(self.scene, dict(zip(self.keys, theta))), self.design, self.fish,
                               self.data, self.progress)
        self.last_fom = (theta.copy(), run, model)
        return model

    def fom_check(self, theta: np.ndarray) -> dict:
        """The FOM record at θ (its last run there, or a new one) with the PROM's distance from it."""
        from aquarom_fenics.calibration.report import fom_record

        if self.last_fom is None or not np.array_equal(self.last_fom[0], theta):
            self.fom(theta)
        _, run, model = self.last_fom
        return fom_record(run, model, self.prom_run(theta)[0], self.data)

    def reporter(self, data, model: str):
        """One line per iteration: the model, the residual RMS and θ."""
        def report(iteration: int, cost: float, values: np.ndarray):
            shown_values = ", ".join(f"{key.split('.')[1]} {value:.6g}" for key, value in zip(self.keys, values))
            say(f"{model} iteration {iteration}: residual RMS {1e3 * np.sqrt(2 * cost / data.values.size):.4f} mm; "
                f"{shown_values}")
        return report
