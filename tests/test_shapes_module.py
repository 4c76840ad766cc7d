"""``--shapes-module``: the command line imports the module that registers a scene's own shape
fields before it reads the scene, checks them (``aquarom check``) and refuses, in one line with
exit code 2, a module it cannot import or one that registers nothing the scene uses."""
import pytest

from aquarom_fenics.api import unregister_shape_field
from aquarom_fenics.cli import main
from aquarom_fenics.geometry.shape_registry import registered_fields
from conftest import one_line

FIELDS = '''
import numpy as np
from aquarom_fenics.api import register_shape_field

L = 0.2


def value(X):                     # dz = z (x/L)^2
    U = np.zeros_like(X)
    U[:, 2] = X[:, 2] * (X[:, 0] / L) ** 2
    return U


def gradient(X):
    G = np.zeros((len(X), 3, 3))
    G[:, 2, 0] = {factor} * 2 * X[:, 2] * X[:, 0] / L ** 2
    G[:, 2, 2] = (X[:, 0] / L) ** 2
    return G


register_shape_field("z_taper", value, gradient)
'''

SCENE = """
[mesh]
level = 1
[solver]
duration = 0.1
[shapes]
{name} = {{ bounds = [-0.2, 0.2] }}
"""


@pytest.fixture(autouse=True)
def forget_fields():
    yield
    for name in registered_fields():
        unregister_shape_field(name)


def files(directory, factor=1.0, name="z_taper"):
    module = directory / "my_fields.py"
    module.write_text(FIELDS.format(factor=factor))
    scene = directory / "taper.toml"
    scene.write_text(SCENE.format(name=name))
    return str(scene), str(module)


@pytest.mark.parametrize("factor, code", [(1.0, 0), (1.1, 1)])
def test_check_runs_the_taylor_test_of_a_field_of_the_shapes_module(tmp_path, capsys, factor, code):
    scene, module = files(tmp_path, factor)
    assert main(["check", scene, "--shapes-module", module]) == code
    [row] = [line for line in capsys.readouterr().out.splitlines() if line.startswith("0 ∇U")]
    assert row.startswith("0 ∇U z_taper") and ("PASS" if code == 0 else "FAIL") in row, row


def test_without_the_module_the_field_is_unknown(tmp_path, capsys):
    scene, _ = files(tmp_path)
    assert main(["check", scene]) == 2
    assert "unknown shape variation 'z_taper'" in one_line(capsys)


@pytest.mark.parametrize("command", ["check", "simulate", "optimize", "sweep", "mesh"])
def test_a_module_that_is_not_there_is_one_line(tmp_path, capsys, command):
    scene, _ = files(tmp_path)
    missing = tmp_path / "missing_fields.py"
    assert main([command, scene, "--shapes-module", str(missing)]) == 2
    assert f"--shapes-module {missing}: no such file" in one_line(capsys)


@pytest.mark.parametrize("text, message", [
    ("import numpy as np\nx = 1 +\n", r"importing it failed: SyntaxError: invalid syntax \(line 2\)"),
    ("raise RuntimeError('no data\\nsecond line')\n", r"importing it failed: RuntimeError: no data$"),
    ("from aquarom_fenics.api import register_shape_field\nregister_shape_field('y_thin', abs, abs)\n",
     r"shape field 'y_thin': the name is the catalogue's field y_thin"),
    ("x = 1\n", r"it registers no shape field"),
])
def test_a_module_that_cannot_run_or_registers_nothing_is_one_line(tmp_path, capsys, text, message):
    scene, _ = files(tmp_path)
    module = tmp_path / "bad_fields.py"
    module.write_text(text)
    assert main(["check", scene, "--shapes-module", str(module)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"aquarom check: error: --shapes-module {module}: ")
    assert __import__("re").search(message, line), line
    assert not registered_fields()


def test_a_module_name_that_is_not_there_and_one_the_scene_does_not_use(tmp_path, capsys):
    scene, module = files(tmp_path, name="y_thin")
    assert main(["mesh", scene, "--shapes-module", "no_such_package.fields"]) == 2
    assert "--shapes-module no_such_package.fields: no such module on the Python path" in one_line(capsys)
    assert main(["mesh", scene, "--shapes-module", module]) == 2
    assert (f"--shapes-module {module} registers z_taper; scene {scene} uses none of them ([shapes]: y_thin)"
            in one_line(capsys))


@pytest.mark.mpi
def test_every_mpi_rank_imports_the_module(tmp_path):
    """``aquarom mesh`` builds U on every rank: a rank without the field would refuse the scene."""
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene, module = files(tmp_path)
    completed = subprocess.run(["mpirun", "-n", "2", str(Path(sys.executable).with_name("aquarom")), "mesh", scene,
                                "--shapes-module", module], capture_output=True, text=True, timeout=600, env=os.environ)
    assert completed.returncode == 0, completed.stderr
    assert "cells        1372" in completed.stdout


def test_a_sweep_of_a_registered_field_runs_in_this_process(tmp_path, capsys):
    scene, module = files(tmp_path)
    grid = ["--grid", "z_taper=-0.1:0.1:3", "--shapes-module", module]
    assert main(["sweep", scene, *grid, "--dry-run"]) == 0
    assert "runs on: this process (one worker)" in capsys.readouterr().out
    assert main(["sweep", scene, *grid, "--workers", "2", "--out", str(tmp_path / "sweep")]) == 2
    assert "worker processes started afresh do not import: run its sweep tasks in this process" in one_line(capsys)
    assert not (tmp_path / "sweep").exists()
