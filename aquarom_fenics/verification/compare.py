"""FOM against reduced model at one design: errors of distance, tail amplitude and trajectories."""
from __future__ import annotations

import numpy as np

ERROR_SIGNALS = ("head_x", "tail_y", "com_x")


def deviation(value: float, reference: float) -> tuple[float, float | None]:
    """The error of ``value`` against ``reference``: (value - reference, (value - reference) / |reference|);
    the relative error is None for a zero reference."""
    difference = value - reference
    return difference, (difference / abs(reference) if reference else None)


def model_errors(reference, approximation) -> dict:
    """Relative and absolute errors of the reduced run against the FOM run [m]."""
    errors = {}
    for name in ("distance", "tail_amplitude"):
        errors[f"{name}_absolute"], errors[f"{name}_relative"] = deviation(getattr(approximation, name),
                                                                           getattr(reference, name))
    ref_arrays, arrays = reference.trajectory.arrays(), approximation.trajectory.arrays()
    for name in ERROR_SIGNALS:
        scale = np.abs(ref_arrays[name]).max()
        errors[f"{name}_max_error_relative_to_peak"] = float(np.abs(arrays[name] - ref_arrays[name]).max() / scale)
    return errors
