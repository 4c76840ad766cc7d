"""The manual's worked example (docs/your_own_swimmer.md): scripts/example_own_swimmer.py writes a
.msh with plain gmsh that a scene reads with its regions, axis and dorsal line."""
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from aquarom_fenics.cli import main
from aquarom_fenics.geometry.mesh import signed_cell_volumes
from aquarom_fenics.geometry.mesh_files import read_mesh

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "example_own_swimmer.py"


def test_example_script_makes_a_mesh_a_scene_swims_with(tmp_path, capsys):
    path = tmp_path / "my_swimmer.msh"
    subprocess.run([sys.executable, str(SCRIPT), str(path)], check=True, capture_output=True, timeout=600)
    mesh = read_mesh(path)
    assert set(mesh.regions) == {"head", "left_muscle", "right_muscle", "body"}
    volumes = np.abs(signed_cell_volumes(mesh.points, mesh.cells))
    assert sum(volumes[cells].sum() for cells in mesh.regions.values()) == volumes.sum()     # a partition
    centroids = mesh.points[mesh.cells].mean(axis=1)
    assert np.all(centroids[mesh.regions["left_muscle"], 1] > 0) and np.all(centroids[mesh.regions["right_muscle"], 1] < 0)
    assert np.all(centroids[mesh.regions["head"], 0] > -0.06)
    scene = tmp_path / "my_swimmer.toml"
    scene.write_text(textwrap.dedent("""
        name = "my_swimmer"
        description = "the manual's example"
        [mesh]
        file = "my_swimmer.msh"
        [regions]
        head = "head"
        muscles = ["left_muscle", "right_muscle"]
    """))
    assert main(["mesh", str(scene)]) == 0
    printed = capsys.readouterr().out
    assert "(tagged)" in printed and "length 0.2 m along x" in printed
