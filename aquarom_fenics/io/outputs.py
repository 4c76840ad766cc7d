"""Output folders: claimed before a run (never over another's files), listed in a manifest, published
when the run is done (CSV tables: ``tables``, versions: ``versions``, plots: ``plots``, atomic
writes: ``persistence``)."""
from __future__ import annotations

import ctypes
import json
import os
import shutil
import stat
import logging
from dataclasses import dataclass, field
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.output_lock import lock_output, release_output_locks
from aquarom_fenics.io.persistence import require_writable, write_json_atomic
from aquarom_fenics.io.versions import git_commit, software_versions

log = logging.getLogger("aquarom")


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
    made: list[Path] = field(default_factory=list)      # parent folders this run created (deepest first)
    foreign: list[str] = field(default_factory=list)    # files in ``working`` at the claim not of the toolkit
    foreign_stats: dict = field(default_factory=dict)   # their (inode, mtime, size) at the claim


def holds_file(folder: Path, pattern: str) -> bool:
    """Whether ``folder`` holds a file matching ``pattern`` (a name or a glob such as ``w1_*/checkpoint.json``)."""
    return any(found.is_file() for found in Path(folder).glob(pattern))


def claim_folder(path: Path, force: bool, resume: bool, resume_file: str = "checkpoint.json") -> OutputLocation:
    """An output folder that may be written, refusing to touch anything the toolkit did not write.

    The run first takes the folder's lock (:mod:`output_lock`: one writer per output). Without
    ``force`` an occupied folder is refused; with it, only a folder of an earlier run (its
    ``manifest.json`` lists every file in it) is accepted, and the new run writes beside it.
    ``resume``: the folder of an earlier run, which must hold ``resume_file`` (a name or a glob
    pattern such as ``w1_*/checkpoint.json``), is continued in place.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"output {path} is a file, not a folder; choose another --out")
    absolute = path.resolve()
    if absolute == Path(absolute.anchor):
        raise InputError(f"output {path} is the root folder; give a folder of its own to --out")
    if resume:
        if not holds_file(path, resume_file):
            raise InputError(f"--resume: no {resume_file} in {path}; run without --resume")
        lock_output(path)
        require_writable(path)
        foreign = foreign_files(path)
        return OutputLocation(path, path, created=False, replacing=False, foreign=foreign,
                              foreign_stats={name: _stat_key(path / name) for name in foreign})
    made = _make_parents(path)
    try:
        return _claim_unlocked(path, force, made)
    except BaseException:
        remove_if_empty(made)
        raise


def _claim_unlocked(path: Path, force: bool, made: list[Path]) -> OutputLocation:
    lock_output(path)
    _mention_leftovers(path)
    if not path.is_dir() or not any(path.iterdir()):
        created = not path.exists()
        _make_folder(path)
        return OutputLocation(path, path, created=created, replacing=False, made=made)
    if not force:
        raise InputError(f"output {path} exists; pass --force to replace it or choose another --out")
    _refuse_foreign(path, "holds")
    absolute = path.resolve()
    working = absolute.with_name(f"{absolute.name}.new-{os.getpid()}")
    _make_folder(working)
    return OutputLocation(path, working, created=True, replacing=True, made=made)


def _mention_leftovers(path: Path) -> None:
    """Warn about ``NAME.new-PID/`` folders of runs that were killed outright (their process is
    gone): partial results the toolkit never swapped in, left for the user to look at or remove."""
    absolute = Path(path).resolve()
    for folder in sorted(absolute.parent.glob(f"{absolute.name}.new-*")):
        pid = folder.name.rsplit("-", 1)[-1]
        if folder.is_symlink() or not folder.is_dir() or not pid.isdigit() or Path(f"/proc/{pid}").exists():
            continue
        how = "stopped by its solver" if manifest_files(folder) is not None else "that was killed"
        log.warning("output %s: %s/ holds the partial results of a run %s (PID %s); "
                    "remove it when you no longer need it", path, folder, how, pid)


def _refuse_foreign(path: Path, verb: str, kept: str = "") -> None:
    problem = manifest_problem(path)
    if problem:
        raise InputError(f"output {path}: {problem}; so it cannot tell the files the toolkit did not write: "
                         f"{kept or 'look at the folder, or choose another --out'}")
    foreign = foreign_files(path)
    if foreign:
        raise InputError(f"output {path} {verb} files the toolkit did not write ({', '.join(foreign[:3])}"
                         f"{', …' if len(foreign) > 3 else ''}); --force only replaces an earlier run's folder: "
                         f"{kept or 'move them or choose another --out'}")


def manifest_files(folder: Path) -> list[str] | None:
    """The files a folder's manifest.json lists (None without a readable manifest)."""
    from aquarom_fenics.io.readback import load_manifest

    try:
        return load_manifest(Path(folder) / MANIFEST).get("files")
    except InputError:
        return None


