"""Content-addressed caches of offline work: PROMs, FOM checks and meshes.

An entry's name is the hash of everything it depends on (scene values and mesh content through
the scene hash, the building point, the model kind, the software versions); each file has a
SHA-256 sidecar, and an entry whose content does not match it is reported and rebuilt, not used.
Compiled forms are cached by FFCx itself (by form signature) in its own cache folder.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import shutil
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import cache_root, mesh_cache
from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")
KINDS = ("prom", "fom")


def require_cache_writable(kind: str | None = None) -> None:
    """Refuse (one line, exit 2) a cache that cannot take new entries, before the work that fills it."""
    from aquarom_fenics.io.outputs import require_writable

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


def entry_key(*parts) -> str:
    """SHA-256 (24 hex digits) of the JSON of what an entry depends on, plus the software versions."""
    from aquarom_fenics.io.outputs import software_versions

    text = json.dumps([parts, software_versions()], sort_keys=True, default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def _plain(value):
    if isinstance(value, np.ndarray):
        return [repr(float(v)) for v in value.ravel()]
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(type(value))


def file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def is_intact(path: Path) -> bool:
    """The file exists and matches its SHA-256 sidecar."""
    sidecar = path.with_name(path.name + ".sha256")
    return path.exists() and sidecar.exists() and sidecar.read_text().strip() == file_digest(path)


def seal(path: Path) -> None:
    """Write the SHA-256 sidecar of a finished cache file (atomically, under a unique temporary name)."""
    from aquarom_fenics.io.outputs import write_text_atomic

    write_text_atomic(path.with_name(path.name + ".sha256"), file_digest(path) + "\n")


def store(path: Path, save) -> None:
    """``save(path)`` (an atomic replacement) and the checksum sidecar, as one step under the entry's lock."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with entry_lock(path):
        save(path)
        seal(path)


def discard(path: Path) -> None:
    with entry_lock(path):
        for victim in (path, path.with_name(path.name + ".sha256")):
            victim.unlink(missing_ok=True)


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


def read_intact(path: Path, load):
    """``load(path)`` of an entry that matches its checksum; None (logged) for a damaged one."""
    with entry_lock(path, shared=True):
        if is_intact(path):
            return load(path)
    log.warning("cache: entry %s does not match its checksum (corrupted); rebuilding it", path.name)
    return None


def cached_prom(scene: Scene, xi_center: np.ndarray, build, parametric: bool = True,
                comm: MPI.Comm = MPI.COMM_WORLD):
    """The PROM of ``scene`` at ``xi_center`` from the cache, or ``build()`` and store it."""
    from aquarom_fenics.reduction.prom import ReducedModel

    key = entry_key("prom", scene.hash, np.asarray(xi_center, dtype=float), parametric)
    path = cache_root() / "prom" / f"{key}.npz"
    if path.exists():
        try:
            model = read_intact(path, lambda entry: ReducedModel.load(entry, scene_hash=scene.hash))
            if model is not None:
                log.info("PROM cache: reused %s", path.name)
                return model
        except InputError as damaged:
            log.warning("PROM cache: entry %s unusable (%s); rebuilding it", path.name, damaged)
        comm.barrier()
        if comm.rank == 0:
            discard(path)
    require_cache_writable("prom")
    model = build()
    if comm.rank == 0:
        store(path, model.save)
        log.info("PROM cache: built and stored %s", path.name)
    comm.barrier()
    return model


def listing() -> list[tuple[str, int, int]]:
    """(kind, entries, bytes) for every cache: PROMs, FOM checks, meshes, compiled forms."""
    folders = {kind: cache_root() / kind for kind in KINDS}
    folders["mesh"] = mesh_cache()
    folders["compiled forms"] = Path.home() / ".cache" / "fenics"
    rows = []
    for kind, folder in folders.items():
        files = [f for f in folder.rglob("*") if f.is_file() and not f.name.endswith((".sha256", ".lock"))
                 ] if folder.exists() else []
        rows.append((kind, len(files), sum(f.stat().st_size for f in files)))
    return rows


def clear(kinds: list[str]) -> list[Path]:
    """Remove the named caches ("prom", "fom", "mesh"); returns the folders removed."""
    removed = []
    for kind in kinds:
        folder = mesh_cache() if kind == "mesh" else cache_root() / kind
        if folder.exists():
            shutil.rmtree(folder)
            removed.append(folder)
    return removed
