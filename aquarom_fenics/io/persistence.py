"""Files that must never be seen half-written, and content-addressed caches of expensive results.

One atomic write (:func:`write_bytes_atomic`: a uniquely named temporary file beside the target,
then ``os.replace``) under the text, JSON and .npz writers; one get-or-compute
(:func:`get_or_compute`) for every cache (meshes, PROMs, FOM checks, validation cases). A cache
entry is a file with a SHA-256 sidecar (``NAME.sha256``) and an flock file (``NAME.lock``):
writers store file and checksum as one step under an exclusive lock, readers check the checksum
under a shared lock (a read-only cache is read without a lock), and an entry that does not match
its checksum is reported and rebuilt, never used.
"""
from __future__ import annotations

import fcntl
import hashlib
import io
import json
import logging
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import cache_root

log = logging.getLogger("aquarom")
Value = TypeVar("Value")


# ---------------------------------------------------------------------- atomic writes
def write_bytes_atomic(path: Path, content: bytes) -> None:
    """A uniquely named temporary file beside ``path``, then os.replace; an OS error names ``path``."""
    path = Path(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(content)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except OSError as error:
        Path(temporary).unlink(missing_ok=True)
        raise OSError(error.errno, error.strerror, str(path)) from None
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str) -> None:
    """UTF-8 text written like :func:`write_bytes_atomic` (atomic on POSIX)."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: Path, data) -> None:
    """JSON (sorted keys, indent 2) written like :func:`write_bytes_atomic`, its folder created.

    Non-finite numbers become null (standard JSON has no Infinity or NaN).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_finite_or_null(data), indent=2, sort_keys=True, default=_json_default, allow_nan=False)
    write_text_atomic(path, text + "\n")


def write_npz_atomic(path: Path, arrays: dict[str, np.ndarray], compressed: bool = False) -> None:
    """A .npz archive built in memory, then written like :func:`write_bytes_atomic` (a full disk
    fails on one plain write that names the file, never halfway through the archive)."""
    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def _finite_or_null(value):
    if isinstance(value, dict):
        return {key: _finite_or_null(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(item) for item in value]
    if isinstance(value, np.ndarray):
        return _finite_or_null(value.tolist())
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None
    return value


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"not JSON serialisable: {type(value)}")


def require_writable(folder: Path, what: str = "output") -> None:
    """A probe file is created and removed, so a read-only or full location fails before any work."""
    try:
        handle, probe = tempfile.mkstemp(dir=folder, prefix=".write-probe-")
        os.close(handle)
        os.unlink(probe)
    except OSError as error:
        raise InputError(f"{what} {folder}: not writable ({error.strerror}); choose a writable location") from None