def manifest_problem(folder: Path) -> str | None:
    """Why a folder's manifest.json cannot be trusted (a link, damaged, or naming files outside the
    folder), or None (no manifest, or a valid one)."""
    from aquarom_fenics.io.readback import load_manifest

    path = Path(folder) / MANIFEST
    if not path.exists() and not path.is_symlink():
        return None
    try:
        load_manifest(path)
    except InputError as error:
        return str(error)
    return None


def files_in(folder: Path) -> list[str]:
    """Everything below ``folder`` but its folders: files and links (never followed), and each
    empty folder as ``NAME/`` (relative names, sorted)."""
    found: list[str] = []

    def walk(directory: str, prefix: str) -> None:
        try:
            entries = list(os.scandir(directory))
        except OSError:
            return
        for entry in entries:
            name = prefix + entry.name
            if entry.is_dir(follow_symlinks=False):
                before = len(found)
                walk(entry.path, name + "/")
                if len(found) == before and not any(True for _ in _entries(entry.path)):
                    found.append(name + "/")
            else:
                found.append(name)

    walk(str(folder), "")
    return sorted(found)


def _entries(directory: str):
    try:
        return os.scandir(directory)
    except OSError:
        return iter(())


def foreign_files(folder: Path) -> list[str]:
    """Files in ``folder`` that its manifest does not list (everything, when there is no manifest)."""
    listed = manifest_files(folder)
    present = files_in(folder)
    if listed is None:
        return present
    listed = set(listed)
    return [name for name in present if name != MANIFEST and name not in listed]


def _stat_key(path: Path) -> tuple | None:
    """(inode, mtime [ns], size) of a file or link (not followed), None when it is gone."""
    try:
        details = os.lstat(path)
    except OSError:
        return None
    return details.st_ino, details.st_mtime_ns, details.st_size


def list_outputs(folder: Path, foreign: list[str] = (), foreign_stats: dict | None = None) -> None:
    """Add the list of files of a run to its manifest.json (what --force may replace): every file
    in the folder except ``foreign`` (files that were there, not the toolkit's, when the run began).

    With ``foreign_stats`` (a resumed run) a file of ``foreign`` that this run rewrote (another
    inode, mtime or size than at the claim: a killed run's ``sweep.csv`` or ``history.csv``,
    unlisted since that run wrote no manifest) is listed as the toolkit's."""
    manifest = Path(folder) / MANIFEST
    data = json.loads(manifest.read_text())
    stats = foreign_stats or {}
    excluded = {name for name in foreign
                if foreign_stats is None or _stat_key(Path(folder) / name) == stats.get(name)} | {MANIFEST}
    data["files"] = [name for name in files_in(folder) if name not in excluded]
    write_json_atomic(manifest, data)


def record_outputs(folder: Path, paths: list[Path]) -> None:
    """Add files the toolkit wrote into an earlier run's folder (an animation) to its manifest."""
    folder = Path(folder)
    listed = manifest_files(folder)
    if listed is None:
        return
    data = json.loads((folder / MANIFEST).read_text())
    names = {str(Path(p).resolve().relative_to(folder.resolve())) for p in paths}
    data["files"] = sorted(set(listed) | names)
    write_json_atomic(folder / MANIFEST, data)


def claim_file(path: Path, force: bool, written_by_toolkit, example: str = "prom.npz") -> Path:
    """An output file that may be written: its lock is taken (one writer per output); an existing
    one is replaced only with ``force`` and only when ``written_by_toolkit(path)``; the parent
    folder must be writable."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"output {path} is a folder, not a file; give a file name, e.g. {path / example}")
    made = _make_parents(path, "file")
    try:
        lock_output(path)
        if path.exists():
            if not force:
                raise InputError(f"output {path} exists; pass --force to replace it or choose another --out")
            if not written_by_toolkit(path):
                raise InputError(f"output {path} was not written by the toolkit; --force only replaces its own files")
        require_writable(path.parent)
    except BaseException:
        remove_if_empty(made)
        raise
    return path


def publish(location: OutputLocation) -> Path:
    """Swap a finished replacement run into its target, deciding at that moment: files added to
    the target during the run keep the earlier run in place (InputError naming them). After the
    swap only the files the earlier run's manifest lists are removed."""
    if not location.replacing:
        return location.target
    target = location.target.resolve()
    _refuse_foreign(location.target, "now holds",
                    f"the earlier results are kept; this run's results are in {location.working}/")
    if not _exchange(location.working, target):
        previous = target.with_name(f"{target.name}.old-{os.getpid()}")
        os.rename(target, previous)
        os.rename(location.working, target)
        location.working = previous
    left = remove_run_folder(location.working)
    if left:
        kept = _kept_name(target)
        try:
            os.rename(location.working, kept)
        except OSError:
            kept = location.working
        log.warning("output %s: files added during the swap were kept in %s/ (%s)", location.target,
                    kept, ", ".join(left[:3]))
    location.working = location.target
    return location.target


