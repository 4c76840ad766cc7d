"""Files read back checked before they are opened: regular files of bounded size only."""
from __future__ import annotations

import stat
from pathlib import Path

from aquarom_fenics.errors import InputError


def require_regular_file(path: Path, what: str, max_bytes: int, remedy: str = "") -> None:
    """Refuse (InputError, one line: ``what path: reason[; remedy]``) anything but a regular file of
    at most ``max_bytes``: a FIFO, a device such as /dev/zero, a folder or a symbolic-link loop is
    refused before it is opened (a FIFO would block the reader, a device never ends)."""
    hint = f"; {remedy}" if remedy else ""
    try:
        details = Path(path).stat()
    except FileNotFoundError:
        raise InputError(f"{what} {path}: not found{hint}") from None
    except OSError as error:          # a link loop, a name too long, no permission
        raise InputError(f"{what} {path}: cannot be read ({error.strerror}){hint}") from None
    if stat.S_ISDIR(details.st_mode):
        raise InputError(f"{what} {path}: a folder, not a file{hint}")
    if not stat.S_ISREG(details.st_mode):
        raise InputError(f"{what} {path}: not a regular file (a FIFO, socket or device); give a file{hint}")
    if details.st_size > max_bytes:
        raise InputError(f"{what} {path}: {details.st_size / 2**20:.0f} MB, larger than the "
                         f"{max_bytes / 2**20:.0f} MB such a file may have{hint}")
