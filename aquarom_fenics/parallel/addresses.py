"""Dask scheduler addresses and scheduler files, checked before any connection is made.

A malformed address would fail inside ``distributed.Client`` and print a traceback from its
finaliser seconds later; a damaged scheduler file would be a traceback from Dask's own reader.
Only the standard library is used here: the file is read as untrusted input (a regular file of
bounded size, UTF-8 JSON, an object whose ``address`` is a string this module accepts).
"""
from __future__ import annotations

import json
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import read_text_file

SCHEMES = ("tcp", "tls")
"""Dask protocols connected with (ucx:// needs packages that are not installed)."""
MAX_SCHEDULER_FILE_BYTES = 1024 * 1024
"""Largest scheduler file read [bytes] (Dask writes a few hundred)."""
EXAMPLE = "tcp://head-node:8786"


def check_address(address: str, where: str) -> str:
    """A Dask scheduler address ``[tcp://|tls://]host[:port]`` (port in 1 … 65535), returned with its
    protocol (``tcp://`` when none is given); InputError (one line, starting with ``where``) otherwise."""
    if not isinstance(address, str) or not address.strip() or any(c.isspace() or ord(c) < 32 for c in address):
        raise InputError(f"{where}: not a scheduler address; give one such as {EXAMPLE}")
    scheme, separator, rest = address.partition("://")
    if not separator:
        scheme, rest = "tcp", address
    if scheme not in SCHEMES:
        raise InputError(f"{where}: the protocol {scheme}:// is not supported; use "
                         f"{' or '.join(s + '://' for s in SCHEMES)}, e.g. {EXAMPLE}")
    host, colon, port = rest.rpartition(":") if not rest.endswith("]") else (rest, "", "")
    if not colon:
        host, port = rest, ""
    if not host or "/" in host or (colon and not (port.isdigit() and 0 < int(port) < 65536)):
        raise InputError(f"{where}: expected {scheme}://HOST:PORT with a port in 1 … 65535, e.g. {EXAMPLE}")
    return address if separator else f"tcp://{address}"


def scheduler_file_address(path: Path) -> str:
    """The scheduler address in a ``dask scheduler --scheduler-file`` JSON file, checked (a regular
    file of at most :data:`MAX_SCHEDULER_FILE_BYTES`, UTF-8 JSON, an object whose ``address`` is a
    string that :func:`check_address` accepts); InputError (one line) otherwise."""
    where = f"scheduler file {path}"
    remedy = "give the file `dask scheduler --scheduler-file FILE` writes"
    data = _read_json(Path(path), where, remedy)
    if not isinstance(data, dict) or "address" not in data:
        raise InputError(f"{where}: expected a JSON object with an \"address\"; {remedy}")
    address = data["address"]
    if not isinstance(address, str):
        raise InputError(f"{where}: address {address!r:.60}: expected a string; {remedy}")
    return check_address(address, f"{where}: address {address!r}")


def _read_json(path: Path, where: str, remedy: str):
    """The JSON value of ``path``, read as untrusted text (:func:`read_text_file`: a regular file of
    bounded size, UTF-8, arrays and objects nested at most ``files.MAX_NESTING`` deep)."""
    text = read_text_file(path, "scheduler file", MAX_SCHEDULER_FILE_BYTES, remedy, nesting="json")
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as error:
        reason = str(error).splitlines()[0] if str(error) else "nested too deeply"
        raise InputError(f"{where}: not valid JSON ({reason}); {remedy}") from None
