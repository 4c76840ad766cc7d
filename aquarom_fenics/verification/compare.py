"""FOM against reduced model at one design: errors of distance, tail amplitude and trajectories."""
from __future__ import annotations

import numpy as np

ERROR_SIGNALS = ("head_x", "tail_y", "com_x")


def model_errors(reference, approximation) -> dict:
    """Relative and absolute errors of the reduced run against the FOM run [m]."""
    errors = {}
    for name, ref, value in (("distance", reference.distance, approximation.distance),
                             ("tail_amplitude", reference.tail_amplitude, approximation.tail_amplitude)):
        errors[f"{name}_absolute"] = value - ref
        errors[f"{name}_relative"] = (value - ref) / abs(ref)
    ref_arrays, arrays = reference.trajectory.arrays(), approximation.trajectory.arrays()
    for name in ERROR_SIGNALS:
        scale = np.abs(ref_arrays[name]).max()
        errors[f"{name}_max_error_relative_to_peak"] = float(np.abs(arrays[name] - ref_arrays[name]).max() / scale)
    return errors
