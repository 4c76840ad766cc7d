"""A gmsh session that leaves gmsh as it found it, and gmsh meshes as numpy arrays."""

from __future__ import annotations

import os
import signal
import tempfile
import threading
from contextlib import contextmanager

import numpy as np

from aquarom_fenics.geometry.mesh import used_nodes_only


GMSH_TETRAHEDRON = 4
"""gmsh element type of the linear tetrahedron."""


@contextmanager
def _keeping_sigint():
    """Restore the caller's SIGINT handler afterwards: importing gmsh sets it to SIG_DFL, and
    gmsh.finalize() sets it back to the handler of the import's time, which may be a temporary one
    long gone (a simulation's Ctrl-C catcher would then swallow every later Ctrl-C)."""
    in_main_thread = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGINT) if in_main_thread else None
    try:
        yield
    finally:
        if in_main_thread and handler is not None:
            signal.signal(signal.SIGINT, handler)


def import_gmsh():
    """Import gmsh, keeping the caller's SIGINT handler."""
    with _keeping_sigint():
        import gmsh
    return gmsh


@contextmanager
def _stderr_silenced():
    """Redirect file descriptor 2 to /dev/null (gmsh prints to it from C)."""
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(devnull)
        os.close(saved)


def gmsh_is_initialized(gmsh) -> bool:
    """True when the gmsh API is initialized (the 4.8 API has no `gmsh.isInitialized`)."""
    if hasattr(gmsh, "isInitialized"):
        return bool(gmsh.isInitialized())
    with _stderr_silenced():
        try:
            return bool(gmsh.option.getString("General.Version"))
        except Exception:
            return False


@contextmanager
def _private_home():
    """$HOME set to an empty temporary folder, restored and the folder removed afterwards.

    gmsh.initialize() sets its default options, and General.Tooltips hands its value to FLTK, whose
    first option query creates $HOME/.fltk/fltk.org/fltk.prefs (FLTK 1.3 takes the path from $HOME
    alone; readConfigFiles=False and no gmsh option avoid it). Later queries in the process read
    FLTK's memory, not the file, so only the initialization needs the private home."""
    saved = os.environ.get("HOME")
    with tempfile.TemporaryDirectory(prefix="aquarom-gmsh-home-") as home:
        os.environ["HOME"] = home
        try:
            yield
        finally:
            if saved is None:
                del os.environ["HOME"]
            else:
                os.environ["HOME"] = saved


def initialize_gmsh(gmsh) -> None:
    """gmsh.initialize() that reads no configuration file and writes nothing in the user's home."""
    with _private_home():
        gmsh.initialize(readConfigFiles=False)


@contextmanager
def gmsh_model(name: str, options: dict[str, float]):
    """A fresh gmsh model with the given options, removed afterwards.

    gmsh is initialized only if it is not already, and then finalized on exit; otherwise the
    caller's current model and option values are restored.
    """
    gmsh = import_gmsh()
    started_here = not gmsh_is_initialized(gmsh)
    if started_here:
        initialize_gmsh(gmsh)
    previous_model = gmsh.model.getCurrent()
    previous_options = {option: gmsh.option.getNumber(option) for option in options}
    try:
        for option, value in options.items():
            gmsh.option.setNumber(option, value)
        gmsh.model.add(name)
        yield gmsh
    finally:
        if started_here:
            with _keeping_sigint():
                try:
                    gmsh.finalize()
                except ValueError:
                    # gmsh.finalize() restores its import-time SIGINT handler after finalizing; off
                    # the main thread (a Dask worker's task) Python refuses signal handlers
                    if threading.current_thread() is threading.main_thread():
                        raise
        else:
            if gmsh.model.getCurrent() == name:
                gmsh.model.remove()
            if previous_model in gmsh.model.list():
                gmsh.model.setCurrent(previous_model)
            for option, value in previous_options.items():
                gmsh.option.setNumber(option, value)


def gmsh_version() -> str:
    return import_gmsh().__version__


def points_and_cells_from_gmsh(node_tags, coordinates, element_nodes):
    """(points, cells) from gmsh node tags/coordinates and tetrahedron node tags, renumbered to
    the nodes the tetrahedra use."""
    node_tags = np.asarray(node_tags, dtype=np.int64)
    points = np.asarray(coordinates, dtype=float).reshape(-1, 3)
    cell_tags = np.asarray(element_nodes, dtype=np.int64).reshape(-1, 4)
    order = np.argsort(node_tags)
    position = np.searchsorted(node_tags[order], cell_tags)
    position = np.clip(position, 0, len(node_tags) - 1)
    if not np.all(node_tags[order][position] == cell_tags):
        raise ValueError("a tetrahedron refers to a node that is not defined")
    return used_nodes_only(points[order], position)
