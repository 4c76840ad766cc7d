"""One reader of untrusted text files: a scene (TOML), a file read back (JSON, CSV), a --designs
table and a scheduler file say the same about the same trouble, in one line naming the file."""
import os
from pathlib import Path

import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.files import MAX_NESTING, nesting_depth, read_text_file
from aquarom_fenics.io.readback import load_run_summary, load_trajectory
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.parallel.addresses import scheduler_file_address

READERS = {
    "scene": (Scene.load, "scene", ".toml"),
    "run summary": (load_run_summary, "run summary", ".json"),
    "trajectory": (load_trajectory, "trajectory", ".csv"),
    "scheduler file": (scheduler_file_address, "scheduler file", ".json"),
}
DEEP = {".toml": "a = " + "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1) + "\n",
        ".json": '{"completed": ' + "[" * (MAX_NESTING + 1) + "]" * (MAX_NESTING + 1) + "}"}


def troubled_file(tmp_path: Path, trouble: str, suffix: str) -> Path:
    """A path of ``suffix`` with ``trouble``: what every reader must refuse in the same words."""
    path = tmp_path / f"input{suffix}"
    if trouble == "missing":
        return path
    if trouble == "folder":
        path.mkdir()
    elif trouble == "not a folder above":
        (tmp_path / "plain").write_text("x")
        return tmp_path / "plain" / f"input{suffix}"
    elif trouble == "name too long":
        return tmp_path / ("n" * 300 + suffix)
    elif trouble == "dangling link":
        path.symlink_to(tmp_path / "gone")
    elif trouble == "link loop":
        path.symlink_to(path)
    elif trouble == "fifo":
        os.mkfifo(path)
    elif trouble == "not UTF-8":
        path.write_bytes(b'name = "ok"\n\xff\xfe\n')
    elif trouble == "NUL byte":
        path.write_bytes(b"a\x00b\n")
    elif trouble == "too deep":
        path.write_text(DEEP[suffix])
    return path


def reason(message: str, kind: str, path: Path) -> str:
    """The reason of ``KIND PATH: reason[; remedy]``, the kind and path checked."""
    assert message.startswith(f"{kind} {path}: ") and "\n" not in message, message
    return message.removeprefix(f"{kind} {path}: ").split("; ")[0]


def refusal(tmp_path: Path, reader: str, trouble: str) -> str:
    load, kind, suffix = READERS[reader]
    folder = tmp_path / reader.replace(" ", "_")
    folder.mkdir()
    path = troubled_file(folder, trouble, suffix)
    with pytest.raises(InputError) as raised:
        load(path)
    return reason(str(raised.value), kind, path).replace(str(folder), "FOLDER")


TROUBLES = {"missing": "not found", "folder": "a folder, not a file", "not a folder above": "cannot be read",
            "name too long": "cannot be read", "dangling link": "a symbolic link that leads to no file",
            "link loop": "a symbolic link that leads to no file", "fifo": "not a regular file",
            "not UTF-8": "not UTF-8 text (byte 0xff at line 2, column 1)", "NUL byte": "a NUL byte at line 1, column 2"}


@pytest.mark.parametrize("trouble", list(TROUBLES))
def test_every_reader_gives_the_same_line_for_the_same_trouble(tmp_path, trouble):
    reasons = {reader: refusal(tmp_path, reader, trouble) for reader in READERS}
    assert len(set(reasons.values())) == 1, reasons
    assert TROUBLES[trouble] in reasons["scene"]


def test_the_toml_and_json_readers_refuse_the_same_nesting(tmp_path):
    reasons = {reader: refusal(tmp_path, reader, "too deep") for reader in ("scene", "run summary", "scheduler file")}
    assert set(reasons.values()) == {f"arrays or tables nested deeper than {MAX_NESTING} levels"}, reasons


def test_nesting_is_counted_outside_strings_and_comments():
    assert nesting_depth('a = [[1], "[[[", \'[[[\'] # [[[[\n', "toml") == 2
    assert nesting_depth('{"a": ["]]]\\"[[[", [[]]]}', "json") == 4
    assert nesting_depth("a = ']]]]' [[[", "toml") == 3


def test_a_file_that_grew_past_its_bound_after_the_check_is_refused(tmp_path, monkeypatch):
    path = tmp_path / "t.txt"
    path.write_text("x" * 100)
    monkeypatch.setattr("aquarom_fenics.files.require_regular_file", lambda *args: None)
    with pytest.raises(InputError, match="larger than"):
        read_text_file(path, "table", 50)


def test_a_byte_order_mark_is_dropped(tmp_path):
    path = tmp_path / "t.toml"
    path.write_bytes("\ufeffname = 'x'\n".encode())
    assert read_text_file(path, "scene", 1000, nesting="toml") == "name = 'x'\n"
