"""What a calibration writes: calibration.json, fit.png and calibrated.toml, and the FOM run at the fitted
values that checks it (its residual against the data and its distance from the fitted PROM)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.calibration.parameters import with_values
from aquarom_fenics.io.persistence import write_json_atomic, write_text_atomic


def residual_rms(residual: np.ndarray, observables) -> dict[str, float]:
    """RMS [m] of the residual (n, k) per tracked point and overall."""
    per_point = {name: float(np.sqrt(np.mean(residual[:, j] ** 2))) for j, name in enumerate(observables)}
    return per_point | {"overall": float(np.sqrt(np.mean(residual ** 2)))}


def fom_model(scene, design: dict, fish, data, progress: bool = True, offset: float = 0.0):
    """The FOM run at ``scene``'s values and its observed points at the data's times shifted by the time
    offset [s] (at rest before t = 0), (n, k) [m], by cubic Hermite interpolation of its positions and
    velocities (``fit.sample_trajectory``, as the reduced model); raises SolverError when it stops."""
    from aquarom_fenics.calibration.fit import sample_trajectory
    from aquarom_fenics.dynamics.simulate import simulate_fom
    from aquarom_fenics.errors import SolverError

    run = simulate_fom(scene, xi=design, fish=fish, progress=progress)
    if not run.completed:
        raise SolverError(f"the FOM at the fitted values stopped: {run.error}")
    return run, sample_trajectory(run.trajectory, data.time + offset, data.observables)


def fom_record(run, fom: np.ndarray, prom: np.ndarray, data) -> dict:
    """The FOM at the reported values: its residual RMS against the data and its distance from the PROM
    there (max |y_FOM - y_PROM| over each point's range in the FOM)."""
    spread = np.maximum(np.ptp(fom, axis=0), 1e-300)
    distance = np.abs(fom - prom).max(axis=0) / spread
    return {"completed": True, "residual_rms": residual_rms(fom - data.values, data.observables),
            "prom_distance": {name: float(value) for name, value in zip(data.observables, distance)},
            "swimming_distance": run.distance, "wall_time": run.wall_time, "model": fom, "prom": prom}


def calibration_record(scene, data_path, data, result, stats, fom: dict, settings) -> dict:
    """The content of calibration.json."""
    keys = result.keys
    checked = {key: value for key, value in fom.items() if key not in ("model", "prom")}
    return {
        "scene": scene.source, "scene_hash": scene.hash, "data": str(data_path), "rows": int(data.time.size),
        "columns": list(data.columns), "converged": bool(result.converged), "iterations": result.iterations,
        "prom_rebuilds": result.rebuilds, "rebuild_fraction": settings.rebuild_fraction,
        "step_tolerance": settings.step_tolerance,
        "parameters": {key: {"value": float(value), "start": float(start), "std": float(std),
                             "ci95": [float(low), float(high)]}
                       for key, value, start, std, (low, high)
                       in zip(keys, result.values, result.start, stats.std, stats.ci95)},
        "correlation": {"keys": keys, "matrix": stats.correlation.tolist()},
        "information_condition": stats.condition,
        "not_identifiable": stats.unidentifiable,
        "noise_estimate_m": stats.noise,
        "residual_rms_m": residual_rms(result.residual, data.observables),
        "fom": checked,
        "history": result.history,
    }


def plot_fit(path: Path, data, result, fom: dict) -> None:
    """Data (dots) and the fitted PROM and FOM (lines) against time, one panel per tracked point [mm]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = len(data.observables)
    figure, axes = plt.subplots(k, 1, figsize=(7, 2.4 * k + 0.6), sharex=True, squeeze=False)
    for j, (axis, name) in enumerate(zip(axes[:, 0], data.observables)):
        axis.plot(data.time, 1e3 * data.values[:, j], ".", markersize=3, color="black", label="data")
        axis.plot(data.time, 1e3 * fom["model"][:, j], "-", label="FOM at the fitted values")
        axis.plot(data.time, 1e3 * fom["prom"][:, j], "--", label="PROM at the fitted values")
        axis.set_ylabel(f"{name.replace('_', ' ')} [mm]")
        axis.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(", ".join(f"{key.rpartition('.')[2]} = {value:.4g}" for key, value in zip(result.keys, result.values)))
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def write_outputs(out: Path, scene, data_path, data, result, stats, fom: dict, settings) -> None:
    """calibration.json, fit.png and calibrated.toml in ``out``."""
    write_json_atomic(out / "calibration.json", calibration_record(scene, data_path, data, result, stats, fom, settings))
    plot_fit(out / "fit.png", data, result, fom)
    fitted = with_values(scene, dict(zip(result.keys, result.values)))
    write_text_atomic(out / "calibrated.toml", fitted.to_toml())


__all__ = ["calibration_record", "fom_model", "fom_record", "plot_fit", "residual_rms", "write_outputs"]
