"""The PROM cache, and the listing and clearing of every cache (PROMs, FOM checks, meshes).

A PROM entry's name is the hash of everything it depends on (the scene values a build reads and
the mesh content through ``Scene.prom_hash``, the building point, the model kind, the software
versions): scenes that differ only in what no build reads (``[optimizer]``, ``[output]``, the shape
starts, ...) share their PROMs, and an entry built from other values is a miss, rebuilt; storing,
checksums, locks and rebuilding damaged entries are :func:`persistence.get_or_compute`'s.
Compiled forms are cached by FFCx itself (by form signature) in its own cache folder.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.io.paths import cache_root, forms_cache, mesh_cache
from aquarom_fenics.io.persistence import entry_key, get_or_compute, require_cache_writable
from aquarom_fenics.io.scene import Scene

KINDS = ("prom", "fom")


def cached_prom(scene: Scene, xi_center: np.ndarray, build, parametric: bool = True,
                comm: MPI.Comm = MPI.COMM_WORLD, basis_center: np.ndarray | None = None):
    """The PROM of ``scene`` at ``xi_center`` from the cache, or ``build()`` and store it.

    ``basis_center``: the design whose basis the PROM reuses (None: its basis is built at
    ``xi_center``); part of the entry's name, since the basis changes the PROM.
    """
    from aquarom_fenics.reduction.prom import ReducedModel

    def checked_build():
        require_cache_writable("prom")
        return build()

    return get_or_compute(prom_entry(scene, xi_center, parametric, basis_center), checked_build,
                          save=lambda model, path: model.save(path),
                          load=lambda path: ReducedModel.load(path, prom_hash=scene.prom_hash),
                          comm=comm, label="PROM cache")


def prom_entry(scene: Scene, xi_center: np.ndarray, parametric: bool = True,
               basis_center: np.ndarray | None = None) -> Path:
    """The cache file of the PROM of ``scene`` at ``xi_center`` (on the basis built at ``basis_center``)."""
    extra = () if basis_center is None else ("basis", np.asarray(basis_center, dtype=float))
    key = entry_key("prom", scene.prom_hash, np.asarray(xi_center, dtype=float), parametric, *extra)
    return cache_root() / "prom" / f"{key}.npz"


def listing() -> list[tuple[str, Path, int, int]]:
    """(kind, folder, entries, bytes) for every cache: PROMs, FOM checks, meshes, compiled forms."""
    folders = {kind: cache_root() / kind for kind in KINDS}
    folders["mesh"] = mesh_cache()
    folders["compiled forms"] = forms_cache()
    rows = []
    for kind, folder in folders.items():
        files = [f for f in folder.rglob("*") if f.is_file() and not f.name.endswith((".sha256", ".lock"))
                 ] if folder.exists() else []
        rows.append((kind, folder, len(files), sum(f.stat().st_size for f in files)))
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


def stored_prom(scene: Scene, xi_center: np.ndarray, parametric: bool = True):
    """The PROM of ``scene`` at ``xi_center`` if the cache holds an intact entry of it (the key of
    :func:`cached_prom` without a basis centre), else None: nothing is built, stored or removed (a dry run's
    look-up)."""
    from aquarom_fenics.errors import InputError
    from aquarom_fenics.io.persistence import read_intact
    from aquarom_fenics.reduction.prom import ReducedModel

    path = prom_entry(scene, xi_center, parametric)
    if not path.exists():
        return None
    try:
        return read_intact(path, lambda entry: ReducedModel.load(entry, prom_hash=scene.prom_hash))
    except (InputError, ValueError):
        return None
