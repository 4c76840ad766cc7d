"""The compiled reduced kernel's modules and their numba cache; its ``jit`` decorator, ``available`` and ``TypedCall``
are those of :mod:`aquarom_fenics.machine_code` (one for every compiled kernel)."""
from __future__ import annotations

from aquarom_fenics.machine_code import TypedCall, available, jit  # noqa: F401  (the kernel modules' imports)


KERNEL_MODULES = ("compiled", "kernel_pack", "kernel_terms", "kernel_thrust", "reduced_kernel", "lane_values",
                  "kernel_lanes", "kernel_lanes_thrust", "lane_lu", "lockstep_kernel", "kernel_adjoint")
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
