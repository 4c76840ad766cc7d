"""Each command's input checks stand beside the command: no check in cli/ branches on the command's
name, and a dry run makes the checks its run makes."""
import ast
from pathlib import Path

import aquarom_fenics.cli as cli
from aquarom_fenics.cli import main
from aquarom_fenics.cli.commands import COMMANDS
from aquarom_fenics.cli.parser import build_parser

from conftest import one_line


def command_name_tests(path: Path) -> list[str]:
    """``X.command == …`` / ``X.command in (…)`` comparisons in a module, as ``file:line``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(isinstance(item, ast.Attribute) and item.attr == "command" for item in operands):
                found.append(f"{path.name}:{node.lineno}")
    return found


def test_no_input_check_branches_on_the_command_name():
    folder = Path(cli.__file__).parent
    assert [hit for path in sorted(folder.glob("*.py")) for hit in command_name_tests(path)] == []


def test_every_command_with_a_dry_run_declares_its_checks():
    subparsers = next(action for action in build_parser()._actions if action.dest == "command")
    for name, parser in subparsers.choices.items():
        dry = any("--dry-run" in action.option_strings for action in parser._actions)
        if dry and name != "sweep":          # a sweep's plan needs its designs: it plans itself
            assert hasattr(COMMANDS[name], "__wrapped__"), f"{name}: no @checked(inputs)"


def test_a_dry_run_refuses_what_the_run_refuses(tmp_path, capsys):
    assert main(["shapes", "nominal", "--dry-run"]) == 2          # nothing to show: no [shapes], no --xi
    assert "nothing to show" in one_line(capsys)
