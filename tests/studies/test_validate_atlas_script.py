"""scripts/validate_atlas.py's pure parts: the corners it checks with the FOM and where it says the time went."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.studies import atlas

REPOSITORY = Path(__file__).resolve().parents[2]
SPEC = importlib.util.spec_from_file_location("validate_atlas", REPOSITORY / "scripts" / "validate_atlas.py")
script = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(script)


def so1_like():
    return scene_from_dict({"shapes": {"z_tail": {"bounds": [-0.5, 0.5]}, "z_head": {"bounds": [-0.5, 0.5]},
                                       "y_thin": {"bounds": [-0.15, 0.15], "radius": 0.025}}}, source="<test>")


def test_the_corners_are_those_of_the_cells_that_erred_most_each_answered_by_its_own_cell():
    grid = atlas.cover(so1_like())
    results = [{"prom_center": "0_4_3", "relative_error": 0.0222}, {"prom_center": "1_0_1", "relative_error": -0.03},
               {"prom_center": "0_4_3", "relative_error": 0.01}, {"prom_center": "2_2_2", "relative_error": 0.005},
               {"prom_center": "4_4_6"}]                                     # a FOM that did not complete
    corners = script.corner_designs(grid, results, 2)
    assert len(corners) == 16
    xis = np.array([[corner[name] for name in grid.names] for corner in corners])
    cells = [atlas.center_id(cell) for cell in grid.cells(xis)]
    assert cells == ["1_0_1"] * 8 + ["0_4_3"] * 8                           # |-3 %| first, each cell once
    for xi, name in zip(xis, cells):
        offset = np.abs(xi - grid.center(atlas.cell_of(name, grid))) / grid.half_width
        assert np.allclose(offset, 1, rtol=0, atol=2e-9) and np.all(offset < 1)      # every shape at ±h at once
    assert len({tuple(xi) for xi in xis}) == 16


def test_every_corner_of_every_cell_is_answered_by_its_own_cell_and_compared_at_its_grid_vertex():
    grid = atlas.cover(so1_like())
    cells, corners, vertices = script.every_cell_corner(grid)
    counts = [int(n) for n in grid.counts]
    assert len(cells) == np.prod(counts) and len(corners) == 8 * len(cells)
    assert len(vertices) == np.prod([n + 1 for n in counts])                  # shared by the cells meeting there
    for (vertex, design), cell in zip(corners, np.repeat(np.array(cells), 8, axis=0)):
        xi = np.array([design[name] for name in grid.names])
        assert tuple(grid.cells(xi[None])[0]) == tuple(cell)                  # the corner's own cell answers it
        assert np.allclose(xi, vertices[vertex], rtol=0, atol=1e-9) and not np.array_equal(xi, vertices[vertex])
    box = np.array(list(vertices.values()))
    assert np.allclose(box.min(axis=0), grid.lower) and np.allclose(box.max(axis=0), grid.upper)


def test_the_time_split_counts_builds_made_here_and_each_workers_first_apart():
    centres = [{"status": "built", "build_time_s": 2.0, "build_cpu_s": 1.0, "builds_in_worker": 1, "worker": "a",
                "solve_time_s": 1.0, "solve_cpu_s": 0.5},
               {"status": "built", "build_time_s": 0.8, "build_cpu_s": 0.4, "builds_in_worker": 2, "worker": "a",
                "solve_time_s": 2.0, "solve_cpu_s": 1.0},
               {"status": "built", "build_time_s": 3.0, "build_cpu_s": 1.5, "builds_in_worker": 1, "worker": "b",
                "solve_time_s": 1.0, "solve_cpu_s": 0.5},
               {"status": "built", "build_time_s": 0.6, "build_cpu_s": 0.2, "builds_in_worker": 2, "worker": "b",
                "solve_time_s": 1.0, "solve_cpu_s": 0.5},
               {"status": "from the cache", "build_time_s": 0.1, "build_cpu_s": 0.05, "builds_in_worker": 2,
                "worker": "b", "solve_time_s": 1.0, "solve_cpu_s": 0.5}]
    split = script.time_split({"centres": centres, "totals": {"designs": 1000}})
    assert split["builds"] == 4 and split["workers"] == 2
    assert split["build_wall_s"] == pytest.approx(6.4) and split["build_cpu_s"] == pytest.approx(3.1)
    assert split["first_build_per_worker_s"] == [2.0, 3.0]
    assert split["later_build_mean_s"] == pytest.approx(0.7) and split["later_build_cpu_mean_s"] == pytest.approx(0.3)
    assert split["solve_wall_s"] == pytest.approx(6.0) and split["solve_cpu_s"] == pytest.approx(3.0)
    assert split["solve_cpu_per_design_s"] == pytest.approx(3e-3)


@pytest.mark.parametrize("option, value", [("--corners", "-1"), ("--samples", "0"), ("--workers", "0")])
def test_a_count_out_of_range_is_refused_before_any_run(option, value, monkeypatch, capsys):
    monkeypatch.setattr("sys.argv", ["validate_atlas.py", option, value])
    with pytest.raises(SystemExit) as stop:
        script.main()
    assert stop.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].endswith(f"{option} {value}: a count, at least "
                                                                     f"{0 if option == '--corners' else 1}")


def test_the_start_corners_are_the_start_and_seeded_corners_of_its_cell_and_of_one_other():
    scene = so1_like().replace("reduction", atlas_scale=0.5)
    grid = atlas.cover(scene)
    designs = script.start_corner_designs(scene, grid, 4, seed=3)
    assert [why for why, _ in designs] == ["start"] + ["start cell corner"] * 4 + ["other cell corner"] * 4
    xis = np.array([[design[name] for name in grid.names] for _, design in designs])
    assert np.array_equal(xis[0], [0.0, 0.0, 0.0])
    cells = [tuple(cell) for cell in grid.cells(xis)]
    assert cells[0] == (4, 4, 6) and set(cells[1:5]) == {(4, 4, 6)}          # ξ = 0: the lower corner of 4_4_6
    assert len(set(cells[5:])) == 1 and cells[5] != cells[0]                  # one other cell
    for xi, cell in zip(xis[1:], cells[1:]):
        offset = np.abs(xi - grid.center(cell)) / grid.half_width
        assert np.allclose(offset, 1, rtol=0, atol=2e-9) and np.all(offset < 1)      # a corner, inside its cell
    assert designs == script.start_corner_designs(scene, grid, 4, seed=3)                # seeded
    assert designs != script.start_corner_designs(scene, grid, 4, seed=4)


@pytest.mark.parametrize("flag, value, refusal", [
    ("--atlas-scale", "1.5", "atlas_scale = 1.5 must be in (0, 1]"),
    ("--atlas-check", "1.0", "atlas_check = 1.0 must be in [0, 1)"),
])
def test_a_bad_atlas_key_is_refused_before_any_run(monkeypatch, capsys, flag, value, refusal):
    monkeypatch.setattr("sys.argv", ["validate_atlas.py", flag, value, "--start-corners", "2"])
    with pytest.raises(SystemExit) as stop:
        script.main()
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert flag in err and refusal in err