# ---------------------------------------------------------------------- checksummed cache entries
def entry_key(*parts) -> str:
    """SHA-256 (24 hex digits) of the JSON of what an entry depends on, plus the software versions."""
    from aquarom_fenics.io.versions import software_versions

    text = json.dumps([parts, software_versions()], sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _plain(value):
    if isinstance(value, np.ndarray):
        return [repr(float(v)) for v in value.ravel()]
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(type(value))


def require_cache_writable(kind: str | None = None) -> None:
    """Refuse (one line, exit 2) a cache that cannot take new entries, before the work that fills it."""
    root = cache_root()
    folder = root / kind if kind else root
    if root.exists() and not root.is_dir():
        raise InputError(f"cache {root} ($AQUAROM_CACHE) is a file, not a folder; point AQUAROM_CACHE to a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"cache {folder} ($AQUAROM_CACHE): cannot create it ({error.strerror}); "
                         "point AQUAROM_CACHE to a writable folder") from None
    require_writable(folder, "cache")


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes, as 64 hex digits."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + ".sha256")


def is_intact(path: Path) -> bool:
    """The file exists and matches its SHA-256 sidecar."""
    sidecar = _sidecar(path)
    return path.exists() and sidecar.exists() and sidecar.read_text().strip() == file_digest(path)


def seal(path: Path) -> None:
    """Write the SHA-256 sidecar of a finished cache file (atomically, under a unique temporary name)."""
    write_text_atomic(_sidecar(path), file_digest(path) + "\n")


@contextmanager
def entry_lock(path: Path, shared: bool = False):
    """An flock on ``PATH.lock``: exclusive for writers, shared for readers, so a reader never sees
    one writer's data with another writer's checksum. A read-only cache is read without a lock."""
    try:
        handle = open(path.with_name(path.name + ".lock"), "a")
    except OSError:
        if not shared:
            raise
        handle = None
    try:
        if handle is not None:
            fcntl.flock(handle, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        yield
    finally:
        if handle is not None:
            handle.close()


def store(path: Path, save: Callable[[Path], None]) -> None:
    """``save(path)`` (an atomic replacement) and the checksum sidecar, as one step under the entry's lock;
    a store cut short (an error, Ctrl-C or SIGTERM between the two) leaves no unsealed entry behind."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with entry_lock(path):
        try:
            save(path)
            seal(path)
        except BaseException:
            if not is_intact(path):
                for victim in (path, _sidecar(path)):
                    victim.unlink(missing_ok=True)
            raise


def discard_entry(path: Path) -> None:
    """Remove an entry and its checksum under the entry's lock."""
    with entry_lock(path):
        for victim in (path, _sidecar(path)):
            victim.unlink(missing_ok=True)


def read_intact(path: Path, load: Callable[[Path], Value]) -> Value | None:
    """``load(path)`` of an entry that matches its checksum; None (logged) for a damaged or unsealed one."""
    with entry_lock(path, shared=True):
        if is_intact(path):
            return load(path)
        sealed = _sidecar(path).exists()
    problem = "does not match its checksum (corrupted)" if sealed else "has no checksum"
    log.warning("cache: entry %s %s; rebuilding it", path.name, problem)
    return None


def get_or_compute(path: Path, compute: Callable[[], Value], save: Callable[[Value, Path], None],
                   load: Callable[[Path], Value], comm=None, label: str = "cache",
                   on_store_error: Callable[[OSError], None] | None = None,
                   store_if: Callable[[Value], bool] | None = None) -> Value:
    """The value of the cache entry ``path`` when it matches its checksum, else ``compute()``, stored there.

    ``load(path)`` reads an entry (InputError or ValueError: unusable, rebuilt with a warning);
    ``save(value, path)`` writes one atomically. With an MPI communicator ``comm`` every rank reads
    and computes (``compute`` may be collective) and rank 0 alone removes and stores entries, the
    ranks meeting at barriers around that. ``on_store_error(error)`` takes an OSError of the cache
    (read-only or blocked folder) instead of raising it: the value is then returned unstored.
    ``store_if(value)`` False keeps a value out of the cache (an outcome that is no answer of the
    model, such as a time limit, is computed again next time).
    ``label`` starts the log lines ("PROM cache: reused from the cache (NAME)").
    """
    path = Path(path)
    is_writer = comm is None or comm.rank == 0
    if path.exists():
        try:
            value = read_intact(path, load)
        except (InputError, ValueError) as damaged:
            log.warning("%s: entry %s unusable (%s); rebuilding it", label, path.name, damaged)
            value = None
        if value is not None:
            log.info("%s: reused from the cache (%s)", label, path.name)
            return value
        _on_writer(comm, is_writer, lambda: discard_entry(path), on_store_error)
    value = compute()
    if store_if is not None and not store_if(value):
        return value

    def store_value():
        store(path, lambda target: save(value, target))
        log.info("%s: built and stored %s", label, path.name)

    _on_writer(comm, is_writer, store_value, on_store_error)
    return value


def _on_writer(comm, is_writer: bool, action: Callable[[], None], on_store_error) -> None:
    """``action()`` on the writing rank, the others waiting at a barrier; an OSError goes to
    ``on_store_error`` when given."""
    if comm is not None:
        comm.barrier()
    if is_writer:
        try:
            action()
        except OSError as error:
            if on_store_error is None:
                raise
            on_store_error(error)
    if comm is not None:
        comm.barrier()


def clear_entries(folder: Path) -> tuple[int, list[str]]:
    """Remove the cache entries in ``folder`` (files with a checksum sidecar, each under its lock,
    with the sidecar and the lock file) and the folders left empty; return the number removed and
    the files left (not written by the cache: a user's files are never removed)."""
    folder = Path(folder)
    if not folder.is_dir():
        return 0, []
    removed = 0
    for sidecar in sorted(folder.rglob("*.sha256")):
        entry = sidecar.with_name(sidecar.name[:-len(".sha256")])
        discard_entry(entry)
        entry.with_name(entry.name + ".lock").unlink(missing_ok=True)
        removed += 1
    for sub in sorted((p for p in folder.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True):
        try:
            sub.rmdir()
        except OSError:
            pass
    left = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir())
    if not left:
        try:
            folder.rmdir()
        except OSError:
            pass
    return removed, left
