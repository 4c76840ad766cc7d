"""A virtual X display for off-screen renders on a machine without one.

VTK's X render window needs an X server; a process without ``DISPLAY`` starts its own Xvfb. Xvfb's
``-displayfd`` picks the first display number no running server answers on, which is not atomic:
two servers started at the same moment can both take the same number, and a render on the one that
lost the socket aborts the process ("bad X server connection"). The start is therefore serialised
between processes by a lock file of this toolkit's own in the temporary folder, held until the new
server accepts connections.
"""
from __future__ import annotations

import atexit
import fcntl
import os
import select
import subprocess
import tempfile
import time
from pathlib import Path

XVFB_START_TIMEOUT = 10.0
"""Seconds to wait for a virtual X server to accept connections."""
START_LOCK_TIMEOUT = 60.0
"""Seconds to wait for other processes' servers to start before giving up."""
START_LOCK = "aquarom-xvfb-start.lock"
"""The lock file's name in the temporary folder (created by this toolkit, never removed)."""


def ensure_display() -> None:
    """Start a virtual X server (Xvfb) once when the process has no display; it stops when the process exits.

    The server gets none of this process's open files: an inherited pipe (MPI's singleton daemon
    holds the process's stdout until every holder of its watch pipe is gone) would keep a caller
    reading our output waiting for as long as the server lives. It picks a free display number
    itself (``-displayfd``) while this process holds the start lock, so concurrent processes never
    share one."""
    if os.environ.get("DISPLAY"):
        return
    with _start_lock():
        server, number = _start_server()
    atexit.register(_stop_server, server)
    os.environ["DISPLAY"] = f":{number}"


class _start_lock:
    """An exclusive ``flock`` on the start lock, waited for at most :data:`START_LOCK_TIMEOUT` s."""

    def __enter__(self):
        path = Path(tempfile.gettempdir()) / START_LOCK
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
        try:
            self.descriptor = os.open(path, flags, 0o666)
        except OSError as error:
            raise RuntimeError(f"no display: cannot open the start lock {path}: {error.strerror} "
                               "(set DISPLAY)") from None
        deadline = time.monotonic() + START_LOCK_TIMEOUT
        while True:
            try:
                fcntl.flock(self.descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return self
            except BlockingIOError:
                if time.monotonic() > deadline:
                    os.close(self.descriptor)
                    raise RuntimeError(f"no display: other processes held {path} for {START_LOCK_TIMEOUT:g} s "
                                       "while starting Xvfb (set DISPLAY, or retry)") from None
                time.sleep(0.05)

    def __exit__(self, *exc):
        os.close(self.descriptor)          # closing releases the lock


def _start_server() -> tuple[subprocess.Popen, int]:
    """Xvfb on the first free display: (the server, its display number) once it accepts connections."""
    read_end, write_end = os.pipe()
    try:
        server = subprocess.Popen(["Xvfb", "-displayfd", str(write_end), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  pass_fds=(write_end,), start_new_session=True)
    except FileNotFoundError:
        raise RuntimeError("no display: DISPLAY is not set and Xvfb is not installed (install xvfb)") from None
    finally:
        os.close(write_end)
    try:
        number = _read_display_number(read_end, XVFB_START_TIMEOUT)
    finally:
        os.close(read_end)
    if number is None:
        _stop_server(server)
        raise RuntimeError(f"no display: Xvfb did not report a display within {XVFB_START_TIMEOUT:g} s "
                           "(set DISPLAY, or install xvfb)")
    return server, number


def _read_display_number(read_end: int, timeout: float) -> int | None:
    """The display number Xvfb writes on ``read_end`` when it accepts connections, or None."""
    deadline = time.monotonic() + timeout
    text = b""
    while not text.endswith(b"\n"):
        remaining = deadline - time.monotonic()
        if remaining <= 0 or not select.select([read_end], [], [], remaining)[0]:
            return None
        chunk = os.read(read_end, 16)
        if not chunk:            # the server exited before it was ready
            return None
        text += chunk
    return int(text)


def _stop_server(server: subprocess.Popen) -> None:
    """SIGTERM (the server removes its socket), SIGKILL after 5 s."""
    if server.poll() is not None:
        return
    server.terminate()
    try:
        server.wait(timeout=5.0)
    except subprocess.TimeoutExpired:
        server.kill()
        server.wait()
