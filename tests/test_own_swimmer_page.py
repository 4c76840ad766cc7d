"""The page "Your own swimmer" (docs/your_own_swimmer.md): every message its lists quote is still one the
package can print, so that the page cannot drift from the code.

Each string literal of the package's source (an f-string, or a plain string with %-formats) is a
pattern: its constant text as written, each formatted value any text. A quoted message must be one
pattern filled in, where every value is short (a path shortened to "…", a number, a name; at most
MAX_VALUE characters) or is itself such a message (a remedy or a cause composed into another one)."""
import ast
import re
from functools import lru_cache
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]
PAGE = REPOSITORY / "docs" / "your_own_swimmer.md"
PACKAGE = REPOSITORY / "aquarom_fenics"

MAX_VALUE = 40
"""Longest text a formatted value may fill unless it is itself a message of the source."""
MIN_CONSTANT = 10
"""Least constant text of a pattern (f"{a}: {b}" is no message of its own)."""

_PERCENT_FORMAT = re.compile(r"%[-#0-9.]*[sdfgr]")


def _parts(node) -> list[str | None]:
    """The constant parts of a string literal, None for each formatted value."""
    if isinstance(node, ast.Constant):
        texts = _PERCENT_FORMAT.split(node.value)
        return [part for text in texts for part in (None, text)][1:]
    return [value.value if isinstance(value, ast.Constant) else None for value in node.values]


@lru_cache(maxsize=1)
def source_patterns() -> tuple[tuple[tuple[str, ...], re.Pattern], ...]:
    """(constant parts, compiled pattern) of every string literal of the package with MIN_CONSTANT
    constant characters or more."""
    patterns = {}
    for path in PACKAGE.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        inside = {id(value) for node in ast.walk(tree) if isinstance(node, ast.JoinedStr) for value in ast.walk(node)
                  if value is not node}
        for node in ast.walk(tree):
            literal = isinstance(node, ast.JoinedStr) or (isinstance(node, ast.Constant) and isinstance(node.value, str))
            if not literal or id(node) in inside:
                continue
            parts = _parts(node)
            constants = tuple(part for part in parts if part)
            if sum(map(len, constants)) < MIN_CONSTANT:
                continue
            regex = "".join("(.*?)" if part is None else re.escape(part) for part in parts)
            patterns[regex] = constants
    return tuple((constants, re.compile(regex, re.DOTALL)) for regex, constants in patterns.items())


def is_source_message(text: str) -> bool:
    """True when ``text`` is a pattern of the source filled in with short values or messages of the source."""
    for constants, pattern in source_patterns():
        if not all(constant in text for constant in constants):
            continue
        match = pattern.fullmatch(text)
        if match and all(len(value) <= MAX_VALUE or (len(value) < len(text) and is_source_message(value))
                         for value in match.groups()):
            return True
    return False


def quoted_messages(text: str) -> list[str]:
    """The first cells (`code`) of the tables of the section "Messages a mesh can get"."""
    start = text.index("## Messages a mesh can get")
    end = text.index("\n## ", start + 1)
    rows = [line for line in text[start:end].splitlines() if line.startswith("| `")]
    return [re.match(r"\| `(.+?)` \|", row).group(1) for row in rows]


MESSAGES = quoted_messages(PAGE.read_text(encoding="utf-8"))


def test_the_page_lists_the_messages_of_every_kind_of_bad_input():
    assert len(MESSAGES) >= 40
    for words in ("--level", "unsupported suffix", "no tetrahedra: its physical groups", "netCDF4",
                  "m long along x, outside 1 mm to 5 m", "reaches both ends", "[[muscles]] 1: unknown key",
                  "misses the body", "overlap", "separate solids", "reaches neither end", "is the body's longest",
                  "inverted or tangled", "lies far from the rest", "besides its"):
        assert any(words in message for message in MESSAGES), words


@pytest.mark.parametrize("message", MESSAGES, ids=[message[:60] for message in MESSAGES])
def test_every_quoted_message_is_in_the_source(message):
    assert is_source_message(message), message


def test_a_message_the_code_does_not_print_is_caught():
    """A word changed, left out or moved in a quoted message, or a value too long to be one, fails."""
    message = ("mesh …: the body is 200 m long along x, outside 1 mm to 5 m; its coordinates are probably in "
               "millimetres or centimetres: set [mesh] scale = 0.001 (mm) or 0.01 (cm)")
    assert is_source_message(message)
    assert not is_source_message(message.replace("probably", "surely"))
    assert not is_source_message(message.replace(" along x", ""))
    assert not is_source_message(message.replace("200 m", "200 m, which is far too long for a swimmer of this toolkit, m"))
    assert not is_source_message("mesh …: no nodes on the body axis; the stations need no nodes on the axis")
