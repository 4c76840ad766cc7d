"""SIGTERM handled like Ctrl-C: both end a run between two of its steps, with its partial results.

The command line installs :func:`raise_terminated` for SIGTERM (:func:`sigterm_as_interrupt`), so
a batch system's stop raises :class:`Terminated` (a ``KeyboardInterrupt``) wherever the run is,
and every handler of Ctrl-C handles it too. A time loop that must not stop in the middle of a
step asks :func:`stop_between_steps` instead: while it runs, Ctrl-C and SIGTERM are only
recorded, and the loop ends after its current step.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

from aquarom_fenics.errors import Interrupted, Terminated


def raise_terminated(number, frame):
    """The SIGTERM handler of the command line."""
    raise Terminated("terminated (SIGTERM)")


@contextmanager
def sigterm_as_interrupt():
    """SIGTERM raises :class:`Terminated` while the block runs (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


STOPS = {signal.SIGINT: (Interrupted, "interrupted", "Ctrl-C"), signal.SIGTERM: (Terminated, "terminated", "SIGTERM")}


def stop_for(number: int, where: str) -> Interrupted:
    """The exception that ends a run stopped by signal ``number``: "interrupted at t = … (Ctrl-C)"."""
    kind, verb, name = STOPS[number]
    return kind(f"{verb} {where} ({name})")


@contextmanager
def stop_between_steps():
    """While the block runs, Ctrl-C (when Python's default handler is installed) and SIGTERM (when
    the command line's is) only ask to stop; yields ``requested()``: the first such signal's
    number, or None. Elsewhere (another thread, a caller that ignores Ctrl-C) nothing changes."""
    requested: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    ours = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: raise_terminated}
    previous = {number: signal.getsignal(number) for number in ours}
    deferred = [number for number, handler in ours.items() if previous[number] is handler]
    for number in deferred:
        signal.signal(number, lambda received, frame: requested.append(received))
    try:
        yield lambda: requested[0] if requested else None
    finally:
        for number in deferred:
            signal.signal(number, previous[number])
