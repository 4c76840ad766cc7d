"""Sampled swimming trajectories and the measures of SPEC §10."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aquarom_fenics.io.tables import TRAJECTORY_COLUMNS as COLUMNS

OBSERVED = ("head_x", "tail_y", "com_x", "tail_x", "com_y")
"""The observed points of a trajectory, in the order of its columns and of its velocities."""

DISTANCE_WINDOW = 0.1    # s, the centre-of-mass x is averaged over the last 0.1 s
AMPLITUDE_WINDOW = 1.0   # s, the tail amplitude is the max |y_tail| over the last second


@dataclass
class Trajectory:
    """One sample per stored time (t = 0 included); displacements in metres."""

    time: list = field(default_factory=list)
    head_x: list = field(default_factory=list)
    tail_y: list = field(default_factory=list)
    com_x: list = field(default_factory=list)
    tail_x: list = field(default_factory=list)
    com_y: list = field(default_factory=list)
    newton_iterations: list = field(default_factory=list)
    rates: list = field(default_factory=list)   # per sample, the velocities of OBSERVED [m/s] (runs that record them)

    def append(self, time: float, head_x: float, tail_y: float, com_x: float, tail_x: float, com_y: float,
               iterations: int, rates=None) -> None:
        """One sample; ``rates``: the velocities of the points of OBSERVED at this time [m/s], if recorded."""
        for name, value in zip(COLUMNS, (time, head_x, tail_y, com_x, tail_x, com_y, iterations)):
            getattr(self, name).append(value)
        if rates is not None:
            self.rates.append(tuple(rates))

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.asarray(getattr(self, name)) for name in COLUMNS}

    def rate_arrays(self) -> dict[str, np.ndarray]:
        """The velocities of the points of OBSERVED per sample [m/s] (d/dt of the arrays of the same name);
        refused when the run did not record them at every sample."""
        if len(self.rates) != len(self.time):
            raise ValueError(f"the trajectory has velocities at {len(self.rates)} of its {len(self.time)} samples")
        rates = np.asarray(self.rates, dtype=float).reshape(len(self.time), len(OBSERVED))
        return {name: rates[:, j] for j, name in enumerate(OBSERVED)}

    def __len__(self) -> int:
        return len(self.time)


def last_stroke_start(duration: float, frequency: float) -> float:
    """Start of the last actuation period [T - 1/f, T] [s], 0 when the horizon is shorter."""
    return max(duration - 1.0 / frequency, 0.0)


def window_mask(time: np.ndarray, window: float) -> np.ndarray:
    """Samples with t ≥ T - window (with a tolerance of a thousandth of the step)."""
    time = np.asarray(time)
    step = time[1] - time[0] if time.size > 1 else 1.0
    return time >= time[-1] - window - 1e-3 * step


def swimming_distance(time, com_x) -> float:
    """d = mean of the centre-of-mass x-displacement over the last 0.1 s [m]."""
    return float(np.mean(np.asarray(com_x)[window_mask(time, DISTANCE_WINDOW)]))


def tail_amplitude(time, tail_y) -> float:
    """The tail amplitude: max over the last second of ``|y_tail|`` [m]."""
    return float(np.max(np.abs(np.asarray(tail_y)[window_mask(time, AMPLITUDE_WINDOW)])))
