"""Files read as untrusted input: regular files of bounded size only, text decoded and bounded here.

Every reader of a file the user gives or the toolkit wrote earlier (scenes, summaries,
checkpoints, manifests, CSV tables, scheduler files) goes through :func:`read_text_file`, so the
same trouble reads the same in one line, ``WHAT PATH: reason[; remedy]``: not found, a link that
leads nowhere, a folder, a FIFO or device, too large, unreadable, not UTF-8, a NUL byte, nested
too deeply.
"""
from __future__ import annotations

import errno
import stat
from pathlib import Path

from aquarom_fenics.errors import InputError

MAX_NESTING = 64
"""Deepest nesting of arrays and tables (objects) read from a text file: the toolkit's files need
fewer than 10, a scene 3; deeper text would exhaust the parsers' recursion."""


def is_regular_file(path: Path) -> bool:
    """Whether ``path`` is a regular file (or a link to one); False for any path the OS refuses
    (a name too long, a file where a folder should be, a link loop)."""
    try:
        return stat.S_ISREG(Path(path).stat().st_mode)
    except (OSError, ValueError):
        return False


def require_regular_file(path: Path, what: str, max_bytes: int, remedy: str = "") -> None:
    """Refuse (InputError, one line: ``what path: reason[; remedy]``) anything but a regular file of
    at most ``max_bytes``: a FIFO, a device such as /dev/zero, a folder or a symbolic-link loop is
    refused before it is opened (a FIFO would block the reader, a device never ends)."""
    def refuse(reason: str):
        return InputError(f"{what} {path}: {reason}{f'; {remedy}' if remedy else ''}")

    try:
        details = Path(path).stat()
    except FileNotFoundError:
        raise refuse("a symbolic link that leads to no file (a loop or a missing target)"
                     if Path(path).is_symlink() else "not found") from None
    except OSError as error:          # a link loop, a name too long, no permission
        if error.errno == errno.ELOOP:
            raise refuse("a symbolic link that leads to no file (a loop or a missing target)") from None
        raise refuse(f"cannot be read ({error.strerror})") from None
    if stat.S_ISDIR(details.st_mode):
        raise refuse("a folder, not a file")
    if not stat.S_ISREG(details.st_mode):
        raise refuse("not a regular file (a FIFO, socket or device); give a file")
    if details.st_size > max_bytes:
        raise refuse(f"{details.st_size / 2**20:.0f} MB, larger than the {max_bytes / 2**20:.0f} MB such a file may have")


def read_text_file(path: Path, what: str, max_bytes: int, remedy: str = "", nesting: str | None = None) -> str:
    """The text of the UTF-8 file ``path`` (a leading byte-order mark dropped), read only if it is a
    regular file of at most ``max_bytes`` (:func:`require_regular_file`); a file that is not UTF-8,
    holds a NUL byte or (``nesting`` = ``"json"`` or ``"toml"``) nests arrays and tables deeper than
    :data:`MAX_NESTING` is one InputError line ``what path: reason[; remedy]`` naming where."""
    hint = f"; {remedy}" if remedy else ""
    require_regular_file(path, what, max_bytes, remedy)
    try:
        with open(path, "rb") as stream:
            data = stream.read(max_bytes + 1)          # a file that grew since its size was checked stays bounded
    except OSError as error:
        raise InputError(f"{what} {path}: cannot be read ({error.strerror}){hint}") from None
    if len(data) > max_bytes:
        raise InputError(f"{what} {path}: larger than the {max_bytes / 2**20:.0f} MB such a file may have{hint}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise InputError(f"{what} {path}: not UTF-8 text (byte 0x{data[error.start]:02x} at "
                         f"{_place(data, error.start)}){hint}") from None
    if "\0" in text:
        raise InputError(f"{what} {path}: not a text file (a NUL byte at {_place(data, data.index(0))}){hint}")
    if nesting is not None and nesting_depth(text, nesting) > MAX_NESTING:
        raise InputError(f"{what} {path}: arrays or tables nested deeper than {MAX_NESTING} levels{hint}")
    return text.removeprefix("\ufeff")


def _place(data: bytes, offset: int) -> str:
    """``line L, column C`` of the byte at ``offset`` (both from 1; the column counts bytes)."""
    line = data.count(b"\n", 0, offset) + 1
    column = offset - (data.rfind(b"\n", 0, offset) + 1) + 1
    return f"line {line}, column {column}"


def nesting_depth(text: str, syntax: str) -> int:
    """Upper bound of how deeply arrays and tables nest in ``syntax`` (``"json"`` or ``"toml"``) text:
    brackets and braces counted outside strings (and TOML's ``'`` strings and ``#`` comments)."""
    quotes, comments = ('"', False) if syntax == "json" else ("\"'", True)
    depth = deepest = 0
    quote = None
    comment = escaped = False
    for character in text:
        if comment:
            comment = character != "\n"
        elif quote:
            if escaped:
                escaped = False
            elif character == "\\" and quote == '"':
                escaped = True
            elif character == quote:
                quote = None
        elif character in quotes:
            quote = character
        elif character == "#" and comments:
            comment = True
        elif character in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif character in "]}":
            depth = max(depth - 1, 0)
    return deepest
