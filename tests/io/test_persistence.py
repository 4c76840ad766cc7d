"""The atomic write and the checksummed get-or-compute every cache uses."""
import errno
import json
import logging

import pytest

from aquarom_fenics.io import persistence
from aquarom_fenics.io.persistence import get_or_compute, is_intact, write_bytes_atomic, write_json_atomic


class Counter:
    """compute() that counts its calls and returns a new value each time."""

    def __init__(self):
        self.calls = 0

    def __call__(self) -> dict:
        self.calls += 1
        return {"value": 1.5, "call": self.calls}


def save(value, path):
    write_json_atomic(path, value)


def load(path):
    return json.loads(path.read_text())


def test_an_entry_is_computed_once_and_then_read_from_the_cache(tmp_path, caplog):
    compute, entry = Counter(), tmp_path / "kind" / "entry.json"
    with caplog.at_level(logging.INFO, logger="aquarom"):
        first = get_or_compute(entry, compute, save, load, label="test cache")
        second = get_or_compute(entry, compute, save, load, label="test cache")
    assert compute.calls == 1 and first == second == {"value": 1.5, "call": 1}
    assert is_intact(entry)
    assert "test cache: built and stored entry.json" in caplog.text
    assert "test cache: reused from the cache (entry.json)" in caplog.text
    assert sorted(p.name for p in entry.parent.iterdir()) == ["entry.json", "entry.json.lock", "entry.json.sha256"]


@pytest.mark.parametrize("damage, reported", [
    (lambda entry: entry.write_text('{"value": 2.5, "call": 1}\n'), "does not match its checksum (corrupted)"),
    (lambda entry: entry.with_name("entry.json.sha256").unlink(), "has no checksum"),
])
def test_a_damaged_entry_is_reported_and_rebuilt(tmp_path, caplog, damage, reported):
    compute, entry = Counter(), tmp_path / "entry.json"
    get_or_compute(entry, compute, save, load)
    damage(entry)
    with caplog.at_level(logging.INFO, logger="aquarom"):
        again = get_or_compute(entry, compute, save, load)
    assert compute.calls == 2 and again["call"] == 2
    assert reported in caplog.text and is_intact(entry)


def test_an_entry_its_loader_refuses_is_rebuilt(tmp_path, caplog):
    compute, entry = Counter(), tmp_path / "entry.json"
    get_or_compute(entry, compute, save, load)

    def refuse(path):
        raise ValueError("old layout")

    with caplog.at_level(logging.WARNING, logger="aquarom"):
        again = get_or_compute(entry, compute, save, refuse, label="test cache")
    assert again["call"] == 2 and "test cache: entry entry.json unusable (old layout)" in caplog.text


def test_a_cache_that_cannot_be_written_gives_the_value_unstored_or_raises(tmp_path):
    (tmp_path / "file").write_text("x")
    entry = tmp_path / "file" / "entry.json"        # its folder cannot be created
    problems = []
    value = get_or_compute(entry, Counter(), save, load, on_store_error=problems.append)
    assert value["call"] == 1 and len(problems) == 1 and isinstance(problems[0], OSError)
    with pytest.raises(OSError):
        get_or_compute(entry, Counter(), save, load)


def test_a_value_kept_out_of_the_cache_is_computed_again(tmp_path):
    compute, entry = Counter(), tmp_path / "entry.json"

    def from_a_later_call(value) -> bool:
        return value["call"] > 1

    assert get_or_compute(entry, compute, save, load, store_if=from_a_later_call)["call"] == 1
    assert not entry.exists()
    assert get_or_compute(entry, compute, save, load, store_if=from_a_later_call)["call"] == 2
    assert get_or_compute(entry, compute, save, load, store_if=from_a_later_call)["call"] == 2 and compute.calls == 2


def test_a_read_only_cache_is_read_without_a_lock(tmp_path, monkeypatch):
    compute, entry = Counter(), tmp_path / "cache" / "entry.json"
    get_or_compute(entry, compute, save, load)
    real_open = open

    def no_lock_files(file, *args, **kwargs):       # what a read-only folder answers
        if str(file).endswith(".lock"):
            raise PermissionError(errno.EACCES, "Permission denied", str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr("builtins.open", no_lock_files)
    assert get_or_compute(entry, compute, save, load)["call"] == 1 and compute.calls == 1
    with pytest.raises(PermissionError):
        persistence.store(entry, lambda path: save({"value": 0.0}, path))


def test_a_failed_atomic_write_names_the_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "out.bin"
    target.write_bytes(b"before")

    def disk_full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(persistence.os, "replace", disk_full)
    with pytest.raises(OSError) as failure:
        write_bytes_atomic(target, b"after")
    assert failure.value.filename == str(target) and failure.value.errno == errno.ENOSPC
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"] and target.read_bytes() == b"before"
