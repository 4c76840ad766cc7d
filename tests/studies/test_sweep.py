"""`aquarom sweep`: design sources, refused input, rows, cache and resume, and the Dask backend on a
real ``distributed.LocalCluster`` (TCP scheduler, 2 worker processes of one thread each)."""
import csv
import os
import signal
import tomllib
from pathlib import Path

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.workers import SWIMMER_WORKERS
from aquarom_fenics.parallel import ClusterSettings, DaskCluster
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.studies import atlas, sweep

SCENE = """
name = "sweep-test"
[mesh]
level = 1
[solver]
duration = {duration}
[shapes]
z_tail = {{ bounds = [-0.3, 0.3] }}
y_thin = {{ bounds = [0.0, 0.1] }}
"""

GRID = ["--grid", "z_tail=-0.2:0.2:3", "--grid", "y_thin=0:0.1:2"]
"""Six designs."""


def write_scene(folder: Path, duration: float = 0.2) -> Path:
    path = folder / "scene.toml"
    path.write_text(SCENE.format(duration=duration))
    return path


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


def refused(capsys, argv, out: Path) -> str:
    """Run a command that must be refused: exit 2, one line on stderr, no output folder."""
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert not out.exists()
    return lines[0]


# ---------------------------------------------------------------------- designs and refused input
def test_grid_is_the_product_of_its_axes_with_the_other_shapes_at_their_start():
    scene = sweep_scene()
    designs = sweep.grid_designs(["z_tail=-0.2:0.2:3"], scene)
    assert designs == [{"z_tail": -0.2, "y_thin": 0.0}, {"z_tail": 0.0, "y_thin": 0.0}, {"z_tail": 0.2, "y_thin": 0.0}]
    assert len(sweep.grid_designs(["z_tail=-0.2:0.2:3", "y_thin=0:0.1:4"], scene)) == 12


def sweep_scene():
    return scene_from_dict(tomllib.loads(SCENE.format(duration=0.2)), source="<test>")


def test_latin_hypercube_puts_one_design_in_every_stratum_and_is_seeded():
    scene = sweep_scene()
    designs = sweep.latin_hypercube(scene, 8, seed=3)
    for shape in scene.shapes:
        unit = np.array([(d[shape.name] - shape.lower) / (shape.upper - shape.lower) for d in designs])
        assert sorted(np.floor(unit * 8).astype(int)) == list(range(8))
    assert designs == sweep.latin_hypercube(scene, 8, seed=3)
    assert designs != sweep.latin_hypercube(scene, 8, seed=4)


@pytest.mark.parametrize("grid, expected", [
    ("z_tail=0:1", "expected name=lo:hi:n"),
    ("fin=0:1:3", "'fin' is not a shape variation"),
    ("z_tail=0:1:x", "must be a whole number"),
    ("z_tail=0:1:0", "must be ≥ 1"),
    ("z_tail=0:nan:3", "not a finite number"),
])
def test_a_bad_grid_is_refused_in_one_line(tmp_path, capsys, grid, expected):
    out = tmp_path / "out"
    line = refused(capsys, ["sweep", str(write_scene(tmp_path)), "--grid", grid, "--out", str(out)], out)
    assert line.startswith("aquarom sweep: error: --grid") and expected in line


def test_an_unknown_shape_in_the_designs_file_is_refused_in_one_line(tmp_path, capsys):
    designs = tmp_path / "designs.csv"
    designs.write_text("z_tail,fin_height\n0.1,0.2\n")
    out = tmp_path / "out"
    line = refused(capsys, ["sweep", str(write_scene(tmp_path)), "--designs", str(designs), "--out", str(out)], out)
    assert "column 'fin_height' is not a shape variation" in line and "valid: z_tail, y_thin" in line


def test_a_non_number_in_the_designs_file_names_its_line_and_column(tmp_path, capsys):
    designs = tmp_path / "designs.csv"
    designs.write_text("z_tail,y_thin\n0.1,0.02\n0.2,thin\n")
    out = tmp_path / "out"
    line = refused(capsys, ["sweep", str(write_scene(tmp_path)), "--designs", str(designs), "--out", str(out)], out)
    assert "line 3 column y_thin: 'thin' is not a number" in line


def test_exactly_one_source_of_designs(tmp_path, capsys):
    out = tmp_path / "out"
    scene = str(write_scene(tmp_path))
    assert "got --grid --samples" in refused(capsys, ["sweep", scene, "--grid", "z_tail=0:0.1:2", "--samples", "3",
                                                      "--out", str(out)], out)
    assert "give the designs with one of" in refused(capsys, ["sweep", scene, "--out", str(out)], out)


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(write_scene(tmp_path)), "--samples", "5", "--dry-run", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "designs: 5 (Latin hypercube, seed 0)" in text and "0 of the 5 designs answered already" in text
    assert "estimate: ~" in text and not out.exists()


