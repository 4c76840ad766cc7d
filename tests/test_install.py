"""The package installs from a wheel and runs outside the checkout: shipped scenes and mesh
recipes are package data, caches go to the user's cache folder."""
import json
import os
import subprocess
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]


def run(command, **options):
    return subprocess.run(command, capture_output=True, text=True, timeout=600, **options)


def test_wheel_installs_into_a_fresh_environment_and_simulates_from_another_folder(tmp_path):
    built = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w",
                 str(tmp_path / "dist"), str(REPOSITORY)])
    assert built.returncode == 0, built.stderr
    wheel = next((tmp_path / "dist").glob("aquarom_fenics-*.whl"))
    environment = tmp_path / "env"          # a fresh environment; this pip installs into it
    assert run(["/usr/bin/python3", "-m", "venv", "--without-pip", "--system-site-packages",
                str(environment)]).returncode == 0
    installed = run([sys.executable, "-m", "pip", "--python", str(environment / "bin" / "python"), "install",
                     "--no-deps", str(wheel)])
    assert installed.returncode == 0, installed.stderr

    elsewhere = tmp_path / "work"
    elsewhere.mkdir()
    variables = {key: value for key, value in os.environ.items() if key != "AQUAROM_CACHE"}
    variables["XDG_CACHE_HOME"] = str(tmp_path / "user-cache")
    simulated = run([str(environment / "bin" / "aquarom"), "simulate", "nominal", "--level", "1",
                     "--out", "nominal", "--set", "solver.duration=0.4"], cwd=elsewhere, env=variables)
    assert simulated.returncode == 0, simulated.stderr
    summary = json.loads((elsewhere / "nominal" / "summary.json").read_text())
    assert summary["completed"] and summary["distance"] > 0.0
    assert list((tmp_path / "user-cache" / "aquarom" / "meshes").glob("block_level1_*.npz"))
    package = run([str(environment / "bin" / "python"), "-c",
                   "import aquarom_fenics, pathlib; print(pathlib.Path(aquarom_fenics.__file__).parent)"],
                  cwd=elsewhere)
    assert str(environment) in package.stdout          # the installed copy ran, not the checkout
    fish = run([str(environment / "bin" / "aquarom"), "mesh", "fish"], cwd=elsewhere, env=variables)
    assert fish.returncode == 0, fish.stderr          # the shipped fish's mesh is package data beside its scene
    assert "fish_l1.msh" in fish.stdout and str(environment) in fish.stdout and "(tagged)" in fish.stdout
