"""A virtual X display for off-screen renders on a machine without one.

VTK's X render window needs an X server; a process without ``DISPLAY`` starts its own Xvfb. Left to
pick the first free display number itself (``-displayfd`` alone), two servers started at the same
moment could both take the same number, and a render on the one that lost the socket aborted the
process ("bad X server connection"). So the number is derived from the process id (distinct among
live processes; another one is tried when a server holds it, up to :data:`DISPLAY_ATTEMPTS`), and
the starts are serialised between processes by a lock file of this toolkit's own in the temporary
folder, held until the new server accepts connections.
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
DISPLAY_ATTEMPTS = 8
"""Display numbers tried before giving up."""
START_LOCK = "aquarom-xvfb-start.lock"
"""The lock file's name in the temporary folder (created by this toolkit, never removed)."""


def ensure_display() -> None:
    """Start a virtual X server (Xvfb) once when the process has no display; it stops when the process exits.

    The server gets none of this process's open files: an inherited pipe (MPI's singleton daemon
    holds the process's stdout until every holder of its watch pipe is gone) would keep a caller
    reading our output waiting for as long as the server lives."""
    if os.environ.get("DISPLAY"):
        return
    with _start_lock():
        for attempt in range(DISPLAY_ATTEMPTS):
            number = display_number(os.getpid(), attempt)
            server = _start_server(number)
            if server is not None:
                break
        else:
            raise RuntimeError(f"no display: Xvfb started on none of {DISPLAY_ATTEMPTS} display numbers "
                               "(set DISPLAY, or check that xvfb is installed and works)")
    atexit.register(_end_display, server)
    os.environ["DISPLAY"] = f":{number}"


def display_number(pid: int, attempt: int) -> int:
    """The display tried at ``attempt`` (0, 1, ...) by process ``pid``: 1000 + (pid + 9973 attempt) mod 60000,
    above the numbers desktops and ``xvfb-run`` take."""
    return 1000 + (pid + 9973 * attempt) % 60000


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


def _start_server(number: int) -> subprocess.Popen | None:
    """Xvfb on display ``number`` once it accepts connections; None when it does not start there
    within :data:`XVFB_START_TIMEOUT` (another server holds the number)."""
    read_end, write_end = os.pipe()
    try:
        server = subprocess.Popen(["Xvfb", f":{number}", "-displayfd", str(write_end), "-screen", "0", "1024x768x24",
                                   "-nolisten", "tcp"],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  pass_fds=(write_end,), start_new_session=True)
    except FileNotFoundError:
        raise RuntimeError("no display: DISPLAY is not set and Xvfb is not installed (install xvfb)") from None
    finally:
        os.close(write_end)
    try:
        reported = _read_display_number(read_end, XVFB_START_TIMEOUT)
    finally:
        os.close(read_end)
    if reported != number:
        _stop_server(server)
        return None
    return server


def _end_display(server: subprocess.Popen) -> None:
    """At exit: close every plotter still open (one a Ctrl-C stopped mid-picture), then stop the
    server; a window left on a stopped server makes Xlib end the process with exit code 1
    ("XIO: fatal IO error") instead of the command's own."""
    import sys

    try:
        if "pyvista" in sys.modules:
            sys.modules["pyvista"].close_all()
    finally:
        _stop_server(server)


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