# ---------------------------------------------------------------------- rows, cache, resume
def test_every_design_is_one_row_with_refused_ones_and_a_rerun_reads_the_cache(tmp_path, capsys):
    designs = tmp_path / "designs.csv"
    designs.write_text("y_thin,z_tail\n0.05,0.1\n1.5,0\n")        # y_thin = 1.5 inverts the mesh
    scene = str(write_scene(tmp_path))
    out = tmp_path / "out"
    assert main(["sweep", scene, "--designs", str(designs), "--workers", "1", "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [(r["design"], r["status"]) for r in rows] == [("0", "completed"), ("1", "refused")]
    assert float(rows[0]["tail_amplitude_m"]) > 0 and rows[0]["cached"] == "False"
    assert "inverts or flattens" in rows[1]["reason"] and rows[1]["distance_m"] == ""
    assert (out / "sweep.png").stat().st_size > 10_000 and (out / "manifest.json").exists()
    again = tmp_path / "again"
    assert main(["sweep", scene, "--designs", str(designs), "--workers", "1", "--out", str(again)]) == 0
    second = read_csv(again / "sweep.csv")
    assert second[0]["cached"] == "True" and second[0]["distance_m"] == rows[0]["distance_m"]


def test_resume_keeps_the_rows_written_and_runs_only_the_missing_designs(tmp_path, capsys):
    scene = str(write_scene(tmp_path))
    out = tmp_path / "out"
    argv = ["sweep", scene, "--grid", "z_tail=-0.1:0.1:3", "--workers", "1", "--out", str(out)]
    assert main(argv) == 0
    lines = (out / "sweep.csv").read_text().splitlines()
    (out / "sweep.csv").write_text("\n".join(lines[:2]) + "\n")   # as if stopped after the first design
    capsys.readouterr()
    assert main(argv + ["--resume"]) == 0
    assert "2 to run" in capsys.readouterr().out
    resumed = (out / "sweep.csv").read_text().splitlines()
    assert resumed[:2] == lines[:2] and len(resumed) == 4
    assert sorted(row["design"] for row in read_csv(out / "sweep.csv")) == ["0", "1", "2"]
    other = refused(capsys, ["sweep", scene, "--grid", "z_tail=-0.2:0.2:3", "--workers", "1", "--out",
                             str(tmp_path / "nowhere"), "--resume"], tmp_path / "nowhere")
    assert "no sweep.csv" in other


# ---------------------------------------------------------------------- Dask distributed
@pytest.fixture
def cluster(dask_cluster):
    return dask_cluster


def test_unreachable_scheduler_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "out"
    line = refused(capsys, ["sweep", str(write_scene(tmp_path)), *GRID, "--scheduler", "tcp://127.0.0.1:9",
                            "--connect-timeout", "1", "--out", str(out)], out)
    assert line.startswith("aquarom sweep: error: Dask scheduler tcp://127.0.0.1:9: not reachable within 1 s")


def test_a_sweep_on_dask_equals_the_serial_one_bit_for_bit(tmp_path, monkeypatch, cluster):
    scene = str(write_scene(tmp_path))
    results = {}
    for backend, options in (("serial", ["--workers", "1"]), ("dask", ["--scheduler", cluster.scheduler_address])):
        monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / f"cache-{backend}"))   # both compute every design
        assert main(["sweep", scene, *GRID, *options, "--out", str(tmp_path / backend)]) == 0
        results[backend] = sorted(read_csv(tmp_path / backend / "sweep.csv"), key=lambda row: int(row["design"]))
    workers = set(cluster.scheduler_info["workers"])
    assert {row["worker"] for row in results["dask"]} <= workers
    assert len({row["worker"] for row in results["dask"]}) == 2
    for serial, dask in zip(results["serial"], results["dask"], strict=True):
        assert serial["status"] == dask["status"] == "completed" and dask["cached"] == "False"
        for key in ("design", "z_tail", "y_thin", "distance_m", "tail_amplitude_m"):
            assert serial[key] == dask[key], key       # the full repr of each float


def test_a_worker_killed_mid_sweep_loses_no_design(tmp_path, monkeypatch, cluster):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = Scene.load(write_scene(tmp_path, duration=0.6))
    designs = sweep.grid_designs(["z_tail=-0.2:0.2:3", "y_thin=0:0.1:2"], scene)
    pool = DaskCluster(ClusterSettings(scheduler=cluster.scheduler_address), SWIMMER_WORKERS)
    killed = []

    def kill_a_busy_worker(row):
        if killed:
            return
        busy = {address: tasks for address, tasks in pool.client.processing().items() if tasks}
        victim = max(busy, key=lambda address: len(busy[address]))
        pid = pool.client.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        killed.append((victim, len(busy[victim])))

    try:
        rows = sweep.run_sweep(scene, designs, "fom", tmp_path / "out", pool, on_row=kill_a_busy_worker)
    finally:
        pool.shutdown()
    assert killed and killed[0][1] >= 1           # the victim held a task when it died
    assert [row["design"] for row in rows] == list(range(6))
    assert all(row["status"] == "completed" for row in rows), [row["reason"] for row in rows]
    written = read_csv(tmp_path / "out" / "sweep.csv")
    assert sorted(int(row["design"]) for row in written) == list(range(6))


