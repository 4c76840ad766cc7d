"""What the commands say on the console: `build` says whether its PROM was built or reused from the
cache and names a basis vector it left out; `--no-progress` is accepted by every command that runs
a FOM or reports progress, and turns progress off for the command's run only."""
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.cli.parser import build_parser
from aquarom_fenics.dynamics import simulate

SCENE = """
[mesh]
level = 1
[solver]
duration = 0.1
[shapes]
z_tail = { bounds = [-0.2, 0.2] }
y_thin = { bounds = [-0.1, 0.1] }
"""

PROGRESS_COMMANDS = ("simulate", "compare", "build", "optimize", "pareto", "sweep")


def write_scene(directory: Path) -> Path:
    path = directory / "scene.toml"
    path.write_text(SCENE)
    return path


def test_build_says_built_then_reused_from_the_cache(tmp_path, capsys):
    scene = str(write_scene(tmp_path))
    assert main(["build", scene, "--out", str(tmp_path / "first.npz"), "--no-progress"]) == 0
    first = capsys.readouterr().out
    assert "; built in " in first and "reused" not in first
    assert main(["build", scene, "--out", str(tmp_path / "second.npz"), "--no-progress"]) == 0
    second = capsys.readouterr().out
    assert "; reused from the PROM cache (built there in " in second and "; built in " not in second
    assert first.split("; ")[0] == second.split("; ")[0]         # the same basis, m and p


def test_build_names_a_basis_vector_it_left_out(tmp_path, capsys):
    """SO1's z_head variation leaves the nominal basis's xi_1_2 a combination of the others."""
    assert main(["build", "so1", "--level", "1", "--out", str(tmp_path / "so1.npz")]) == 0
    line = capsys.readouterr().out
    assert "p = 3; left out: xi_1_2 (a numerical combination of the others" in line
    assert "xi_1_2" not in line.split("left out")[0]


@pytest.mark.parametrize("command", PROGRESS_COMMANDS)
def test_every_command_with_progress_accepts_no_progress(command):
    arguments = [command, "so1", "--no-progress"] + (["--samples", "2"] if command == "sweep" else [])
    assert build_parser().parse_args(arguments).no_progress is True


def test_no_progress_turns_the_fom_bars_off_for_the_run_only(tmp_path, capsys, monkeypatch):
    seen = []
    original = simulate._progress_bar

    def recording(total, label, enabled):
        bar = original(total, label, enabled)
        seen.append(simulate.PROGRESS_BARS["shown"])
        return bar

    monkeypatch.setattr(simulate, "_progress_bar", recording)
    scene = str(write_scene(tmp_path))
    assert main(["simulate", scene, "--out", str(tmp_path / "quiet"), "--no-progress"]) == 0
    assert main(["simulate", scene, "--out", str(tmp_path / "shown")]) == 0
    assert seen == [False, True] and simulate.PROGRESS_BARS["shown"] is True
    with simulate.progress_bars(False):
        assert simulate._progress_bar(10, "FOM", True) is None


def test_a_sweep_without_progress_prints_no_line_per_design(tmp_path, capsys):
    scene = str(write_scene(tmp_path))
    arguments = ["sweep", scene, "--grid", "z_tail=0:0.1:2", "--model", "prom", "--workers", "1"]
    assert main(arguments + ["--out", str(tmp_path / "lines")]) == 0
    assert "[1/2] design" in capsys.readouterr().out
    assert main(arguments + ["--out", str(tmp_path / "quiet"), "--no-progress"]) == 0
    quiet = capsys.readouterr().out
    assert "design 0" not in quiet and "sweep of scene: 2 designs" in quiet
