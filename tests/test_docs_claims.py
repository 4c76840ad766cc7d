"""Claims of the manual that can be checked cheaply: the citation's DOI, what ``tail_y_m`` is, and
that the .vtu example of "Your own swimmer" gives the regions the page says."""
import re
import tomllib
from pathlib import Path

import numpy as np

from aquarom_fenics.geometry.fish_recipe import shipped_fish_path
from aquarom_fenics.geometry.mesh_files import read_mesh
from aquarom_fenics.geometry.meshio_files import read_vtu
from aquarom_fenics.io.scene import scene_from_dict

REPOSITORY = Path(__file__).resolve().parents[1]
DOI = "10.48550/arXiv.2511.01031"


def test_citation_carries_the_paper_s_doi():
    text = (REPOSITORY / "CITATION.cff").read_text()
    citation = text[text.index("preferred-citation:"):]
    assert re.search(rf'^  doi: "?{re.escape(DOI)}"?$', citation, re.MULTILINE)
    assert re.search(rf'- type: doi\n\s+value: "?{re.escape(DOI)}"?', citation)


def test_outputs_page_says_tail_y_m_is_the_tail_station_s():
    text = (REPOSITORY / "docs" / "user" / "03-outputs.rst").read_text()
    row = text[text.index("* - ``tail_y_m``"):text.index("* - ``com_x_m``")]
    assert "tail station" in row and "tail-node" not in row


def vtu_section() -> str:
    text = (REPOSITORY / "docs" / "your_own_swimmer.md").read_text()
    start = text.index("### Region names in a .vtu")
    return text[start:text.index("\n## ", start)]


def blocks(section: str, language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", section, re.DOTALL)


def test_the_vtu_example_of_the_own_swimmer_page_gives_numbered_then_named_regions(tmp_path, monkeypatch):
    section = vtu_section()
    fish = read_mesh(shipped_fish_path(1))
    monkeypatch.chdir(tmp_path)
    exec(blocks(section, "python")[0], {"points": fish.points, "tetrahedra": fish.cells,
                                        "head_cells": fish.regions["head"], "left_cells": fish.regions["left_muscle"],
                                        "right_cells": fish.regions["right_muscle"]})
    scene = scene_from_dict(tomllib.loads(blocks(section, "toml")[0]), source=str(tmp_path / "my_swimmer.toml"))
    _, cells, regions = read_vtu(tmp_path / "my_swimmer.vtu")
    assert len(cells) == len(fish.cells) and set(regions) == {"1", "2", "3"}
    assert scene.regions.head == "1" and list(scene.regions.muscles) == ["2", "3"]
    np.testing.assert_array_equal(regions[scene.regions.head], fish.regions["head"])
    named = tmp_path / "named.vtu"
    field_data = blocks(section, "xml")[0].strip().removeprefix("<UnstructuredGrid>")
    named.write_text((tmp_path / "my_swimmer.vtu").read_text().replace("<UnstructuredGrid>",
                                                                       "<UnstructuredGrid>" + field_data, 1))
    _, _, regions = read_vtu(named)
    assert set(regions) == {"head", "left_muscle", "right_muscle"}
    np.testing.assert_array_equal(regions["left_muscle"], fish.regions["left_muscle"])
