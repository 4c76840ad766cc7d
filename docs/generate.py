"""Pages of the manual generated from the code, so they cannot drift from it.

``scene_keys.rst``: every key of every scene section with its default (as TOML), its check and
its meaning, from the schema in ``aquarom_fenics.io.scene_sections`` and, for ``[cluster]``,
``aquarom_fenics.parallel.settings.ClusterSettings``. ``cli.rst``: the ``--help``
of ``aquarom`` and of every sub-command. ``report.md``: the validation report
``results/REPORT.md`` of ``make validate`` when it exists, otherwise how to make it. The measured
tables of the README and of the pages in ``measured.PAGES``, rewritten between their markers from
the snapshot ``docs/data/`` (``measured.py``).

    python docs/generate.py                 # the generated pages and the measured tables
    python docs/generate.py --snapshot      # copy results/ into docs/data/ (date, host), then the same
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


CLUSTER_KEYS_MEANING = {
    "scheduler": "address of a Dask scheduler (e.g. \"tcp://head-node:8786\") for the designs of `aquarom sweep`, "
                 "the weights of `aquarom pareto` and the starts of a multi-start `aquarom optimize` when the "
                 "command line names none; empty: local worker processes. Not part of the scene's hash",
    "scheduler_file": "as scheduler, the address read from this file of `dask scheduler --scheduler-file`, "
                      "relative to the scene file (give scheduler or scheduler_file, not both)",
    "connect_timeout": "seconds to wait for the scheduler (or for its file to appear) before the command ends "
                       "with exit code 2",
}
"""Meaning of each key of a scene's [cluster] table (``aquarom_fenics.parallel.settings.ClusterSettings``)."""


def key_tables() -> dict:
    """Every table of a scene file: the sections of the scene schema, then [cluster]."""
    from aquarom_fenics.parallel.settings import ClusterSettings
    from aquarom_fenics.io.scene import SECTIONS

    return {**SECTIONS, "cluster": ClusterSettings}


def scene_key_rows() -> list[tuple[str, str, str, str]]:
    """(section, key, default as TOML, meaning) of every key of the scene schema and of [cluster]."""
    rows = []
    for section, cls in key_tables().items():
        for field in dataclasses.fields(cls):
            meaning = CLUSTER_KEYS_MEANING[field.name] if section == "cluster" else field.metadata.get("doc", "")
            rows.append((section, field.name, toml_literal(field.default), meaning))
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
    from measured import write_pages

    folder.mkdir(parents=True, exist_ok=True)
    write_pages(REPOSITORY)
    write_if_changed(folder / "scene_keys.rst", scene_keys_page())
    write_if_changed(folder / "cli_help.rst", command_help_page())
    write_if_changed(folder / "report.md", report_page(REPOSITORY / "results", folder))


def main(argv=None) -> int:
    import sys

    from measured import refresh

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--snapshot", action="store_true",
                        help="first copy the measurements' JSON files from --results into docs/data/")
    parser.add_argument("--results", type=Path, default=REPOSITORY / "results",
                        help="where the measurements wrote their files (default results/)")
    args = parser.parse_args(argv)
    if args.snapshot:
        if not args.results.is_dir():
            print(f"generate: error: --results {args.results} is not a folder", file=sys.stderr)
            return 2
        copied = refresh(args.results)
        print(f"snapshot: {len(copied)} file(s) copied into docs/data/" + "".join(f"\n  {name}" for name in copied))
    write_generated_pages(Path(__file__).resolve().parent / "_generated")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
