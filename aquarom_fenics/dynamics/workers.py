"""How a worker of a many-run job is made ready for the toolkit's tasks (:mod:`aquarom_fenics.parallel`).

Every task runs with the submitting process's result cache ($AQUAROM_CACHE, see
:func:`aquarom_fenics.io.paths.cache_root`), so workers on other machines read and fill the same
content-addressed cache when it lies on a shared file system. A Dask worker imports gmsh, dolfinx
and the FOM when it starts, on its main thread: importing gmsh installs a signal handler, which
Python allows on the main thread only, and a long-lived worker's first task does not pay for them.
"""
from __future__ import annotations

from pathlib import Path

from aquarom_fenics.parallel import WorkerSetup


def task_variables() -> dict[str, str]:
    """The submitting process's result cache, as an absolute path, for every task."""
    from aquarom_fenics.io.paths import cache_root

    return {"AQUAROM_CACHE": str(Path(cache_root()).resolve())}


def main_thread_imports() -> None:
    """gmsh (its signal handler), dolfinx, petsc4py and the FOM, imported once in a new worker."""
    from aquarom_fenics.geometry.gmsh_session import import_gmsh

    import_gmsh()
    import aquarom_fenics.dynamics.simulate  # noqa: F401 — dolfinx, petsc4py, the FOM


def import_probe() -> str:
    """The first task a Dask cluster runs before it is used: the package's version, so a worker
    whose Python cannot import the package fails here, in one line, not inside a design's task."""
    import aquarom_fenics

    return aquarom_fenics.__version__


SWIMMER_WORKERS = WorkerSetup(environment=task_variables, on_start=main_thread_imports,
                              name="aquarom-main-thread-imports", probe=import_probe)
"""The set-up of every pool the toolkit opens."""