def test_a_local_worker_killed_mid_sweep_loses_no_design(tmp_path, monkeypatch):
    """The local backend replaces its broken pool and submits the unfinished designs again."""
    from aquarom_fenics.parallel import LocalProcesses

    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    scene = Scene.load(write_scene(tmp_path, duration=0.6))
    designs = sweep.grid_designs(["z_tail=-0.2:0.2:4"], scene)
    pool = LocalProcesses(2, SWIMMER_WORKERS)
    killed = []

    def kill_a_worker(row):
        if not killed:
            process = next(iter(pool._pool._processes.values()))
            os.kill(process.pid, signal.SIGKILL)
            killed.append(process.pid)

    try:
        rows = sweep.run_sweep(scene, designs, "fom", tmp_path / "out", pool, on_row=kill_a_worker)
    finally:
        pool.shutdown()
    assert killed and [row["design"] for row in rows] == list(range(4))
    assert all(row["status"] == "completed" for row in rows), [row["reason"] for row in rows]
    assert sorted(int(row["design"]) for row in read_csv(tmp_path / "out" / "sweep.csv")) == list(range(4))


def test_a_prom_sweep_answers_designs_beyond_one_validity_radius(tmp_path, capsys):
    """z_tail = ±0.2 lie beyond the radius 0.075 of a PROM at the start design: the atlas answers them from
    the centres of their cells (tests/studies/test_atlas.py tests the atlas itself)."""
    scene = str(write_scene(tmp_path))
    out = tmp_path / "out"
    assert main(["sweep", scene, "--grid", "z_tail=-0.2:0.2:3", "--model", "prom", "--workers", "1",
                 "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [row["status"] for row in rows] == ["completed"] * 3, [row["reason"] for row in rows]
    grid = atlas.cover(Scene.load(scene))                  # the atlas's cells (their size follows RADIUS_SCALE)
    cells = grid.cells([[float(row["z_tail"]), float(row["y_thin"])] for row in rows])
    assert [row["prom_center"] for row in rows] == [atlas.center_id(cell) for cell in cells]
    assert len({row["prom_center"] for row in rows}) == 3 and np.all(grid.half_width <= grid.radius)
    assert all(float(row["tail_amplitude_m"]) > 0 for row in rows)
    assert "PROM atlas: 3 centre(s) used" in capsys.readouterr().out


@pytest.mark.parametrize("names", [["z_tail"], ["z_tail", "y_thin"], ["z_tail", "y_thin", "z_head"]])
def test_the_sweep_figure_for_one_two_and_more_parameters(tmp_path, names):
    from aquarom_fenics.viz.sweep_plot import plot_sweep, varying

    generator = np.random.default_rng(0)
    rows = [{"design": k, **{name: float(generator.uniform(-0.3, 0.3)) for name in names},
             "distance_m": None if k == 3 else float(generator.uniform(0.01, 0.02))} for k in range(9)]
    assert varying(rows, names) == names
    path = plot_sweep(rows, names, tmp_path / "sweep.png", "test")
    assert path.stat().st_size > 10_000


def test_a_prom_sweep_answers_its_designs_in_a_batch_as_single_runs_would(tmp_path, request):
    """The designs of each atlas centre are integrated together (``simulate_batch``), not one
    ``simulate_reduced`` each, and their rows are the single runs' answers to 1e-12."""
    from aquarom_fenics.dynamics import reduced_dynamics

    path = write_scene(tmp_path)
    scene = Scene.load(path)
    designs = sweep.grid_designs(["z_tail=-0.08:0.08:3", "y_thin=0:0.02:2"], scene)
    proms = [sweep.reduced_model(scene, design, "prom") for design in designs]     # y_thin = 0, 0.02 share a centre
    centres = [tuple(prom.xi_center) for prom in proms]
    assert len(set(centres)) >= 2 and all(centres.count(centre) >= 2 for centre in centres)
    expected = [reduced_dynamics.simulate_reduced(prom, scene, np.array([d[n] for n in prom.shape_names]))
                for prom, d in zip(proms, designs)]
    request.getfixturevalue("no_single_reduced_runs")     # from here on, only the batched path may run
    out = tmp_path / "out"
    assert main(["sweep", str(path), "--grid", "z_tail=-0.08:0.08:3", "--grid", "y_thin=0:0.02:2",
                 "--model", "prom", "--workers", "1", "--out", str(out)]) == 0
    rows = read_csv(out / "sweep.csv")
    assert [row["status"] for row in rows] == ["completed"] * 6, [row["reason"] for row in rows]
    for row, single in zip(rows, expected):
        assert abs(float(row["distance_m"]) - single.distance) <= 1e-12 * abs(single.distance)
        assert abs(float(row["tail_amplitude_m"]) - single.tail_amplitude) <= 1e-12 * single.tail_amplitude
