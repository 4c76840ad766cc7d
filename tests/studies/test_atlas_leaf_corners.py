"""scripts/validate_atlas.py's every-corner check on a scene with capped radii walks the leaves that answered the
sweep's designs (cells divided as their PROMs ask), not the regular cells: each leaf's corners are inside that
leaf, compared with the FOM at vertices shared by the leaves meeting there whatever their levels; on a cheap
capped scene (coarsest block, 0.2 s swim) each leaf's own PROM answers its 2^p corners."""
import importlib.util
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import capped_block_scene
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.reduction.atlas_cover import Cover
from aquarom_fenics.reduction.atlas_refine import Refiner, holds

REPOSITORY = Path(__file__).resolve().parents[2]
SPEC = importlib.util.spec_from_file_location("validate_atlas_leaves", REPOSITORY / "scripts" / "validate_atlas.py")
script = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(script)

S = 0.7
GRID = Cover(("a", "b"), np.zeros(2), np.ones(2), np.array([0.25, 0.25]), np.array([2, 2]),
             np.array([0.25, 0.25]) / S, S)
"""2 × 2 cells of half-width 0.25 over [0, 1]²."""


def thin_near_a1(center):
    """A fake PROM at ``center`` whose capped R_a falls towards a = 1; R_b never below the cell."""
    xi = np.array([center["a"], center["b"]])
    return SimpleNamespace(validity_radius=np.array([0.25 / S * (1.0 - 0.6 * xi[0]) ** 2, 0.25 / S]),
                           xi_center=xi), True


def test_the_leaves_corners_are_inside_their_own_leaf_and_share_the_vertices_where_leaves_meet():
    refiner = Refiner(SimpleNamespace(reduction=SimpleNamespace(validity_change=0.03, atlas_change=0.0)), GRID, prom_at=thin_near_a1)
    xis = np.random.default_rng(5).uniform(0, 1, size=(60, 2))
    rows = [{"status": "completed", "prom_center": refiner.leaf(xi).node.id} for xi in xis]
    rows.append({"status": "refused", "prom_center": "1_1"})                  # not a leaf that answered
    leaves = script.used_leaves(GRID, rows)
    assert {node.id for node in leaves} == {row["prom_center"] for row in rows[:-1]}
    assert len({node.levels for node in leaves}) > 1 and all(node.id != "1_1" for node in leaves)
    corners, vertices = script.leaf_corners(GRID, leaves)
    assert len(corners) == 4 * len(leaves) and len(vertices) < len(corners)
    for vertex, design, node in corners:
        xi = np.array([design["a"], design["b"]])
        assert holds(GRID, node, xi)                                          # the leaf's own PROM answers it
        offset = np.abs(xi - node.center(GRID)) / node.half_width(GRID)
        assert np.allclose(offset, 1, rtol=0, atol=2e-9) and np.all(offset < 1)
        assert np.allclose(xi, vertices[vertex], rtol=0, atol=1e-9)           # compared at its own vertex
    points = np.array(list(vertices.values()))
    assert len({tuple(np.round(p, 12)) for p in points}) == len(points)      # one FOM run per point
    levels_at = {}
    for vertex, _, node in corners:
        levels_at.setdefault(vertex, set()).add(node.levels)
    assert any(len(levels) > 1 for levels in levels_at.values())             # leaves of different levels meet
    assert np.allclose(points.min(axis=0), 0.0) and np.all(points <= 1.0 + 1e-12)


def test_the_regular_cells_vertices_are_the_grids_when_no_cell_is_divided():
    from aquarom_fenics.reduction.atlas_refine import base_node

    corners, vertices = script.leaf_corners(GRID, [base_node((0, 0)), base_node((1, 0))])
    assert len(corners) == 8 and len(vertices) == 6
    assert {vertex: tuple(xi) for vertex, xi in vertices.items()} == {
        (i, j): (0.5 * i, 0.5 * j) for i in range(3) for j in range(2)}


CAPPED = capped_block_scene("atlas-leaf-corners-test", S)
"""test_atlas_capped.py's scene: cells of half-width 0.05, bisected once in y_thin by the capped radius."""


def test_every_corner_of_a_capped_scene_walks_the_leaves_that_answered_the_designs(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = scene_from_dict(tomllib.loads(CAPPED), source="<test>")
    designs = [{"z_tail": -0.27, "y_thin": 0.01}, {"z_tail": -0.27, "y_thin": 0.09}]
    report = script.every_corner(scene, 1, tmp_path / "check", designs)
    assert report["walked"] == "the leaves that answered 2 designs"
    assert report["cell_of"] == {"0_0@0_1": [0, 0], "0_1@0_1": [0, 1]}     # not the 6 regular cells
    assert report["cells"] == 2 and report["corners"] == 8 and report["vertices"] == 6
    assert report["answered_by_own_cell"] == 8 and report["compared"] == 8
    for entry in report["designs"]:
        assert entry["prom_center"] == entry["cell"] and entry["prom_status"] == entry["fom_status"] == "completed"
        assert entry["relative_error"] == pytest.approx(
            (entry["prom_distance_m"] - entry["fom_distance_m"]) / abs(entry["fom_distance_m"]), rel=1e-12)
    shared = [entry for entry in report["designs"] if entry["vertex"][1] == 1]   # y_thin = 0.05: both leaves' corner
    assert len(shared) == 4 and len({entry["fom_distance_m"] for entry in shared}) == 2
    with pytest.raises(ValueError, match="needs the designs"):
        script.every_corner(scene, 1, tmp_path / "again")


def test_every_corner_of_a_scene_without_capped_radii_walks_every_regular_cell(tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    table = tomllib.loads(CAPPED.replace("validity_change = 0.09", "validity_change = 0.0")
                          .replace("bounds = [-0.3, 0.3]", "bounds = [-0.05, 0.05]"))
    scene = scene_from_dict(table, source="<test>")                  # one regular cell, no design needed
    report = script.every_corner(scene, 1, tmp_path / "check")
    assert report["walked"] == "every cell of the box" and report["cell_of"] == {"0_0": [0, 0]}
    assert (report["cells"], report["corners"], report["vertices"], report["answered_by_own_cell"]) == (1, 4, 4, 4)
    assert report["compared"] == 4
