"""Round three of output safety: what the toolkit reads back is untrusted input.

Manifests name only files inside their folder, lock files are never followed through a link,
--force leaves a user's folders and links alone, a resume continues only the same run, and a
write that fails stops the command with what was written before kept.
"""
import errno
import json
import os
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.io import outputs as outputs_module
from aquarom_fenics.io.output_lock import lock_file_of, lock_output, release_output_locks

from conftest import SHORT_SCENE as SHORT


def write_scene(directory: Path, duration=0.2, extra="", name="scene.toml") -> str:
    path = directory / name
    path.write_text(SHORT.format(duration=duration, extra=extra))
    return str(path)


def one_line(capsys) -> str:
    error = "\n".join(line for line in capsys.readouterr().err.strip().splitlines() if not line.startswith("warning:"))
    assert len(error.splitlines()) == 1 and "Traceback" not in error, error
    return error


def simulate(scene, out, *extra) -> int:
    return main(["simulate", scene, "--out", str(out), "--no-progress", *extra])


def earlier_run(tmp_path: Path, files: dict[str, str]) -> Path:
    """A folder that looks like an earlier run: ``files`` (name: content) and a manifest listing them."""
    out = tmp_path / "run"
    out.mkdir()
    for name, content in files.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(content)
    return out


def set_manifest(folder: Path, files: list[str]) -> None:
    (folder / "manifest.json").write_text(json.dumps({"command": "aquarom simulate", "files": files}))


# ---------------------------------------------------------------------- manifests read back
@pytest.mark.parametrize("named", ["../victim.txt", "ABSOLUTE", "sub/../../victim.txt", "./../victim.txt"])
def test_a_manifest_naming_files_outside_its_folder_deletes_nothing_outside(tmp_path, capsys, named):
    scene = write_scene(tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    out = earlier_run(tmp_path, {"trajectory.csv": "t\n"})
    set_manifest(out, ["trajectory.csv", str(victim) if named == "ABSOLUTE" else named])
    code = simulate(scene, out, "--force")
    assert victim.read_text() == "mine"
    if code != 0:
        assert code == 2 and "manifest" in one_line(capsys)


def test_removing_a_run_folder_never_follows_a_link(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "data.csv").write_text("mine")
    folder = tmp_path / "run.new-1"
    folder.mkdir()
    os.symlink(outside, folder / "link")
    set_manifest(folder, ["link/data.csv"])
    outputs_module.remove_run_folder(folder)
    assert (outside / "data.csv").read_text() == "mine"


def test_force_keeps_a_users_empty_folder_and_symlink(tmp_path, capsys):
    scene = write_scene(tmp_path)
    out = tmp_path / "prev"
    assert simulate(scene, out) == 0
    (out / "my-empty").mkdir()
    (tmp_path / "elsewhere").mkdir()
    os.symlink(tmp_path / "elsewhere", out / "my-link")
    capsys.readouterr()
    assert simulate(scene, out, "--force") == 2
    assert "did not write" in one_line(capsys)
    assert (out / "my-empty").is_dir() and (out / "my-link").is_symlink()
    assert not [p for p in tmp_path.iterdir() if ".new-" in p.name]


def test_files_added_during_the_swap_are_not_called_a_killed_run(tmp_path, caplog, monkeypatch):
    scene = write_scene(tmp_path)
    out = tmp_path / "prev"
    assert simulate(scene, out) == 0
    original = outputs_module._refuse_foreign
    calls = []

    def add_file_after_the_check(path, verb, kept=""):
        original(path, verb, kept)
        calls.append(verb)
        if verb == "now holds":           # the check at the swap passed; a user adds a file at once
            (Path(path) / "late.txt").write_text("mine")

    monkeypatch.setattr(outputs_module, "_refuse_foreign", add_file_after_the_check)
    assert simulate(scene, out, "--force") == 0
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("prev.") and p.is_dir()]
    assert len(kept) == 1 and (kept[0] / "late.txt").read_text() == "mine"
    assert ".new-" not in kept[0].name
    caplog.clear()
    assert simulate(scene, out, "--force") == 0
    assert "was killed" not in caplog.text


# ---------------------------------------------------------------------- lock files
def test_a_lock_file_that_is_a_symlink_is_refused_and_its_target_untouched(tmp_path, capsys):
    scene = write_scene(tmp_path)
    precious = tmp_path / "precious.txt"
    precious.write_text("my thesis")
    out = tmp_path / "run"
    os.symlink(precious, lock_file_of(out))
    assert simulate(scene, out) == 2
    assert "lock file" in one_line(capsys)
    assert precious.read_text() == "my thesis"


def test_a_lock_file_that_is_a_hard_link_or_a_fifo_is_refused(tmp_path):
    precious = tmp_path / "precious.txt"
    precious.write_text("my thesis")
    os.link(precious, lock_file_of(tmp_path / "a"))
    with pytest.raises(InputError, match="lock file"):
        lock_output(tmp_path / "a")
    assert precious.read_text() == "my thesis"
    os.mkfifo(lock_file_of(tmp_path / "b"))
    with pytest.raises(InputError, match="not a regular file"):
        lock_output(tmp_path / "b")
    release_output_locks()


# ---------------------------------------------------------------------- PROM files
@pytest.fixture(scope="module")
def prom_file(tmp_path_factory):
    directory = tmp_path_factory.mktemp("prom")
    scene = write_scene(directory)
    assert main(["build", scene, "--out", str(directory / "p.npz")]) == 0
    return scene, directory / "p.npz"


def rewrite_prom(source: Path, target: Path, edit_header=None, drop: str | None = None) -> Path:
    import numpy as np

    with np.load(source) as data:
        arrays = {key: data[key] for key in data.files}
    header = json.loads(arrays["header"].tobytes().decode())
    if edit_header is not None:
        header = edit_header(header)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    if drop is not None:
        arrays.pop(drop)
    np.savez(target, **arrays)
    return target


def drop_y_thin(header):
    header["shape_names"] = ["z_tail"]
    header["design_point"].pop("y_thin")
    return header


def without(key):
    def edit(header):
        header.pop(key)
        return header
    return edit


@pytest.mark.parametrize("edit, drop, named", [
    (drop_y_thin, None, "shape_names"),
    (lambda header: [header], None, "header"),
    (without("scene_hash"), None, "scene_hash"),
    (without("labels"), None, "labels"),
    (None, "basis", "basis"),
    (None, "elastic.cubic.first", "elastic.cubic.first"),
    (lambda header: header | {"labels": header["labels"][:-1]}, None, "labels"),
])
def test_a_prom_header_is_checked_against_its_arrays(prom_file, tmp_path, capsys, edit, drop, named):
    scene, source = prom_file
    damaged = rewrite_prom(source, tmp_path / "damaged.npz", edit, drop)
    code = main(["simulate", scene, "--model", "prom", "--prom", str(damaged), "--xi", "y_thin=0.02",
                 "--out", str(tmp_path / "run")])
    assert code == 2
    message = one_line(capsys)
    assert "PROM file" in message and named in message
    assert not (tmp_path / "run").exists()
