"""The code of the Python API page runs as written (on a 0.2 s horizon with two optimiser
iterations, in a temporary folder) and prints what its comments say."""
import re
from pathlib import Path

PAGE = Path(__file__).resolve().parents[1] / "docs" / "user" / "06-python.rst"
SCENE_LINE = 'Scene.load("so1").replace("mesh", level=1)'
SHORT = SCENE_LINE + '.replace("solver", duration=0.2).replace("optimizer", max_iterations=2)'


def python_blocks(text: str) -> list[str]:
    blocks = re.findall(r"\.\. code-block:: python\n\n((?:   .*\n|\n)+)", text)
    return ["\n".join(line[3:] for line in block.splitlines()) for block in blocks]


def test_the_python_page_runs(tmp_path, monkeypatch, capsys):
    blocks = python_blocks(PAGE.read_text())
    assert len(blocks) == 1 and SCENE_LINE in blocks[0]
    monkeypatch.chdir(tmp_path)
    namespace = {}
    exec(compile(blocks[0].replace(SCENE_LINE, SHORT), str(PAGE), "exec"), namespace)
    samples = namespace["fom"].trajectory.arrays()
    assert set(samples) == {"time", "head_x", "tail_y", "tail_x", "com_x", "com_y", "newton_iterations"}
    assert samples["time"][-1] == 0.2 or abs(samples["time"][-1] - 0.2) < 1e-12
    assert namespace["result"].optimum_dict.keys() == {"z_tail", "z_head", "y_thin"}
    assert (tmp_path / "so1-prom.npz").is_file() and (tmp_path / "results" / "my-so1" / "manifest.json").is_file()
    assert len(capsys.readouterr().out.splitlines()) == 4
