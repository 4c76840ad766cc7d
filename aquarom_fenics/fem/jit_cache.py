"""Where the compiled forms live, and a compile that no interruption can poison.

FFCx (the form compiler behind dolfinx 0.5) keeps one C extension module per form, element or
expression in a cache folder. It claims a module by creating ``<module>.c`` empty with an exclusive
open, compiles, then writes ``<module>.c.cached``; a process that finds the ``.c`` waits 10 s for
the ``.cached`` file and fails. Its clean-up catches ``Exception`` only, so a compile ended by
Ctrl-C, SIGTERM, SIGKILL, a crash or a full disk leaves the ``.c`` behind and every later process
that needs that module fails, on that machine, for good.

Here every compile first takes an exclusive lock (``flock``) on ``<module>.claim`` in the cache
folder. The kernel releases such a lock when its process ends, however it ends, so whoever holds
the claim knows that no live process is compiling the module: files of an unfinished compile found
then are a dead process's leftovers and are removed before FFCx looks. The claim file names the
process holding it, for the message of a process that waits for it (a bounded wait).
"""
from __future__ import annotations

import errno
import fcntl
import importlib.machinery
import logging
import os
import socket
import time
from contextlib import contextmanager
from pathlib import Path

from cffi import VerificationError

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.paths import FORMS_CACHE_VARIABLE as CACHE_VARIABLE

logger = logging.getLogger("aquarom")

WAIT_SECONDS = 600.0
"""The longest wait for another process's compile of the same module [s]."""

POLL_SECONDS = 0.05


class JitCacheError(InputError):
    """The folder of the compiled forms cannot be used (not writable, full, or held too long)."""


def module_files(cache_dir: Path, module: str) -> dict[str, Path]:
    """The files FFCx writes for ``module``: its C source (the claim of FFCx), the mark of a
    finished compile, the extension module, the object file and the mark of a failed compile."""
    return {"source": cache_dir / f"{module}.c", "ready": cache_dir / f"{module}.c.cached",
            "library": cache_dir / f"{module}{importlib.machinery.EXTENSION_SUFFIXES[0]}",
            "object": cache_dir / f"{module}.o", "failed": cache_dir / f"{module}.c.failed"}


def is_complete(cache_dir: Path, module: str) -> bool:
    """Source, extension module and the mark of a finished compile are all there."""
    files = module_files(cache_dir, module)
    return all(files[name].is_file() for name in ("source", "ready", "library"))


def clear_unfinished(cache_dir: Path, module: str) -> list[str]:
    """Remove the files of an unfinished compile of ``module`` (call with its claim held); the
    names removed. A complete module is left alone."""
    if is_complete(cache_dir, module):
        return []
    removed = []
    for path in module_files(cache_dir, module).values():
        try:
            path.unlink()
            removed.append(path.name)
        except FileNotFoundError:
            pass
    return removed


def _unusable(cache_dir: Path, error: OSError) -> JitCacheError:
    reason = os.strerror(error.errno) if error.errno else str(error)
    return JitCacheError(f"the folder of compiled forms {cache_dir} cannot be used ({reason}); "
                         f"set {CACHE_VARIABLE} to a writable folder")


def _holder(claim: int) -> str:
    """Who holds a claim, as its file names it ("process 123 on host"), or "another process"."""
    try:
        text = os.pread(claim, 200, 0).decode("utf-8", "replace").split()
    except OSError:
        return "another process"
    return f"process {text[0]} on {text[1]}" if len(text) >= 2 else "another process"


def _acquire(claim: int, cache_dir: Path, module: str, what: str, wait: float) -> None:
    """Take the exclusive lock of an open claim file, waiting at most ``wait`` seconds."""
    deadline = time.monotonic() + wait
    said = False
    while True:
        try:
            fcntl.flock(claim, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            pass
        if not said:
            logger.info("waiting for %s to finish compiling %s (%s in %s), at most %.0f s",
                        _holder(claim), what, module, cache_dir, wait)
            said = True
        if time.monotonic() > deadline:
            raise JitCacheError(f"waited {wait:.0f} s for {_holder(claim)} to finish compiling {what} "
                                f"({module} in {cache_dir}); stop that process, or set {CACHE_VARIABLE} "
                                "to another folder")
        time.sleep(POLL_SECONDS)


@contextmanager
def claimed(cache_dir: Path, module: str, what: str = "a form", wait: float = WAIT_SECONDS):
    """Hold the claim of ``module`` in ``cache_dir`` while the block compiles or loads it.

    On entry the leftovers of an unfinished compile are removed; on exit too, so that a compile
    this process started and did not finish (an exception, Ctrl-C, SIGTERM) leaves nothing behind.
    A folder that cannot be made or written raises :class:`JitCacheError`.
    """
    cache_dir = Path(cache_dir)
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        claim = os.open(cache_dir / f"{module}.claim", os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as error:
        raise _unusable(cache_dir, error) from None
    try:
        _acquire(claim, cache_dir, module, what, wait)
        try:
            os.ftruncate(claim, 0)
            os.pwrite(claim, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)
            removed = clear_unfinished(cache_dir, module)
        except OSError as error:
            raise _unusable(cache_dir, error) from None
        if removed:
            logger.info("removed an unfinished compile of %s from %s: %s", module, cache_dir, ", ".join(removed))
        try:
            yield
        except OSError as error:
            if error.errno in (errno.ENOSPC, errno.EDQUOT, errno.EACCES, errno.EROFS, errno.EPERM):
                raise _unusable(cache_dir, error) from None
            raise
        except VerificationError as error:      # the C compiler failed (a full disk, no compiler)
            raise JitCacheError(f"compiling {what} ({module}) in {cache_dir} failed: {error}; check the "
                                "free space there and that the C compiler works") from None
        finally:
            clear_unfinished(cache_dir, module)
    finally:
        os.close(claim)          # releases the lock
