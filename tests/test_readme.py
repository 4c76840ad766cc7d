"""The README's scene documentation is what the code accepts: every TOML snippet loads, and the
keys table names every key of every section with the code's default."""
import dataclasses
import re
import tomllib
from pathlib import Path

import pytest

from aquarom_fenics.io.scene import SECTIONS, scene_from_dict

REPOSITORY = Path(__file__).resolve().parents[1]
README = (REPOSITORY / "README.md").read_text()


def toml_snippets() -> list[str]:
    return re.findall(r"```toml\n(.*?)```", README, flags=re.S)


def keys_table() -> list[tuple[str, str, str]]:
    """(section, key, default as TOML) for every row of the scene keys table."""
    rows, section = [], None
    for line in README.splitlines():
        header = re.fullmatch(r"\| `\[(\w+)\]` \| \| \|", line)
        row = re.fullmatch(r"\| `(\w+)` \| `(.*?)` \| .* \|", line)
        if header:
            section = header.group(1)
        elif row and section in SECTIONS:
            rows.append((section, row.group(1), row.group(2)))
    return rows


def test_the_readme_has_toml_snippets_and_a_keys_table():
    assert toml_snippets() and len(keys_table()) >= 40


@pytest.mark.parametrize("snippet", toml_snippets())
def test_every_toml_snippet_of_the_readme_loads(snippet):
    scene = scene_from_dict(tomllib.loads(snippet), source="README.md")
    assert scene.to_dict()


def test_every_documented_key_is_accepted_with_its_documented_default():
    for section, key, default in keys_table():
        scene = scene_from_dict(tomllib.loads(f"[{section}]\n{key} = {default}\n"), source="README.md")
        field = next(f for f in dataclasses.fields(SECTIONS[section]) if f.name == key)
        assert getattr(getattr(scene, section), key) == field.default, (section, key, default)


def test_every_key_of_the_code_is_documented():
    documented = {(section, key) for section, key, _ in keys_table()}
    for section, cls in SECTIONS.items():
        for field in dataclasses.fields(cls):
            assert (section, field.name) in documented, f"[{section}] {field.name} is missing from the README"


def test_layout_section_names_every_package_folder_and_only_existing_paths():
    """The README's layout table and the folder tree agree (caches are made by runs, not tracked)."""
    layout = README.split("## Layout", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`([\w./-]+/)`", layout))
    folders = {f"aquarom_fenics/{path.parent.name}/" for path in (REPOSITORY / "aquarom_fenics").glob("*/__init__.py")}
    assert folders <= named, f"package folders missing from the README layout: {sorted(folders - named)}"
    missing = [path for path in re.findall(r"`([\w./-]+)`", layout)
               if "/" in path and not path.endswith("cache/") and not (REPOSITORY / path).exists()]
    assert not missing, f"README layout names paths that do not exist: {missing}"
