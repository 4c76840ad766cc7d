"""numba for the compiled kernels (the reduced dynamics' and the internal force's pair products): their one ``jit``
decorator, cached on disk beside the decorated function's module, and whether numba is there (Debian's
python3-numba; without it each kernel's numpy path serves)."""
from __future__ import annotations

try:
    import numba
except ImportError:          # the numpy paths serve; ``available()`` says which
    numba = None


def jit(function):
    """numba.njit with the kernels' options, cached on disk beside its module (identity without numba)."""
    if numba is None:
        return function
    return numba.njit(cache=True, nogil=True, error_model="numpy")(function)


def available() -> bool:
    """Whether numba can be imported."""
    return numba is not None
