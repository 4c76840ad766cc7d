"""Output folders and files of a command: claimed before the work, settled (manifest, swap) after it."""
from __future__ import annotations

import os
import sys
import time
import zipfile
from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.errors import InputError, Interrupted, SolverError


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


def claim_output_file(args, path: Path) -> Path:
    """An output file (a PROM): an existing one is replaced only with --force and only if it is a PROM file."""
    from aquarom_fenics.io.outputs import claim_file

    return on_rank_zero(lambda: claim_file(path, args.force, is_prom_file))


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
    comm = MPI.COMM_WORLD
    outcome = (None, None)
    if comm.rank == 0:
        try:
            outcome = (action(), None)
        except InputError as error:
            outcome = (None, str(error))
        except OSError as error:
            outcome = (None, os_error_text(error))
    value, problem = comm.bcast(outcome) if comm.size > 1 else outcome
    if problem:
        raise InputError(problem)
    return value


def settle_output(args, code: int, wall_time: float) -> None:
    """Finish the output folder on rank 0: a finished run gets its manifest and is swapped into
    place; a stopped or interrupted one keeps its partial results and a manifest (an earlier
    run being replaced stays untouched); a refused one removes the folder it created."""
    from aquarom_fenics.io.outputs import discard, list_outputs, publish

    location = vars(args).pop("output", None)     # settled once; not an argument for the manifest
    if location is None or MPI.COMM_WORLD.rank != 0:
        return
    if code in (0, SolverError.exit_code, Interrupted.exit_code):
        if location.working.is_dir():
            write_manifest(args, wall_time)
            list_outputs(location.working)
        if code == 0:
            publish(location)
    else:
        discard(location)


def write_manifest(args, wall_time: float) -> None:
    """manifest.json: scene, versions, git commit, command, host cores, timings per phase, and what
    a command adds in ``args.manifest_extra`` (a sweep's backend and counts)."""
    from aquarom_fenics.io.outputs import git_commit, software_versions
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.io.paths import PACKAGE

    scene = getattr(args, "scene_used", None)
    write_json_atomic(args.output_dir / "manifest.json", {
        "command": "aquarom " + " ".join(sys.argv[1:]) if sys.argv and sys.argv[0].endswith("aquarom") else args.command,
        "arguments": {k: str(v) for k, v in vars(args).items()
                      if k not in ("scene_used", "timings", "output_dir", "manifest_extra")},
        "scene": None if scene is None else {"name": scene.name, "source": scene.source, "hash": scene.hash,
                                             "values": scene.to_dict()},
        "versions": software_versions(), "git_commit": git_commit(PACKAGE.parent),
        "host_cores": os.cpu_count(), "mpi_ranks": MPI.COMM_WORLD.size,
        "timings": {"total": wall_time} | getattr(args, "timings", {}),
        "date": time.strftime("%Y-%m-%d %H:%M:%S")} | getattr(args, "manifest_extra", {}))
