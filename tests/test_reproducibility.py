"""Runs stay traceable without git, and `make docker-test` says in one line what it is missing."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]

import pytest

from aquarom_fenics.io.versions import git_commit


DRIVER = REPOSITORY / "scripts" / "docker_test.py"
TOY = "[mesh]\nlevel = 1\n[solver]\nduration = 0.2\n[fluid]\ndrag = false\n"
RUN_CLI = "import sys, aquarom_fenics.cli as cli; print(cli.__file__); sys.exit(cli.main(sys.argv[1:]))"


def unpacked_copy(directory: Path) -> Path:
    """The package laid out as a source archive unpacks it: no .git, forms inside the package."""
    shutil.copytree(REPOSITORY / "aquarom_fenics", directory / "aquarom_fenics",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPOSITORY / "forms", directory / "aquarom_fenics" / "forms",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPOSITORY / "scenes", directory / "scenes")
    return directory


def test_a_copy_outside_any_checkout_writes_a_manifest_with_an_unknown_commit(tmp_path):
    copy = unpacked_copy(tmp_path / "unpacked")
    (tmp_path / "toy.toml").write_text(TOY)
    environment = {name: value for name, value in os.environ.items() if name != "AQUAROM_GIT_COMMIT"}
    completed = subprocess.run([sys.executable, "-c", RUN_CLI, "simulate", "toy.toml", "--model", "rom",
                                "--out", "run"], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                               env=environment | {"PYTHONPATH": str(copy)})
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout.startswith(str(copy))           # the copy ran, not the checkout
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert manifest["git_commit"] == "unknown" and manifest["scene"]["hash"]


def test_without_git_the_commit_is_the_one_the_image_was_built_from_or_unknown(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))                # no git on the PATH
    monkeypatch.delenv("AQUAROM_GIT_COMMIT", raising=False)
    assert git_commit(REPOSITORY) == "unknown"
    monkeypatch.setenv("AQUAROM_GIT_COMMIT", "0123abc")
    assert git_commit(REPOSITORY) == "0123abc"


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_a_copy_inside_another_checkout_does_not_take_that_checkouts_commit(tmp_path, monkeypatch):
    monkeypatch.delenv("AQUAROM_GIT_COMMIT", raising=False)
    git = ["git", "-C", str(tmp_path), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "commit", "-q", "--allow-empty", "-m", "outer"], check=True)
    (tmp_path / "vendored").mkdir()
    assert git_commit(tmp_path / "vendored") == "unknown"
    outer = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    assert git_commit(tmp_path) == outer


def fake_docker(directory: Path, failing: str) -> Path:
    """A `docker` on the PATH that fails the subcommand `failing` and succeeds otherwise."""
    directory.mkdir()
    script = directory / "docker"
    script.write_text(f'#!/bin/sh\n[ "$1" = "{failing}" ] && {{ echo "cannot: $1" >&2; exit 1; }}\nexit 0\n')
    script.chmod(0o755)
    return directory


@pytest.mark.parametrize("failing, message", [("info", "no Docker daemon"), ("image", "debian:bookworm")])
def test_docker_test_without_a_daemon_or_base_image_exits_2_with_one_line(tmp_path, failing, message):
    out = tmp_path / "docker.json"
    path = f"{fake_docker(tmp_path / 'bin', failing)}:{os.environ['PATH']}"
    completed = subprocess.run([sys.executable, str(DRIVER), "--out", str(out)], capture_output=True, text=True,
                               timeout=60, env=os.environ | {"PATH": path})
    assert completed.returncode == 2
    assert completed.stderr.count("\n") == 1 and message in completed.stderr and not completed.stdout
    assert not out.exists()


def test_docker_test_without_the_docker_command_exits_2_with_one_line(tmp_path):
    completed = subprocess.run([sys.executable, str(DRIVER), "--out", str(tmp_path / "docker.json")],
                               capture_output=True, text=True, timeout=60, env=os.environ | {"PATH": str(tmp_path)})
    assert completed.returncode == 2 and completed.stderr.count("\n") == 1 and "docker.io" in completed.stderr
