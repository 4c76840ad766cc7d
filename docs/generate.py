"""Pages of the manual generated from the code, so they cannot drift from it.

``scene_keys.rst``: every key of every scene section with its default (as TOML), its check and
its meaning, from the schema in ``aquarom_fenics.io.scene_sections``. ``cli.rst``: the ``--help``
of ``aquarom`` and of every sub-command. ``report.md``: the validation report
``results/REPORT.md`` of ``make validate`` when it exists, otherwise how to make it.
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]


def toml_literal(value) -> str:
    """A scene value written as in a scene file."""
    from aquarom_fenics.io.scene import _toml_value

    return _toml_value(list(value) if isinstance(value, tuple) else value)


def scene_key_rows() -> list[tuple[str, str, str, str]]:
    """(section, key, default as TOML, meaning) of every key of the scene schema."""
    from aquarom_fenics.io.scene import SECTIONS

    rows = []
    for section, cls in SECTIONS.items():
        for field in dataclasses.fields(cls):
            rows.append((section, field.name, toml_literal(field.default), field.metadata.get("doc", "")))
    return rows


def scene_keys_page() -> str:
    lines = [".. list-table:: Scene keys (generated from ``aquarom_fenics.io.scene_sections``)",
             "   :header-rows: 1", "   :widths: 18 22 60", "", "   * - key", "     - default", "     - meaning"]
    current = None
    for section, key, default, meaning in scene_key_rows():
        if section != current:
            lines += [f"   * - **[{section}]**", "     -", "     -"]
            current = section
        lines += [f"   * - ``{key}``", f"     - ``{default}``", f"     - {escape_rst(meaning) or '—'}"]
    return "\n".join(lines) + "\n"


def escape_rst(text: str) -> str:
    """Plain text safe in a table cell: backslashes, stars and backquotes escaped."""
    for special in ("\\", "*", "`", "|", "_"):
        text = text.replace(special, "\\" + special)
    return text


def command_help_page() -> str:
    """The --help of ``aquarom`` and of every sub-command, as literal blocks (100 columns wide)."""
    import os

    from aquarom_fenics.cli.parser import build_parser

    os.environ["COLUMNS"] = "100"

    parser = build_parser()
    parser.prog = "aquarom"
    sections = [("aquarom", parser.format_help())]
    subcommands = next(action for action in parser._actions if isinstance(action, argparse._SubParsersAction))
    for name, sub in subcommands.choices.items():
        sections.append((f"aquarom {name}", sub.format_help()))
    lines = []
    for title, text in sections:
        lines += [title, "~" * len(title), "", ".. code-block:: text", ""]
        lines += [("   " + line).rstrip() for line in text.replace("\t", "    ").splitlines()]
        lines.append("")
    return "\n".join(lines)


def report_page(results: Path, folder: Path) -> str:
    """The validation report ``results/REPORT.md`` as a page in ``folder``: its figures copied
    beside it, its links to data files written as paths; or how to make it when it is missing."""
    import re
    import shutil

    report = results / "REPORT.md"
    if not report.is_file():
        return ("## Validation report\n\nNo report in this checkout: `make validate` writes "
                "`results/REPORT.md` (hours on two cores; every case is cached) and the next "
                "`make docs` shows it here.\n")

    def figure(match) -> str:
        caption, target = match.group(1), match.group(2)
        source = results / target
        if target.startswith(("http:", "https:", "/")) or not source.is_file():
            return f"{caption} (`{target}`, not found)"
        copy = folder / target
        copy.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, copy)
        return f"![{caption}]({target})"

    def data_link(match) -> str:
        text, target = match.group(1), match.group(2)
        return match.group(0) if target.startswith(("http:", "https:")) else f"{text} (`results/{target}`)"

    text = re.sub(r"!\[([^\]]*)\]\(([^)]+)\)", figure, report.read_text())
    text = re.sub(r"(?<!!)\[([^\]]*)\]\(([^)]+)\)", data_link, text)
    text = re.sub(r"^#", "##", text, flags=re.M)          # one level below the Validation page
    return text


def write_if_changed(path: Path, text: str) -> None:
    """Write only a changed page, so Sphinx does not rebuild what did not change."""
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def write_generated_pages(folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    write_if_changed(folder / "scene_keys.rst", scene_keys_page())
    write_if_changed(folder / "cli_help.rst", command_help_page())
    write_if_changed(folder / "report.md", report_page(REPOSITORY / "results", folder))


if __name__ == "__main__":
    write_generated_pages(Path(__file__).resolve().parent / "_generated")
