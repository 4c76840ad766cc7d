"""Dry runs, safe outputs, manifests and content-addressed caches."""
import json
import logging
import time

import pytest

from aquarom_fenics.io.paths import cache_root
from aquarom_fenics.cli import main
from aquarom_fenics.io.scene import Scene

TOY = """
[mesh]
level = 1
[solver]
duration = 1.0
[fluid]
drag = false
[optimizer]
max_iterations = 6
[shapes]
z_tail = { bounds = [-0.2, 0.2] }
y_thin = { bounds = [-0.1, 0.1] }
"""


def write_scene(directory):
    path = directory / "toy.toml"
    path.write_text(TOY)
    return str(path)


def test_dry_run_prints_a_plan_and_writes_nothing(tmp_path, capsys):
    scene = write_scene(tmp_path)
    for command in (["simulate", scene, "--model", "prom"], ["optimize", scene], ["build", scene], ["compare", scene]):
        assert main([*command, "--dry-run", "--out", str(tmp_path / "out")]) == 0
        text = capsys.readouterr().out
        assert "dry run" in text and "estimate" in text
        assert not (tmp_path / "out").exists()
    main(["optimize", scene, "--dry-run"])
    text = capsys.readouterr().out
    assert "skipped: drag" in text and "xi_1_1" in text and "FOM checks" in text


def test_dry_run_says_whether_the_tail_screen_runs_and_adds_its_time(capsys):
    from aquarom_fenics.studies.estimate import TAIL_SCREEN_SECONDS_PER_STATE, tail_screen_seconds

    main(["optimize", "co", "--dry-run", "--set", "optimizer.tail_screen=true"])   # off in the shipped CO scene
    text = capsys.readouterr().out
    screen = 51 * TAIL_SCREEN_SECONDS_PER_STATE         # the last stroke at h = 0.02 s: 51 states
    assert "then the tail screen (the FOM's tail region within 0.015 m" in text
    assert f"~{screen:.0f} s per screen" in text
    main(["optimize", "so1", "--dry-run"])
    assert "tail screen skipped ([optimizer] tail_screen = false)" in capsys.readouterr().out
    main(["optimize", "co", "--dry-run"])
    assert "tail screen skipped ([optimizer] tail_screen = false)" in capsys.readouterr().out
    co = Scene.load("co").replace("optimizer", tail_screen=True)
    assert tail_screen_seconds(co) == pytest.approx(screen)
    assert tail_screen_seconds(co.replace("solver", time_step=0.01)) == pytest.approx(screen)   # every 0.02 s
    assert tail_screen_seconds(co.replace("solver", duration=1.0)) == 0.0                      # one stroke: not judged


def test_existing_outputs_are_kept_unless_forced_and_a_manifest_is_written(tmp_path, capsys):
    scene = write_scene(tmp_path)
    out = tmp_path / "run"
    assert main(["simulate", scene, "--model", "rom", "--out", str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["scene"]["hash"] and manifest["host_cores"] >= 1 and manifest["versions"]["dolfinx"]
    assert manifest["timings"]["total"] > 0
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(["simulate", scene, "--model", "rom", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine"
    assert main(["simulate", scene, "--model", "rom", "--out", str(out), "--force"]) == 2
    assert "did not write (notes.txt)" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine"
    (out / "notes.txt").unlink()
    assert main(["simulate", scene, "--model", "rom", "--out", str(out), "--force"]) == 0
    assert (out / "trajectory.csv").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["run", "toy.toml"]
    assert "trajectory.csv" in json.loads((out / "manifest.json").read_text())["files"]


def test_truncated_prom_cache_entry_is_detected_and_rebuilt(tmp_path, caplog):
    scene = write_scene(tmp_path)
    assert main(["simulate", scene, "--model", "prom", "--out", str(tmp_path / "a")]) == 0
    entries = sorted((cache_root() / "prom").glob("*.npz"))
    assert entries
    newest = max(entries, key=lambda p: p.stat().st_mtime)
    newest.write_bytes(newest.read_bytes()[:1000])
    with caplog.at_level(logging.INFO, logger="aquarom"):
        assert main(["simulate", scene, "--model", "prom", "--out", str(tmp_path / "b")]) == 0
    assert "corrupted" in caplog.text and "built and stored" in caplog.text
    first = json.loads((tmp_path / "a" / "summary.json").read_text())["distance"]
    second = json.loads((tmp_path / "b" / "summary.json").read_text())["distance"]
    assert first == second


def test_second_identical_optimisation_reuses_every_prom(tmp_path, caplog, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))   # empty: the first run builds everything
    scene = write_scene(tmp_path)
    timings, reused = [], []
    for run in ("first", "second"):
        caplog.clear()
        started = time.perf_counter()
        with caplog.at_level(logging.INFO, logger="aquarom"):
            assert main(["optimize", scene, "--out", str(tmp_path / run)]) == 0
        timings.append(time.perf_counter() - started)
        summary = json.loads((tmp_path / run / "summary.json").read_text())
        reused.append(summary["prom_builds_reused_from_cache"])
        log = caplog.text
    builds = summary["prom_builds"]
    assert log.count("PROM cache: reused") == builds and "built and stored" not in log
    assert reused == [0, builds]
    assert "FOM at" in log and "reused from the cache" in log
    assert timings[1] < timings[0]


def test_every_command_help_shows_an_example(capsys):
    import pytest

    from aquarom_fenics.cli import COMMANDS

    for command in COMMANDS:
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "example:" in capsys.readouterr().out, command
