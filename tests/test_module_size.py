"""No module of the package is longer than MAX_LINES, so that each can be read in one sitting."""
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]

MAX_LINES = 450

STILL_TOO_LONG: dict[str, int] = {}
"""Modules over the limit, with their length when listed: each may only shrink, and leaves the list
once it is within the limit."""


def module_lengths() -> dict[str, int]:
    files = [*(REPOSITORY / "aquarom_fenics").rglob("*.py"), *(REPOSITORY / "forms").rglob("*.py")]
    return {path.relative_to(REPOSITORY).as_posix(): len(path.read_text().splitlines()) for path in files}


def test_no_module_is_over_the_limit():
    lengths = module_lengths()
    over = {name: lines for name, lines in lengths.items() if lines > MAX_LINES and name not in STILL_TOO_LONG}
    assert not over, f"modules over {MAX_LINES} lines (split them by concern): {over}"
    grown = {name: lengths.get(name) for name, lines in STILL_TOO_LONG.items() if lengths.get(name, 0) > lines}
    assert not grown, f"listed modules that grew: {grown}"
    within = [name for name in STILL_TOO_LONG if lengths.get(name, 0) <= MAX_LINES]
    assert not within, f"within {MAX_LINES} lines now, remove from STILL_TOO_LONG: {within}"
