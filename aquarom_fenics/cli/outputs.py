"""Output folders and files of a command: claimed before the work, settled (manifest, swap) after it."""
from __future__ import annotations

import sys
import zipfile
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.errors import InputError, Interrupted, SolverError, Terminated
from aquarom_fenics.io import outputs as io_outputs


def os_error_text(error: OSError, unnamed: str = "a file") -> str:
    """'PATH: what went wrong' for an operating-system error (permission, missing folder, full disk)."""
    where = error.filename if error.filename is not None else unnamed
    return f"{where}: {error.strerror or error}"


def claim_output(args, path: Path, resume: bool = False, resume_file: str = "checkpoint.json") -> Path:
    """The folder this run writes to (see :func:`aquarom_fenics.io.outputs.claim_folder`): the output
    folder itself, or a folder beside it when --force replaces an earlier run's results."""
    from aquarom_fenics.io.outputs import claim_folder

    location = on_rank_zero(lambda: claim_folder(path, getattr(args, "force", False), resume, resume_file))
    args.output = location
    args.output_dir = location.working
    return location.working


def claim_output_file(args, path: Path, written_by_toolkit=None, example: str = "prom.npz") -> Path:
    """An output file, locked for this run: an existing one is replaced only with --force and only
    if ``written_by_toolkit(path)`` (default: it is a PROM file)."""
    from aquarom_fenics.io.outputs import claim_file

    parent = Path(path).absolute().parent
    made = [folder for folder in (parent, *parent.parents) if not folder.exists()]
    claimed = on_rank_zero(lambda: claim_file(path, args.force, written_by_toolkit or is_prom_file, example))
    args.made_for_files = getattr(args, "made_for_files", []) + made   # removed again if the run is refused
    return claimed


def is_prom_file(path: Path) -> bool:
    """A .npz archive with the header of a PROM file (see ``ReducedModel.save``)."""
    try:
        with zipfile.ZipFile(path) as archive:
            return "header.npy" in archive.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def shown(args, path: Path) -> Path:
    """Where ``path`` (written in the working folder) is once a successful run is published."""
    location = getattr(args, "output", None)
    if location is None or not location.replacing:
        return Path(path)
    return location.target / Path(path).relative_to(location.working)


def on_rank_zero(action):
    """``action()`` on rank 0 (file-system work); its value, or its error as the same InputError on every rank."""
    return io_outputs.on_rank_zero(MPI.COMM_WORLD, action, os_error_text)


def settle_output(args, code: int, wall_time: float) -> None:
    """Finish the output folder on rank 0: a finished run gets its manifest and is swapped into
    place; a stopped one (solver) keeps its partial results and a manifest beside an earlier run
    being replaced; an interrupted one (Ctrl-C, SIGTERM) that wrote something takes the earlier
    run's place (so that --resume continues it); a refused one removes the folders it created."""
    from aquarom_fenics.io.outputs import remove_if_empty, discard, list_outputs, publish

    location = vars(args).pop("output", None)     # settled once; not an argument for the manifest
    made_for_files = vars(args).pop("made_for_files", [])
    if MPI.COMM_WORLD.rank == 0 and code not in (0, SolverError.exit_code, *STOP_CODES):
        remove_if_empty(made_for_files)
    if location is None or MPI.COMM_WORLD.rank != 0:
        return
    written = location.working.is_dir() and any(location.working.iterdir())
    failed_write = getattr(args, "failed_write", False) and written     # keeps what was written before
    if code in (0, SolverError.exit_code) or (code in STOP_CODES and written) or failed_write:
        if location.working.is_dir():
            write_manifest(args, wall_time)
            list_outputs(location.working, location.foreign, location.foreign_stats)
        if code != SolverError.exit_code and not failed_write:
            publish(location)
    else:
        discard(location)


STOP_CODES = (Interrupted.exit_code, Terminated.exit_code)
"""Exit codes of a run stopped by Ctrl-C (130) or SIGTERM (143)."""


def write_manifest(args, wall_time: float) -> None:
    """manifest.json: scene, versions, git commit, command, host cores, timings per phase, and what
    a command adds in ``args.manifest_extra`` (a sweep's backend and counts)."""
    from aquarom_fenics.io.outputs import write_manifest as write_folder_manifest

    command = "aquarom " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("aquarom") else args.command
    arguments = {k: v for k, v in vars(args).items()
                 if k not in ("scene_used", "timings", "output_dir", "manifest_extra", "failed_write")}
    write_folder_manifest(args.output_dir, command, arguments, getattr(args, "scene_used", None),
                          {"total": wall_time} | getattr(args, "timings", {}), getattr(args, "manifest_extra", {}))
