"""The plots of a run: trajectory and model comparison (matplotlib, Agg)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_comparison(path: Path, runs: dict[str, dict[str, np.ndarray]], title: str) -> None:
    """Overlay of head x, centre-of-mass x and tail y [cm] of several models."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for (label, arrays), style in zip(runs.items(), ("-", "--", ":", "-.")):
        for axis, name in zip(axes, ("head_x", "com_x", "tail_y")):
            axis.plot(arrays["time"], 100 * arrays[name], style, label=label)
    for axis, label in zip(axes, ("head x [cm]", "centre of mass x [cm]", "tail y [cm]")):
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
    axes[0].legend(loc="upper left")
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def plot_trajectory(path: Path, arrays: dict[str, np.ndarray], title: str) -> None:
    """Head x and tail y [cm] over time, and the centre-of-mass x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    top.plot(arrays["time"], 100 * arrays["head_x"], label="head x")
    top.plot(arrays["time"], 100 * arrays["com_x"], label="centre of mass x", linestyle="--")
    top.set_ylabel("displacement x [cm]")
    top.legend(loc="upper left")
    bottom.plot(arrays["time"], 100 * arrays["tail_y"], color="tab:red")
    bottom.set_ylabel("tail y [cm]")
    bottom.set_xlabel("time [s]")
    for axis in (top, bottom):
        axis.grid(alpha=0.3)
    top.set_title(title)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
