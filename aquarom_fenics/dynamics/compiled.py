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
