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


def _fingerprint(value):
    """What numba's typing reads of an argument, cheaply: an array's dtype, dimensions, layout (C, F or any, as
    numba tells them), writeability and alignment; a tuple's items; an int whether it fits int64; else the Python
    type (bool and float type by their class alone)."""
    if isinstance(value, tuple):
        return tuple(_fingerprint(item) for item in value)
    flags = getattr(value, "flags", None)
    if flags is not None:
        layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"      # numba's rule
        return value.dtype.str, value.ndim, layout, flags.writeable, flags.aligned
    if type(value) is int:
        return int, -2 ** 63 <= value < 2 ** 63
    return type(value)


class TypedCall:
    """A compiled kernel called without numba's typing of every argument at every call.

    numba's dispatcher types each argument before each call; arrays are typed in C, but a tuple of arrays goes
    through numba's Python ``typeof`` item by item (the reduced kernel's packed tuples: about 0.2-0.3 ms a call, a
    twentieth of one design's run). Here the dispatcher types the first call with a given fingerprint of the
    arguments (:func:`_fingerprint`: what the typing reads), and later calls with the same fingerprint go straight
    to the compiled overload it chose (``CompileResult.entry_point``, what the dispatcher itself calls after
    typing). A new fingerprint goes through the dispatcher again: the compiled code never sees arguments of other
    types than it was compiled for."""

    def __init__(self, dispatcher):
        self.dispatcher = dispatcher
        self._entries: dict = {}

    def __call__(self, *arguments):
        key = _fingerprint(arguments)
        entry = self._entries.get(key)
        if entry is not None:
            return entry(*arguments)
        result = self.dispatcher(*arguments)
        if numba is not None and hasattr(self.dispatcher, "overloads"):
            types = tuple(self.dispatcher.typeof_pyval(argument) for argument in arguments)
            compiled = self.dispatcher.overloads.get(types)
            if compiled is not None and len(self._entries) < 16:
                self._entries[key] = compiled.entry_point
        return result
