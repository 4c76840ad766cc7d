"""AquaROM-FEniCSx: shape optimisation of soft swimmers with parametric reduced-order models.

Messages go through the logger ``aquarom``: warnings (each distinct one once) on stderr by
default; :func:`set_log_level` shows more (``"info"``: solver set-up, timings) or less.

Importing the package sets environment defaults (a value the user set is kept) so that a run
writes nothing outside its output and the caches, and nothing but its own output on stdout; see
:func:`_third_party_files_in_place`.
"""
from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

__version__ = "0.2.0"

__all__ = ["set_log_level", "__version__"]


class _OncePerMessage(logging.Filter):
    """Lets each distinct warning through once: a study that builds many PROMs does not repeat it."""

    def __init__(self):
        super().__init__()
        self.seen: set[tuple[int, str]] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        key = (record.levelno, record.getMessage())
        if key in self.seen:
            return False
        self.seen.add(key)
        return True


class _Console(logging.StreamHandler):
    """A handler on whatever ``sys.stderr`` is at the time of the message (redirections included)."""

    def __init__(self):
        super().__init__(sys.stderr)
        self.once = _OncePerMessage()
        self.addFilter(self.once)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass


_HANDLER_NAME = "aquarom-console"


def set_log_level(level: str | int = "warning") -> logging.Logger:
    """Show the toolkit's messages from ``level`` up ("debug", "info", "warning", "error" or a
    ``logging`` level) on stderr, each distinct warning once; returns the ``aquarom`` logger.

    Calling it again changes the level and shows every warning once more; the console handler
    is installed once.
    """
    numeric = logging.getLevelName(level.upper()) if isinstance(level, str) else int(level)
    if not isinstance(numeric, int):
        raise ValueError(f"log level {level!r}: use debug, info, warning or error")
    logger = logging.getLogger("aquarom")
    handler = next((h for h in logger.handlers if h.get_name() == _HANDLER_NAME), None)
    if handler is None:
        handler = _Console()
        handler.set_name(_HANDLER_NAME)
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    handler.once.seen.clear()
    handler.setLevel(numeric)
    logger.setLevel(numeric)
    return logger


set_log_level("warning")


def _third_party_files_in_place() -> None:
    """Environment defaults, set before the libraries load, that keep their files out of the user's
    home and the temporary folder, and their bytes out of stdout:

    - ``OMPI_MCA_ess_singleton_isolated=1``: a process not started by mpirun runs as an isolated
      Open MPI singleton, without the daemon whose session folder ($TMPDIR/ompi.<host>.<uid>/pid.<pid>)
      Open MPI 4.1 leaves behind at every exit (it also starts 0.25 s sooner); processes started by
      mpirun are not singletons and ignore it.
    - ``MPLCONFIGDIR``: matplotlib creates its configuration folder ($XDG_CONFIG_HOME/matplotlib,
      default ~/.config/matplotlib) when it is missing; then it is pointed to matplotlib's cache
      folder ($XDG_CACHE_HOME/matplotlib), where matplotlib keeps its font list in any case.
    - ``NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING=1``: in a process started by mpirun, numba's coloured
      error messages start colorama, whose exit hook writes the ANSI reset ESC[0m to stdout after the
      process's last line (a rank that ran a compiled kernel); read at numba's import.
    """
    os.environ.setdefault("OMPI_MCA_ess_singleton_isolated", "1")
    if "MPLCONFIGDIR" not in os.environ:
        config = Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "matplotlib"
        if not config.is_dir():
            os.environ["MPLCONFIGDIR"] = str(Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
                                             / "matplotlib")
    os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")


_third_party_files_in_place()
