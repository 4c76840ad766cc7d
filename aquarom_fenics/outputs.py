"""Files a run leaves behind: incremental CSV, atomic JSON, versions, plots."""
from __future__ import annotations

import csv
import json
import os
import platform
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from .trajectory import COLUMNS


def write_json_atomic(path: Path, data) -> None:
    """Write JSON through a temporary file and os.replace, so a reader never sees half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(handle, "w") as stream:
        json.dump(data, stream, indent=2, sort_keys=True, default=_json_default)
        stream.write("\n")
    os.chmod(temporary, 0o644)
    os.replace(temporary, path)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"not JSON serialisable: {type(value)}")


class TrajectoryCSV:
    """trajectory.csv, one row per converged step, flushed at once (kept if a later step fails)."""

    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(path, "w", newline="")
        self._writer = csv.writer(self._stream)
        self._writer.writerow(COLUMNS)
        self._stream.flush()

    def write(self, time, head_x, tail_y, com_x, iterations) -> None:
        self._writer.writerow([f"{time:.10g}", f"{head_x:.17g}", f"{tail_y:.17g}", f"{com_x:.17g}", iterations])
        self._stream.flush()

    def close(self) -> None:
        self._stream.close()


def write_trajectory_csv(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """A whole trajectory at once (reduced runs are fast enough not to stream)."""
    table = TrajectoryCSV(path)
    for row in zip(*(arrays[name] for name in COLUMNS)):
        table.write(*row[:4], int(row[4]))
    table.close()


def read_trajectory_csv(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    return {name: np.asarray(data[name]) for name in COLUMNS}


def software_versions() -> dict[str, str]:
    import dolfinx
    import petsc4py
    import ufl

    from . import __version__

    return {"aquarom_fenics": __version__, "dolfinx": dolfinx.__version__, "petsc4py": petsc4py.__version__,
            "ufl": ufl.__version__, "numpy": np.__version__, "python": platform.python_version()}


def git_commit(repository: Path) -> str:
    """The commit checked out in `repository`, else $AQUAROM_GIT_COMMIT, else "unknown".

    Only a checkout whose top level is `repository` itself counts (not one that merely contains a
    copy of it); an image built without the history is given the commit in AQUAROM_GIT_COMMIT.
    """
    try:
        answer = subprocess.run(["git", "-C", str(repository), "rev-parse", "--show-toplevel", "HEAD"],
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):   # no git, or git hangs
        answer = None
    lines = answer.stdout.splitlines() if answer is not None and answer.returncode == 0 else []
    if len(lines) == 2 and Path(lines[0]).resolve() == Path(repository).resolve():
        return lines[1]
    return os.environ.get("AQUAROM_GIT_COMMIT") or "unknown"


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
