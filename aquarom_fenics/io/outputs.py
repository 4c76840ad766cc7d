"""Files a run leaves behind: incremental CSV, versions, plots, output folders (atomic writes: ``persistence``)."""
from __future__ import annotations

import csv
import ctypes
import json
import os
import platform
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.dynamics.trajectory import COLUMNS
from aquarom_fenics.io.persistence import require_writable, write_json_atomic


class IncrementalCSV:
    """A CSV file written one row at a time and flushed at once, so that the rows already written
    survive a run that stops later."""

    def __init__(self, path: Path, header: list[str]):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(path, "w", newline="")
        self._writer = csv.writer(self._stream)
        self.rows = 0
        self._writer.writerow(header)
        self._stream.flush()

    def write_row(self, values: list) -> None:
        self._writer.writerow(values)
        self._stream.flush()
        self.rows += 1

    def close(self) -> None:
        self._stream.close()


class TrajectoryCSV(IncrementalCSV):
    """trajectory.csv, one row per converged step (kept if a later step fails)."""

    def __init__(self, path: Path):
        super().__init__(path, list(COLUMNS))

    def write(self, time, head_x, tail_y, com_x, iterations) -> None:
        self.write_row([f"{time:.10g}", f"{head_x:.17g}", f"{tail_y:.17g}", f"{com_x:.17g}", iterations])


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

    from aquarom_fenics import __version__

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


# ---------------------------------------------------------------------- output locations
MANIFEST = "manifest.json"


@dataclass
class OutputLocation:
    """Where a command writes: ``working`` is ``target``, or a folder beside it while an earlier
    run's results in ``target`` are being replaced (they are swapped in only when the run is done)."""

    target: Path
    working: Path
    created: bool          # this run created ``working`` (removed again when the input is refused)
    replacing: bool        # ``target`` holds an earlier run of the toolkit, replaced on success


def claim_folder(path: Path, force: bool, resume: bool, resume_file: str = "checkpoint.json") -> OutputLocation:
    """An output folder that may be written, refusing to touch anything the toolkit did not write.

    Without ``force`` an occupied folder is refused; with it, only a folder of an earlier run
    (its ``manifest.json`` lists every file in it) is accepted, and the new run writes beside it.
    ``resume``: the folder of an earlier run, which must hold ``resume_file``, is continued in place.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"output {path} is a file, not a folder; choose another --out")
    if resume:
        if not (path / resume_file).is_file():
            raise InputError(f"--resume: no {resume_file} in {path}; run without --resume")
        require_writable(path)
        return OutputLocation(path, path, created=False, replacing=False)
    if not path.is_dir() or not any(path.iterdir()):
        created = not path.exists()
        _make_folder(path)
        return OutputLocation(path, path, created=created, replacing=False)
    if not force:
        raise InputError(f"output {path} exists; pass --force to replace it or choose another --out")
    foreign = foreign_files(path)
    if foreign:
        raise InputError(f"output {path} holds files the toolkit did not write ({', '.join(foreign[:3])}"
                         f"{', …' if len(foreign) > 3 else ''}); --force only replaces an earlier run's folder: "
                         "move them or choose another --out")
    absolute = path.resolve()
    working = absolute.with_name(f"{absolute.name}.new-{os.getpid()}")
    _make_folder(working)
    return OutputLocation(path, working, created=True, replacing=True)


def foreign_files(folder: Path) -> list[str]:
    """Files in ``folder`` that its manifest does not list (everything, when there is no manifest)."""
    manifest = folder / MANIFEST
    try:
        listed = set(json.loads(manifest.read_text()).get("files", []))
    except (OSError, ValueError, AttributeError):
        listed = None
    present = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir())
    if listed is None:
        return present
    return [name for name in present if name != MANIFEST and name not in listed]


def list_outputs(folder: Path) -> None:
    """Add the list of files of a finished run to its manifest.json (what --force may replace)."""
    manifest = Path(folder) / MANIFEST
    data = json.loads(manifest.read_text())
    data["files"] = sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*")
                           if not p.is_dir() and p.name != MANIFEST)
    write_json_atomic(manifest, data)


def claim_file(path: Path, force: bool, written_by_toolkit) -> Path:
    """An output file that may be written: an existing one is replaced only with ``force`` and
    only when ``written_by_toolkit(path)``; the parent folder must be writable."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"output {path} is a folder, not a file; give a file name, e.g. {path / 'prom.npz'}")
    if path.exists():
        if not force:
            raise InputError(f"output {path} exists; pass --force to replace it or choose another --out")
        if not written_by_toolkit(path):
            raise InputError(f"output {path} was not written by the toolkit; --force only replaces its own files")
    _make_folder(path.parent)
    return path


def publish(location: OutputLocation) -> Path:
    """Swap a finished replacement run into its target (the earlier run is removed after the swap)."""
    if not location.replacing:
        return location.target
    target = location.target.resolve()
    if not _exchange(location.working, target):
        previous = target.with_name(f"{target.name}.old-{os.getpid()}")
        os.rename(target, previous)
        os.rename(location.working, target)
        location.working = previous
    shutil.rmtree(location.working)
    location.working = location.target
    return location.target


def discard(location: OutputLocation) -> None:
    """Remove what a refused run wrote (only a folder it created itself)."""
    if location.created and location.working.is_dir():
        shutil.rmtree(location.working)


def _exchange(first: Path, second: Path) -> bool:
    """Atomically exchange two folders (Linux renameat2 with RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    return renameat2(at_fdcwd, os.fsencode(first), at_fdcwd, os.fsencode(second), rename_exchange) == 0


def _make_folder(path: Path) -> None:
    """Create ``path`` (and its parents) and check it takes files; on failure nothing created stays."""
    created = [folder for folder in (path, *path.parents) if not folder.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(f"output {path}: a file is in the way of this folder; choose another --out") from None
    except NotADirectoryError:
        raise InputError(f"output {path}: a parent of this folder is a file; choose another --out") from None
    except OSError as error:
        raise InputError(f"output {path}: cannot create the folder ({error.strerror}); choose another --out") from None
    try:
        require_writable(path)
    except InputError:
        for folder in created:
            folder.rmdir()
        raise
