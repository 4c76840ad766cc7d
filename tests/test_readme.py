"""The README and the manual say what the code does: the manual builds without a warning, every
TOML snippet loads, the scene keys table is the code's, every shell command runs (the README's
walkthrough for real on a short horizon, every other ``aquarom`` command as a dry run at mesh
level 1) or is marked as not runnable here, and every link of the README leads to a file."""
import dataclasses
import os
import re
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.cli.parser import build_parser
from aquarom_fenics.io.scene import SECTIONS, scene_from_dict

REPOSITORY = Path(__file__).resolve().parents[1]
DOCS = REPOSITORY / "docs"
README = (REPOSITORY / "README.md").read_text()
USER_GUIDE = sorted((DOCS / "user").glob("*.rst"))
NOT_RUN = "# not run by the tests:"
SHORT_RUN = ["--set", "solver.duration=0.2", "--set", "optimizer.max_iterations=2"]
"""Appended to the walkthrough's commands: a 0.2 s horizon and two optimiser iterations."""

sys.path.insert(0, str(DOCS))
from generate import key_tables, scene_key_rows  # noqa: E402  (docs/generate.py makes the keys table)


def console_blocks(text: str, markdown: bool) -> list[list[str]]:
    """The commands ($ lines) of every console block of a Markdown or reStructuredText page."""
    if markdown:
        blocks = re.findall(r"```console\n(.*?)```", text, flags=re.S)
    else:
        blocks = re.findall(r"\.\. code-block:: console\n\n((?:   .*\n|\n)+)", text)
    return [[line.strip()[2:] for line in block.splitlines() if line.strip().startswith("$ ")] for block in blocks]


def documented_commands() -> list[tuple[str, str]]:
    """(page, command) of every shell command in the README and the user guide."""
    commands = [("README.md", line) for block in console_blocks(README, markdown=True) for line in block]
    for page in USER_GUIDE:
        commands += [(page.name, line) for block in console_blocks(page.read_text(), markdown=False) for line in block]
    return commands


def aquarom_arguments(command: str) -> list[str] | None:
    """The arguments of an ``aquarom`` command (``mpirun -n N`` and ``.venv/bin/`` dropped), else None."""
    words = shlex.split(command, comments=True)
    if words[:1] == ["mpirun"]:
        words = words[3:]
    if not words or Path(words[0]).name != "aquarom":
        return None
    return words[1:]


def test_readme_is_a_short_front_page():
    assert len(README.splitlines()) <= 200
    assert "make demo" in README and "make test" in README


def test_every_link_of_the_readme_leads_to_a_file():
    links = re.findall(r"\]\(([^)#]+)\)", README)
    assert links
    missing = [link for link in links if not link.startswith("http") and not (REPOSITORY / link).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_the_manual_builds_without_a_warning(tmp_path):
    """``make docs`` in short: every page, the generated ones and the API from the docstrings."""
    completed = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "dummy",
                                str(DOCS), str(tmp_path / "build")], capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr[-3000:]


def toml_snippets() -> list[str]:
    snippets = re.findall(r"```toml\n(.*?)```", README, flags=re.S)
    for page in USER_GUIDE:
        for block in re.findall(r"\.\. code-block:: toml\n\n((?:   .*\n|\n)+)", page.read_text()):
            snippets.append("\n".join(line[3:] for line in block.splitlines()))
    return snippets


def test_the_user_guide_has_toml_snippets():
    assert len(toml_snippets()) >= 2


@pytest.mark.parametrize("snippet", toml_snippets())
def test_every_toml_snippet_loads(snippet):
    scene = scene_from_dict(tomllib.loads(snippet), source="docs")
    assert scene.to_dict()


def test_the_keys_table_names_every_key_of_the_code_with_its_default():
    rows = scene_key_rows()
    documented = {(section, key) for section, key, _, _ in rows}
    tables = key_tables()
    assert set(SECTIONS) | {"cluster"} <= set(tables)
    for section, cls in tables.items():
        for field in dataclasses.fields(cls):
            assert (section, field.name) in documented, f"[{section}] {field.name} is missing from the table"
    for section, key, default, meaning in rows:
        assert meaning, f"[{section}] {key} has no meaning in the table"
        scene = scene_from_dict(tomllib.loads(f"[{section}]\n{key} = {default}\n"), source="docs")
        field = next(f for f in dataclasses.fields(tables[section]) if f.name == key)
        assert getattr(getattr(scene, section), key) == field.default, (section, key, default)


