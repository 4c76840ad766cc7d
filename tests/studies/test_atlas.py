"""The PROM atlas of `aquarom sweep --model prom`: the cover of the design box, the centres built (only those
whose cells hold designs, through the PROM cache), one batched solve per centre, atlas.json and --resume."""
import csv
import itertools
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.studies import atlas, sweep

S = atlas.RADIUS_SCALE
SCENE = f"""
name = "atlas-test"
[mesh]
level = 1
[solver]
duration = 0.2
[shapes]
z_tail = {{ bounds = [-0.3, 0.3], radius = {0.075 / S!r} }}
y_thin = {{ bounds = [0.0, 0.1], radius = {0.025 / S!r} }}
"""
"""Validity radii 0.075 / s and 0.025 / s (s the atlas's radius scale): cells of half-width 0.075 (z_tail) and
0.025 (y_thin), 4 × 2 cells, whatever s."""

DESIGNS = [(-0.29, 0.01), (0.01, 0.06), (-0.16, 0.049), (0.149, 0.1), (0.3, 0.0), (0.0, 0.05)]
"""Six designs (z_tail, y_thin) in three of the eight cells: 0_0 (two), 2_1 (three, one at its corner), 3_0."""
CELLS = {"0_0": [0, 2], "2_1": [1, 3, 5], "3_0": [4]}


def so1_like():
    return scene_from_dict({"shapes": {"z_tail": {"bounds": [-0.5, 0.5]}, "z_head": {"bounds": [-0.5, 0.5]},
                                       "y_thin": {"bounds": [-0.15, 0.15], "radius": 0.025}}}, source="<test>")


# ---------------------------------------------------------------------- the cover (no builds)
def test_the_cover_cuts_the_box_in_cells_of_half_width_within_the_validity_radius():
    grid = atlas.cover(so1_like(), scale=1.0)
    assert grid.counts.tolist() == [4, 4, 6] and grid.box_cells() == 96
    assert np.allclose(grid.half_width, [0.125, 0.125, 0.025]) and np.all(grid.half_width <= grid.radius)
    assert np.allclose(grid.center((0, 3, 5)), [-0.375, 0.375, 0.125])
    half = atlas.cover(so1_like(), scale=0.5)
    assert half.counts.tolist() == [8, 8, 12] and np.all(half.half_width <= 0.5 * half.radius + 1e-15)
    shipped = atlas.cover(so1_like())                      # s = RADIUS_SCALE = 0.7: h = 1/12, 1/12, 1/60
    assert shipped.counts.tolist() == [6, 6, 9] and shipped.box_cells() == 324
    assert np.all(shipped.half_width <= atlas.RADIUS_SCALE * shipped.radius + 1e-15)


def test_every_design_falls_in_a_cell_whose_centre_is_the_nearest_and_holds_it():
    scene = so1_like()
    grid = atlas.cover(scene)
    designs = sweep.latin_hypercube(scene, 2000, seed=5)
    xis = np.array([[d[n] for n in grid.names] for d in designs])
    cells = grid.cells(xis)
    assert np.all((cells >= 0) & (cells < grid.counts))
    every = np.array([grid.center(cell) for cell in itertools.product(*(range(n) for n in grid.counts))])
    scaled = np.max(np.abs(xis[:, None, :] - every[None]) / grid.half_width, axis=2)      # (designs, centres)
    own = np.array([grid.scaled_distance(xi, cell)[0] for xi, cell in zip(xis, cells)])
    assert np.all(own <= 1 + 1e-12)                            # inside the cell: within h ≤ r of its centre
    assert np.allclose(own, scaled.min(axis=1), rtol=0, atol=1e-15)        # no centre is nearer
    groups = atlas.assign(grid, designs)
    assert sum(map(len, groups.values())) == len(designs) and len(groups) <= grid.box_cells()


