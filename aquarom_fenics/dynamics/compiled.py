"""numba for the compiled reduced kernel: its one ``jit`` decorator (cached on disk beside the modules), and whether
numba is there (Debian's python3-numba; without it the batched solves use numpy)."""
from __future__ import annotations

try:
    import numba
except ImportError:          # the numpy engine serves; ``available()`` says which
    numba = None


def jit(function):
    """numba.njit with the kernel's options, cached on disk beside its module (identity without numba)."""
    if numba is None:
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


def available() -> bool:
    """Whether numba can be imported."""
    return numba is not None


KERNEL_MODULES = ("compiled", "kernel_pack", "kernel_terms", "kernel_thrust", "reduced_kernel")
"""The modules of the compiled reduced kernel (``aquarom_fenics/dynamics``)."""


def refresh_stale_cache(folder=None) -> bool:
    """Remove numba's cached kernel when any kernel module changed since it was compiled; True if it did.

    numba keys a cached function on its own file only, and the kernel's entry (``reduced_kernel``) carries
    the machine code of the functions it calls in the sibling modules: a change to one of those alone would
    leave the old code in use. The modules' joint SHA-256 is recorded beside the cache
    (``__pycache__/reduced-kernel.sha256``); when it differs, the cache files numba wrote for these modules
    (``<module>.*.nbi``, ``<module>.*.nbc``) are removed, and the next call compiles. Run by the set-up's warm-up
    (one process), not by the runs that share the cache. ``folder``: the modules' folder (default this one's)."""
    import hashlib
    from pathlib import Path

    folder = Path(__file__).resolve().parent if folder is None else Path(folder)
    digest = hashlib.sha256(b"".join((folder / f"{name}.py").read_bytes() for name in KERNEL_MODULES)).hexdigest()
    cache = folder / "__pycache__"
    stamp = cache / "reduced-kernel.sha256"
    if stamp.is_file() and stamp.read_text().strip() == digest:
        return False
    stale = [path for name in KERNEL_MODULES for suffix in ("nbi", "nbc") for path in cache.glob(f"{name}.*.{suffix}")]
    for path in stale:
        path.unlink(missing_ok=True)
    cache.mkdir(exist_ok=True)
    stamp.write_text(digest + "\n")
    return bool(stale)
