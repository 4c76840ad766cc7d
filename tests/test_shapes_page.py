"""The shape page: its table of the fields on a tapered ellipsoid is what scripts/shapes_on_body.py
measures, and its "Your own shape field" code runs as written (on a 0.1 s horizon) and prints what
its comments say."""
import re
import sys
from pathlib import Path

from aquarom_fenics.api import unregister_shape_field

REPOSITORY = Path(__file__).resolve().parents[1]
PAGE = REPOSITORY / "docs" / "user" / "05-shapes.rst"


def python_blocks(text: str) -> list[str]:
    blocks = re.findall(r"\.\. code-block:: python\n\n((?:   .*\n|\n)+)", text)
    return ["\n".join(line[3:] for line in block.splitlines()) for block in blocks]


def test_the_table_on_a_tapered_ellipsoid_is_the_scripts():
    sys.path.insert(0, str(REPOSITORY / "scripts"))
    try:
        import shapes_on_body
    finally:
        sys.path.remove(str(REPOSITORY / "scripts"))
    text = PAGE.read_text()
    start = text.index(".. shapes-on-body table:")
    start = text.index("\n\n", start) + 2
    end = text.index("\n.. end of the shapes-on-body table")
    assert text[start:end] == shapes_on_body.table()


def test_your_own_shape_field_runs(capsys):
    [block] = python_blocks(PAGE.read_text())
    assert '"duration": 2.0' in block
    namespace = {}
    try:
        exec(compile(block.replace('"duration": 2.0', '"duration": 0.1'), str(PAGE), "exec"), namespace)
    finally:
        unregister_shape_field("z_hump")
    lines = capsys.readouterr().out.splitlines()
    assert lines[:2] == ["0 ∇U z_hump PASS 2.00", "0 ∇U y_thin PASS "]
    assert namespace["fom"].completed and float(lines[2]) == namespace["fom"].distance != 0.0