def test_the_box_bounds_belong_to_its_cells_and_designs_beyond_it_to_cells_outside():
    grid = atlas.cover(so1_like(), scale=1.0)
    assert grid.cells([[0.5, -0.5, 0.15]]).tolist() == [[3, 0, 5]]        # upper bounds: the last cell
    outside = np.array([[0.6, 0.0, -0.16]])
    cell = grid.cells(outside)[0]
    assert cell.tolist() == [4, 2, -1] and grid.scaled_distance(outside, cell)[0] <= 1


# ---------------------------------------------------------------------- a sweep over the atlas
def run(argv) -> int:
    return main(["sweep", *argv])


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """One PROM sweep of DESIGNS from an empty PROM cache, counting the batched solves and their sizes."""
    from aquarom_fenics.dynamics import batched

    folder = tmp_path_factory.mktemp("atlas")
    (folder / "scene.toml").write_text(SCENE)
    with open(folder / "designs.csv", "w", newline="") as stream:
        csv.writer(stream).writerows([("z_tail", "y_thin"), *DESIGNS])
    solves = []
    original = batched.simulate_batch

    def counted(prom, scene, xis, *args, **kwargs):
        solves.append((tuple(np.round(prom.xi_center, 9)), len(xis)))
        return original(prom, scene, xis, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("AQUAROM_CACHE", str(folder / "cache"))
        patch.setattr(batched, "simulate_batch", counted)
        argv = [str(folder / "scene.toml"), "--designs", str(folder / "designs.csv"), "--model", "prom",
                "--workers", "1", "--no-progress"]
        assert run([*argv, "--out", str(folder / "out")]) == 0
        yield {"folder": folder, "argv": argv, "solves": solves, "patch": patch}


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


def test_every_design_is_answered_by_its_cells_centre_in_one_batched_solve_per_centre(swept):
    rows = read_csv(swept["folder"] / "out" / "sweep.csv")
    assert [row["status"] for row in rows] == ["completed"] * 6, [row["reason"] for row in rows]
    assert {name: sorted(int(r["design"]) for r in rows if r["prom_center"] == name) for name in CELLS} == CELLS
    assert sorted(size for _, size in swept["solves"]) == [1, 2, 3] and len(swept["solves"]) == 3
    centres = {center for center, _ in swept["solves"]}
    assert centres == {(-0.225, 0.025), (0.075, 0.075), (0.225, 0.025)}


def test_only_the_centres_holding_designs_are_built_and_atlas_json_lists_them(swept):
    report = json.loads((swept["folder"] / "out" / "atlas.json").read_text())
    assert [c["id"] for c in report["centres"]] == ["0_0", "2_1", "3_0"]
    assert [c["designs"] for c in report["centres"]] == [2, 3, 1]
    assert all(c["status"] == "built" and c["build_time_s"] > 0 and c["size"] > 0 for c in report["centres"])
    assert report["centres"][1]["center"] == pytest.approx({"z_tail": 0.075, "y_thin": 0.075})
    assert report["centres"][1]["prom_radius"] == pytest.approx({"z_tail": 0.075 / S, "y_thin": 0.025 / S})
    assert report["cells_in_box"] == 8 and report["cell_half_width"] == pytest.approx({"z_tail": 0.075, "y_thin": 0.025})
    times = ("build_time_s", "build_cpu_s", "solve_time_s", "solve_cpu_s")
    assert report["totals"] | dict.fromkeys(times, 0) == {"centres": 3, "built": 3, "from_the_cache": 0,
                                                          "designs": 6} | dict.fromkeys(times, 0)
    for key in times:
        assert all(c[key] > 0 for c in report["centres"])
        assert report["totals"][key] == pytest.approx(sum(c[key] for c in report["centres"]))
    first = min(c["builds_in_worker"] for c in report["centres"])     # one worker, in this process: 1, 2, 3 here
    assert sorted(c["builds_in_worker"] for c in report["centres"]) == [first, first + 1, first + 2]
    proms = [f for f in (swept["folder"] / "cache" / "prom").rglob("*.npz")]
    assert len(proms) == 3


def test_a_second_sweep_takes_the_centres_from_the_prom_cache(swept):
    out = swept["folder"] / "again"
    assert run([*swept["argv"], "--out", str(out)]) == 0
    report = json.loads((out / "atlas.json").read_text())
    assert [c["status"] for c in report["centres"]] == ["from the cache"] * 3
    assert len({c["builds_in_worker"] for c in report["centres"]}) == 1 and report["totals"]["build_cpu_s"] == 0
    first = read_csv(swept["folder"] / "out" / "sweep.csv")
    assert [r["distance_m"] for r in read_csv(out / "sweep.csv")] == [r["distance_m"] for r in first]


def test_resume_runs_the_missing_designs_and_atlas_json_keeps_every_centre(swept, capsys):
    out = swept["folder"] / "resumed"
    assert run([*swept["argv"], "--out", str(out)]) == 0
    lines = (out / "sweep.csv").read_text().splitlines()
    kept = [line for line in lines[1:] if line.endswith(",0_0")]           # as if stopped after centre 0_0
    (out / "sweep.csv").write_text("\n".join([lines[0], *kept]) + "\n")
    report = json.loads((out / "atlas.json").read_text())
    report["centres"] = [c for c in report["centres"] if c["id"] == "0_0"]
    (out / "atlas.json").write_text(json.dumps(report))
    capsys.readouterr()
    assert run([*swept["argv"], "--out", str(out), "--resume"]) == 0
    assert "4 to run" in capsys.readouterr().out
    rows = read_csv(out / "sweep.csv")
    assert sorted(int(r["design"]) for r in rows) == list(range(6))
    resumed = json.loads((out / "atlas.json").read_text())
    assert [(c["id"], c["designs"]) for c in resumed["centres"]] == [("0_0", 2), ("2_1", 3), ("3_0", 1)]
    assert resumed["centres"][0] == report["centres"][0] | {"designs": 2}       # the earlier run's record


def test_a_damaged_atlas_file_stops_a_resume_in_one_line(swept, capsys):
    out = swept["folder"] / "damaged"
    assert run([*swept["argv"], "--out", str(out)]) == 0
    (out / "atlas.json").write_text("{\"centres\": 3}")
    capsys.readouterr()
    assert run([*swept["argv"], "--out", str(out), "--resume"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "atlas.json: not an atlas file" in lines[0] and "without --resume" in lines[0]


def test_a_design_whose_centre_cannot_be_built_is_a_refused_row(tmp_path, monkeypatch):
    """y_thin ∈ [0, 1.6] is cut in two cells; the centre 1.2 inverts the mesh, its designs are refused rows."""
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    wide = SCENE.replace(f"[0.0, 0.1], radius = {0.025 / S!r}", f"[0.0, 1.6], radius = {0.4 / S!r}")
    scene = scene_from_dict(tomllib.loads(wide), source="<test>")
    rows = sweep.run_sweep(scene, [{"z_tail": 0.0, "y_thin": 1.3}], "prom", tmp_path / "out", pool=_in_process())
    assert rows[0]["status"] == "refused" and "no PROM at its centre 2_1" in rows[0]["reason"]
    report = json.loads((tmp_path / "out" / "atlas.json").read_text())
    assert report["centres"][0]["status"].startswith("refused: ")


def _in_process():
    from aquarom_fenics.parallel import InProcess

    return InProcess()


def test_a_centres_later_task_keeps_its_build_and_adds_its_solve_times():
    built = {"id": "0_1", "status": "built", "build_time_s": 2.0, "solve_time_s": 1.5, "solve_cpu_s": 1.25}
    later = {"id": "0_1", "status": "from the cache", "build_time_s": 0.1, "solve_time_s": 0.5, "solve_cpu_s": 0.25}
    assert atlas.merged_record(built, later) == built | {"solve_time_s": 2.0, "solve_cpu_s": 1.5}
    assert atlas.merged_record(None, later) == later
    assert atlas.merged_record(later, built) == built | {"solve_time_s": 2.0, "solve_cpu_s": 1.5}


def test_a_scale_outside_zero_to_one_is_refused():
    from aquarom_fenics.errors import InputError

    with pytest.raises(InputError, match="must be in"):
        atlas.cover(so1_like(), scale=1.5)
