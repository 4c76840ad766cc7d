"""AquaROM-FEniCSx: shape optimisation of soft swimmers with parametric reduced-order models.

Messages go through the logger ``aquarom``: warnings (each distinct one once) on stderr by
default; :func:`set_log_level` shows more (``"info"``: solver set-up, timings) or less.
"""
from __future__ import annotations

import logging
import sys

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