def remove_run_folder(folder: Path) -> list[str]:
    """Remove the files a run folder's manifest lists, the manifest and the folders these leave
    empty; return what is left (not the toolkit's: the folder then stays).

    Only names inside the folder are removed (relative, no ``..``), never through a link: a link
    itself is removed, not what it points to, and a folder is removed only when it is empty and
    the manifest lists it or a file in it."""
    folder = Path(folder)
    listed = manifest_files(folder) or []
    for name in listed + [MANIFEST]:
        victim = _inside(folder, name)
        if victim is not None and not name.endswith("/"):
            try:
                mode = os.lstat(victim).st_mode
            except OSError:
                continue
            if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
                victim.unlink()
    emptied = set()
    for name in listed:
        parts = name.rstrip("/").split("/")
        emptied.update("/".join(parts[:k]) for k in range(1, len(parts) + (1 if name.endswith("/") else 0)))
    for name in sorted(emptied, key=lambda name: name.count("/"), reverse=True):
        sub = _inside(folder, name)
        if sub is not None and sub.is_dir() and not sub.is_symlink():
            try:
                sub.rmdir()
            except OSError:
                pass
    left = files_in(folder)
    if not left:
        try:
            folder.rmdir()
        except OSError:
            pass
    return left


def _inside(folder: Path, name: str) -> Path | None:
    """``folder / name`` when ``name`` is a relative name inside ``folder`` whose parent folders are
    real folders (no link on the way), else None."""
    from aquarom_fenics.io.readback import is_inside_name

    if not is_inside_name(name):
        return None
    parts = name.rstrip("/").split("/")
    here = Path(folder)
    for part in parts[:-1]:
        here = here / part
        try:
            if not stat.S_ISDIR(os.lstat(here).st_mode):
                return None
        except OSError:
            return None
    return here / parts[-1]


def discard(location: OutputLocation) -> None:
    """Remove what a refused run wrote (only folders it created itself)."""
    if location.created and location.working.is_dir():
        shutil.rmtree(location.working)
    remove_if_empty(location.made)


def _kept_name(target: Path) -> Path:
    """``NAME.kept-PID[-k]``: a folder of files that were not the toolkit's, left after a swap (never
    a ``NAME.new-PID/`` that the next run would take for a killed run's partial results)."""
    candidate = target.with_name(f"{target.name}.kept-{os.getpid()}")
    k = 1
    while candidate.exists() or candidate.is_symlink():
        k += 1
        candidate = target.with_name(f"{target.name}.kept-{os.getpid()}-{k}")
    return candidate


def _exchange(first: Path, second: Path) -> bool:
    """Atomically exchange two folders (Linux renameat2 with RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    return renameat2(at_fdcwd, os.fsencode(first), at_fdcwd, os.fsencode(second), rename_exchange) == 0


def _make_parents(path: Path, kind: str = "folder") -> list[Path]:
    """Create the parent folders of ``path``; return those created (deepest first)."""
    parent = Path(path).absolute().parent
    created = [folder for folder in (parent, *parent.parents) if not folder.exists()]
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        remove_if_empty(created)
        raise InputError(f"output {path}: a parent of this {kind} is a file; choose another --out") from None
    except OSError as error:
        remove_if_empty(created)
        raise InputError(f"output {path}: cannot create its folder {parent} ({error.strerror}); "
                         "choose another --out") from None
    return created


def remove_if_empty(folders: list[Path]) -> None:
    """Remove the folders that are empty but for this run's lock files (deepest first), leaving
    the others."""
    for folder in folders:
        release_output_locks(folder)
        try:
            folder.rmdir()
        except OSError:
            pass


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


def write_manifest(folder: Path, command: str, arguments: dict, scene, timings: dict, extra: dict | None = None) -> None:
    """manifest.json of a run's folder: command and arguments, scene (name, source, hash, values),
    versions, git commit, host cores, MPI ranks, timings per phase [s], the date and ``extra``."""
    import time

    from mpi4py import MPI

    from aquarom_fenics.io.paths import PACKAGE

    write_json_atomic(Path(folder) / MANIFEST, {
        "command": command, "arguments": {key: str(value) for key, value in arguments.items()},
        "scene": None if scene is None else {"name": scene.name, "source": scene.source, "hash": scene.hash,
                                             "values": scene.to_dict()},
        "versions": software_versions(), "git_commit": git_commit(PACKAGE.parent),
        "host_cores": os.cpu_count(), "mpi_ranks": MPI.COMM_WORLD.size, "timings": timings,
        "date": time.strftime("%Y-%m-%d %H:%M:%S")} | (extra or {}))


def on_rank_zero(comm, action, describe_os_error=None):
    """``action()`` on rank 0 of ``comm`` (file-system work); its value on every rank, or its error as the
    same InputError on every rank (an OSError too when ``describe_os_error`` turns it into text)."""
    outcome = (None, None)
    if comm.rank == 0:
        try:
            outcome = (action(), None)
        except InputError as error:
            outcome = (None, str(error))
        except OSError as error:
            if describe_os_error is None:
                raise
            outcome = (None, describe_os_error(error))
    value, problem = comm.bcast(outcome) if comm.size > 1 else outcome
    if problem:
        raise InputError(problem)
    return value
