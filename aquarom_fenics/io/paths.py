"""Where the toolkit finds its shipped data and keeps what it computes.

Shipped scenes (``scenes/``) and mesh recipes and meshes (``meshes/``) are package data, found
through the import system, so an installed wheel works like a checkout. Caches live in the
checkout (``results/cache``, ``meshes/cache``) when the package runs from a writable source tree,
otherwise in the user's cache folder ($XDG_CACHE_HOME/aquarom, default ~/.cache/aquarom);
$AQUAROM_CACHE moves every cache of the toolkit (PROMs, FOM checks, meshes) in either case;
FFCx keeps its compiled forms in its own cache ($XDG_CACHE_HOME/fenics, default ~/.cache/fenics).
"""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1]


def checkout() -> Path | None:
    """The source tree the package runs from (``pyproject.toml`` beside it, writable), else None."""
    root = PACKAGE.parent
    if (root / "pyproject.toml").is_file() and (root / "scenes").is_dir() and os.access(root, os.W_OK):
        return root
    return None


def shipped_scenes() -> Path:
    """Folder of the shipped scene files (*.toml)."""
    return Path(str(resources.files("aquarom_fenics.scenes")))


def shipped_meshes() -> Path:
    """Folder of the mesh recipes and shipped meshes."""
    return Path(str(resources.files("aquarom_fenics.meshes")))


def user_cache() -> Path:
    """$XDG_CACHE_HOME/aquarom, default ~/.cache/aquarom."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "aquarom"


def cache_root() -> Path:
    """$AQUAROM_CACHE, else results/cache of the checkout, else the user cache."""
    if os.environ.get("AQUAROM_CACHE"):
        return Path(os.environ["AQUAROM_CACHE"])
    root = checkout()
    return root / "results" / "cache" if root else user_cache() / "results"


def mesh_cache() -> Path:
    """$AQUAROM_CACHE/meshes, else meshes/cache of the checkout, else the user cache's meshes folder."""
    if os.environ.get("AQUAROM_CACHE"):
        return Path(os.environ["AQUAROM_CACHE"]) / "meshes"
    root = checkout()
    return root / "meshes" / "cache" if root else user_cache() / "meshes"


FORMS_CACHE_VARIABLE = "AQUAROM_JIT_CACHE"
"""Environment variable naming the folder of the compiled forms."""


def forms_cache() -> Path:
    """The folder of the compiled forms: $AQUAROM_JIT_CACHE, else FFCx's own default
    $XDG_CACHE_HOME/fenics (~/.cache/fenics), so that forms compiled before are reused."""
    chosen = os.environ.get(FORMS_CACHE_VARIABLE)
    if chosen:
        return Path(chosen).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fenics"


def bench_results() -> Path | None:
    """results/bench of the checkout (measured costs for time estimates), None when installed."""
    root = checkout()
    return root / "results" / "bench" if root else None
