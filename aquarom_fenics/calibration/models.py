"""The models of one calibration: the PROM at θ (rebuilt when a parameter has moved beyond the settings'
fraction of its value since the last build) with its Jacobian at the data's times, and the FOM at θ."""
from __future__ import annotations

import numpy as np


class CalibrationModels:
    """The PROM (rebuilt when a parameter moved beyond the settings' fraction) and the FOM of a calibration."""

    def __init__(self, scene, design: dict, data, keys: list[str], settings, progress: bool, fish=None):
        from aquarom_fenics.geometry.fish import load_fish

        self.scene, self.design, self.data, self.keys = scene, design, data, keys
        self.settings, self.progress = settings, progress
        self.fish = fish or load_fish(scene)
        self.prom = self.built = self.built_at = None
        self.last_fom = None

    def build(self, values: dict):
        """(PROM, scene it was built on) at ``values``."""
        from aquarom_fenics.calibration.parameters import with_values
        from aquarom_fenics.reduction.reductor import build_prom

        self.built = with_values(self.scene, values)
        self.prom = build_prom(self.built, xi_center=self.design, fish=self.fish, parametric=False,
                               head_share="material.head_stiffness_factor" in self.keys)
        self.built_at = np.array(list(values.values()), dtype=float)
        return self.prom, self.built

    def prom_run(self, theta: np.ndarray):
        """The PROM's observed points (n, k) and Jacobian (n k, q) at the data's times, at θ."""
        from aquarom_fenics.calibration.fit import model_at, moved_beyond
        from aquarom_fenics.dynamics.trajectory import OBSERVED

        if moved_beyond(self.keys, theta, self.built_at, self.settings.rebuild_fraction):
            self.build(dict(zip(self.keys, theta)))
        columns = [OBSERVED.index(name) for name in self.data.observables]
        return model_at(self.prom, self.built, self.data, columns, self.keys, theta)

    def prom_jacobian(self, theta: np.ndarray) -> np.ndarray:
        return self.prom_run(theta)[1]

    def fom(self, theta: np.ndarray) -> np.ndarray:
        """The FOM's observed points at the data's times at θ (kept for the check of the last point)."""
        from aquarom_fenics.calibration.parameters import TIME_OFFSET, with_values
        from aquarom_fenics.calibration.report import fom_model

        point = dict(zip(self.keys, theta))
        run, model = fom_model(with_values(self.scene, point), self.design, self.fish, self.data, self.progress,
                               offset=point.get(TIME_OFFSET, 0.0))
        self.last_fom = (theta.copy(), run, model)
        return model

    def fom_check(self, theta: np.ndarray) -> dict:
        """The FOM record at θ (its last run there, or a new one) with the PROM's distance from it."""
        from aquarom_fenics.calibration.report import fom_record

        if self.last_fom is None or not np.array_equal(self.last_fom[0], theta):
            self.fom(theta)
        _, run, model = self.last_fom
        return fom_record(run, model, self.prom_run(theta)[0], self.data)


def fit_swim(models: CalibrationModels, start: np.ndarray, bounds: np.ndarray, report_prom=None, report_fom=None,
             fom_iterations: int = 6):
    """The whole fit of ``models.data``: Levenberg–Marquardt on the PROM, the last iterations on the FOM,
    the statistics at the FOM's point and the FOM's check there; (FitResult, Statistics, FOM record)."""
    from aquarom_fenics.calibration.fit import calibrate, refine_on_fom, statistics
    from aquarom_fenics.dynamics.trajectory import OBSERVED

    data, keys = models.data, models.keys
    columns = [OBSERVED.index(name) for name in data.observables]
    result = calibrate(data, columns, keys, start, bounds, models.build, models.settings, report_prom)
    result = refine_on_fom(data, result, bounds, models.fom, models.prom_jacobian, fom_iterations, report=report_fom)
    return result, statistics(result), models.fom_check(result.values)