def test_layout_page_names_every_package_folder_and_only_existing_paths():
    """The layout table and the folder tree agree (caches are made by runs, not tracked)."""
    layout = (DOCS / "layout.md").read_text()
    named = set(re.findall(r"`([\w./-]+/)`", layout))
    folders = {f"aquarom_fenics/{path.parent.name}/" for path in (REPOSITORY / "aquarom_fenics").glob("*/__init__.py")}
    assert folders <= named, f"package folders missing from the layout page: {sorted(folders - named)}"
    missing = [path for path in re.findall(r"`([\w./-]+)`", layout)
               if "/" in path and not path.endswith("cache/") and not (REPOSITORY / path).exists()]
    assert not missing, f"the layout page names paths that do not exist: {missing}"


def test_every_documented_command_is_an_aquarom_command_or_marked_not_runnable():
    commands = documented_commands()
    assert len(commands) >= 20
    for page, command in commands:
        if NOT_RUN in command:
            assert command.split(NOT_RUN, 1)[1].strip(), f"{page}: say why `{command}` is not run"
        else:
            assert aquarom_arguments(command) is not None, f"{page}: `{command}` is neither run nor marked"


def dry_run(arguments: list[str]) -> list[str]:
    """The command as a dry run at mesh level 1 (as written when it has no dry run)."""
    parser = build_parser()
    parsed = parser.parse_args(arguments)        # every documented command parses
    if not hasattr(parsed, "dry_run"):
        return arguments
    return arguments + (["--level", "1"] if parsed.level is None else []) + ["--dry-run"]


@pytest.mark.parametrize("page, command", [(page, command) for page, command in documented_commands()
                                           if NOT_RUN not in command and page != "README.md"])
def test_every_command_of_the_user_guide_runs_as_a_dry_run(page, command, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    arguments = aquarom_arguments(command)
    if arguments[0] == "animate":
        build_parser().parse_args(arguments)     # needs a run: the walkthrough animates one for real
        return
    assert main(dry_run(arguments)) == 0, f"{page}: {command}"


def test_the_readme_walkthrough_runs_at_level_1(tmp_path, monkeypatch, capsys):
    """The README's commands in order, for real, on a 0.2 s horizon with two optimiser iterations."""
    monkeypatch.chdir(tmp_path)
    commands = [command for page, command in documented_commands() if page == "README.md" and NOT_RUN not in command]
    assert [aquarom_arguments(c)[0] for c in commands] == ["mesh", "simulate", "build", "compare", "optimize",
                                                           "animate", "shapes"]
    for command in commands:
        arguments = aquarom_arguments(command)
        if arguments[0] != "animate":
            arguments += SHORT_RUN + (["--no-progress"] if arguments[0] in ("simulate", "compare", "build",
                                                                            "optimize") else [])
        assert main(arguments) == 0, command
    for output in ("results/so1-fom/trajectory.csv", "results/so1-prom.npz", "results/so1-compare/compare.json",
                   "results/so1-opt/summary.json", "results/so1-fom/animation.gif",
                   "results/so1-optimum/design.xdmf"):
        assert (tmp_path / output).exists(), output
    assert "FOM check: start" in capsys.readouterr().out


def test_make_docs_is_a_target():
    makefile = (REPOSITORY / "Makefile").read_text()
    assert re.search(r"^docs: setup\n\t.*sphinx -W", makefile, flags=re.M)
    assert "python3-sphinx" in (REPOSITORY / "scripts" / "setup.sh").read_text()
    assert os.path.exists(DOCS / "conf.py")


def test_the_validation_report_is_shown_with_its_figures_and_data_paths(tmp_path):
    from generate import report_page

    results, folder = tmp_path / "results", tmp_path / "generated"
    assert "make validate" in report_page(results, folder)
    (results / "validation").mkdir(parents=True)
    (results / "validation" / "mesh.png").write_bytes(b"png")
    (results / "REPORT.md").write_text("# Report\n\n![mesh](validation/mesh.png)\n\n"
                                       "[cases](validation/cases.json) and ![gone](validation/gone.png)\n")
    page = report_page(results, folder)
    assert page.startswith("## Report") and "![mesh](validation/mesh.png)" in page
    assert (folder / "validation" / "mesh.png").read_bytes() == b"png"
    assert "cases (`results/validation/cases.json`)" in page and "gone (`validation/gone.png`, not found)" in page
