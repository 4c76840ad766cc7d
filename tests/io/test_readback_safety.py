"""Round three of output safety: what the toolkit reads back is untrusted input.

Manifests name only files inside their folder, lock files are never followed through a link,
--force leaves a user's folders and links alone, a resume continues only the same run, and a
write that fails stops the command with what was written before kept.
"""
import errno
import json
import os
from pathlib import Path

import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.errors import InputError
from aquarom_fenics.io import outputs as outputs_module
from aquarom_fenics.io.output_lock import lock_file_of, lock_output, release_output_locks

from conftest import one_line, write_short_scene as write_scene


def simulate(scene, out, *extra) -> int:
    return main(["simulate", scene, "--out", str(out), "--no-progress", *extra])


def earlier_run(tmp_path: Path, files: dict[str, str]) -> Path:
    """A folder that looks like an earlier run: ``files`` (name: content) and a manifest listing them."""
    out = tmp_path / "run"
    out.mkdir()
    for name, content in files.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(content)
    return out


def set_manifest(folder: Path, files: list[str]) -> None:
    (folder / "manifest.json").write_text(json.dumps({"command": "aquarom simulate", "files": files}))


# ---------------------------------------------------------------------- manifests read back
@pytest.mark.parametrize("named", ["../victim.txt", "ABSOLUTE", "sub/../../victim.txt", "./../victim.txt"])
def test_a_manifest_naming_files_outside_its_folder_deletes_nothing_outside(tmp_path, capsys, named):
    scene = write_scene(tmp_path)
    victim = tmp_path / "victim.txt"
    victim.write_text("mine")
    out = earlier_run(tmp_path, {"trajectory.csv": "t\n"})
    set_manifest(out, ["trajectory.csv", str(victim) if named == "ABSOLUTE" else named])
    code = simulate(scene, out, "--force")
    assert victim.read_text() == "mine"
    if code != 0:
        assert code == 2 and "manifest" in one_line(capsys)


def test_removing_a_run_folder_never_follows_a_link(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "data.csv").write_text("mine")
    folder = tmp_path / "run.new-1"
    folder.mkdir()
    os.symlink(outside, folder / "link")
    set_manifest(folder, ["link/data.csv"])
    outputs_module.remove_run_folder(folder)
    assert (outside / "data.csv").read_text() == "mine"


def test_force_keeps_a_users_empty_folder_and_symlink(tmp_path, capsys):
    scene = write_scene(tmp_path)
    out = tmp_path / "prev"
    assert simulate(scene, out) == 0
    (out / "my-empty").mkdir()
    (tmp_path / "elsewhere").mkdir()
    os.symlink(tmp_path / "elsewhere", out / "my-link")
    capsys.readouterr()
    assert simulate(scene, out, "--force") == 2
    assert "did not write" in one_line(capsys)
    assert (out / "my-empty").is_dir() and (out / "my-link").is_symlink()
    assert not [p for p in tmp_path.iterdir() if ".new-" in p.name]


def test_files_added_during_the_swap_are_not_called_a_killed_run(tmp_path, caplog, monkeypatch):
    scene = write_scene(tmp_path)
    out = tmp_path / "prev"
    assert simulate(scene, out) == 0
    original = outputs_module._refuse_foreign
    calls = []

    def add_file_after_the_check(path, verb, kept=""):
        original(path, verb, kept)
        calls.append(verb)
        if verb == "now holds":           # the check at the swap passed; a user adds a file at once
            (Path(path) / "late.txt").write_text("mine")

    monkeypatch.setattr(outputs_module, "_refuse_foreign", add_file_after_the_check)
    assert simulate(scene, out, "--force") == 0
    kept = [p for p in tmp_path.iterdir() if p.name.startswith("prev.") and p.is_dir()]
    assert len(kept) == 1 and (kept[0] / "late.txt").read_text() == "mine"
    assert ".new-" not in kept[0].name
    caplog.clear()
    assert simulate(scene, out, "--force") == 0
    assert "was killed" not in caplog.text


# ---------------------------------------------------------------------- lock files
def test_a_lock_file_that_is_a_symlink_is_refused_and_its_target_untouched(tmp_path, capsys):
    scene = write_scene(tmp_path)
    precious = tmp_path / "precious.txt"
    precious.write_text("my thesis")
    out = tmp_path / "run"
    os.symlink(precious, lock_file_of(out))
    assert simulate(scene, out) == 2
    assert "lock file" in one_line(capsys)
    assert precious.read_text() == "my thesis"


def test_a_lock_file_that_is_a_hard_link_or_a_fifo_is_refused(tmp_path):
    precious = tmp_path / "precious.txt"
    precious.write_text("my thesis")
    os.link(precious, lock_file_of(tmp_path / "a"))
    with pytest.raises(InputError, match="lock file"):
        lock_output(tmp_path / "a")
    assert precious.read_text() == "my thesis"
    os.mkfifo(lock_file_of(tmp_path / "b"))
    with pytest.raises(InputError, match="not a regular file"):
        lock_output(tmp_path / "b")
    release_output_locks()


# ---------------------------------------------------------------------- PROM files
@pytest.fixture(scope="module")
def prom_file(tmp_path_factory):
    directory = tmp_path_factory.mktemp("prom")
    scene = write_scene(directory)
    assert main(["build", scene, "--out", str(directory / "p.npz")]) == 0
    return scene, directory / "p.npz"


def rewrite_prom(source: Path, target: Path, edit_header=None, drop: str | None = None) -> Path:
    import numpy as np

    with np.load(source) as data:
        arrays = {key: data[key] for key in data.files}
    header = json.loads(arrays["header"].tobytes().decode())
    if edit_header is not None:
        header = edit_header(header)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    if drop is not None:
        arrays.pop(drop)
    np.savez(target, **arrays)
    return target


def drop_y_thin(header):
    header["shape_names"] = ["z_tail"]
    header["design_point"].pop("y_thin")
    return header


def without(key):
    def edit(header):
        header.pop(key)
        return header
    return edit


@pytest.mark.parametrize("edit, drop, named", [
    (drop_y_thin, None, "shape_names"),
    (lambda header: [header], None, "header"),
    (without("scene_hash"), None, "scene_hash"),
    (without("prom_hash"), None, "prom_hash"),
    (without("labels"), None, "labels"),
    (None, "basis", "basis"),
    (None, "elastic.cubic.first", "elastic.cubic.first"),
    (lambda header: header | {"labels": header["labels"][:-1]}, None, "labels"),
])
def test_a_prom_header_is_checked_against_its_arrays(prom_file, tmp_path, capsys, edit, drop, named):
    scene, source = prom_file
    damaged = rewrite_prom(source, tmp_path / "damaged.npz", edit, drop)
    code = main(["simulate", scene, "--model", "prom", "--prom", str(damaged), "--xi", "y_thin=0.02",
                 "--out", str(tmp_path / "run")])
    assert code == 2
    message = one_line(capsys)
    assert "PROM file" in message and named in message
    assert not (tmp_path / "run").exists()


# ---------------------------------------------------------------------- sweeps: resume, damaged sweep.csv, full disk
GRID = ["--grid", "z_tail=-0.1:0.1:3"]


def sweep(scene, out, *extra) -> int:
    return main(["sweep", scene, *GRID, "--workers", "1", "--out", str(out), *extra])


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    directory = tmp_path_factory.mktemp("swept")
    scene = write_scene(directory)
    assert sweep(scene, directory / "s") == 0
    return directory, scene, directory / "s"


def copy_of(folder: Path, target: Path) -> Path:
    import shutil

    shutil.copytree(folder, target)
    return target


@pytest.mark.parametrize("options, named", [
    (["--model", "rom"], "--model"),
    (["--set", "solver.duration=0.3"], "scene"),
])
def test_sweep_resume_refuses_another_run(swept, tmp_path, capsys, options, named):
    directory, scene, out = swept
    copy = copy_of(out, tmp_path / "s")
    before = (copy / "sweep.csv").read_text()
    assert sweep(scene, copy, "--resume", *options) == 2
    message = one_line(capsys)
    assert "--resume" in message and named in message
    assert (copy / "sweep.csv").read_text() == before


def test_sweep_resume_after_kill_lists_every_file(swept, tmp_path):
    directory, scene, out = swept
    copy = copy_of(out, tmp_path / "s")
    (copy / "manifest.json").unlink()               # killed outright: no manifest was written
    lines = (copy / "sweep.csv").read_text().splitlines()
    (copy / "sweep.csv").write_text("\n".join(lines[:2]) + "\n")
    assert sweep(scene, copy, "--resume") == 0
    listed = json.loads((copy / "manifest.json").read_text())["files"]
    assert "sweep.csv" in listed and "sweep.png" in listed


@pytest.mark.parametrize("damage, named", [
    (lambda text: text.replace(",completed,", ",done,", 1), "status"),
    (lambda text: text.replace("\n0,", "\n0.0,", 1), "design"),
    (lambda text: text.replace("\n1,-0.1,", "\n1,abc,", 1) if "\n1,-0.1," in text else text.replace("\n1,", "\n1x,", 1),
     "line 3"),
    (lambda text: text + "\x00\xff\n", "sweep.csv"),
])
def test_a_damaged_sweep_csv_is_one_line_on_resume(swept, tmp_path, capsys, damage, named):
    directory, scene, out = swept
    copy = copy_of(out, tmp_path / "s")
    text = damage((copy / "sweep.csv").read_text())
    (copy / "sweep.csv").write_bytes(text.encode("utf-8", errors="surrogateescape"))
    assert sweep(scene, copy, "--resume") == 2
    message = one_line(capsys)
    assert "sweep.csv" in message and named in message


def test_an_empty_distance_of_a_completed_row_is_refused(swept, tmp_path, capsys):
    directory, scene, out = swept
    copy = copy_of(out, tmp_path / "s")
    lines = (copy / "sweep.csv").read_text().splitlines()
    cells = lines[1].split(",")
    cells[4] = ""
    lines[1] = ",".join(cells)
    (copy / "sweep.csv").write_text("\n".join(lines) + "\n")
    assert sweep(scene, copy, "--resume") == 2
    assert "distance_m" in one_line(capsys)


def test_a_partial_last_line_of_sweep_csv_is_dropped_with_a_note(swept, tmp_path, capsys, caplog):
    directory, scene, out = swept
    copy = copy_of(out, tmp_path / "s")
    text = (copy / "sweep.csv").read_text()
    (copy / "sweep.csv").write_text(text[:-25])       # killed while the last row was written
    assert sweep(scene, copy, "--resume") == 0
    assert "partial last line" in caplog.text
    rows = (copy / "sweep.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[:3] == text.splitlines()[:3]


def test_a_full_cache_stops_the_sweep_with_the_rows_before_kept(tmp_path, capsys, monkeypatch):
    from aquarom_fenics.io import persistence

    scene = write_scene(tmp_path)
    original = persistence.write_json_atomic
    stored = []

    def full_after_one(path, data):
        if "fom" in Path(path).parts:
            if stored:
                raise OSError(errno.ENOSPC, "No space left on device", str(path))
            stored.append(path)
        return original(path, data)

    monkeypatch.setattr(persistence, "write_json_atomic", full_after_one)
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "s"
    assert sweep(scene, out) == 2
    assert "No space left on device" in one_line(capsys)
    rows = (out / "sweep.csv").read_text().splitlines()
    assert len(rows) == 2 and ",completed," in rows[1]


# ---------------------------------------------------------------------- optimisations: resume only the same run
OPTIMIZE = """
[mesh]
level = 1
[solver]
duration = 0.4
[fluid]
drag = false
[optimizer]
max_iterations = 3
[shapes]
z_tail = { bounds = [-0.2, 0.2] }
y_thin = { bounds = [-0.1, 0.1] }
"""

CO = OPTIMIZE + """
[actuation]
amplitude = 0.2
[cooptimization]
enabled = true
amplitude_bounds = [0.05, 0.4]
weights = [0.5, 0.9]
"""


@pytest.fixture(scope="module")
def optimized(tmp_path_factory):
    directory = tmp_path_factory.mktemp("optimized")
    scene = directory / "o.toml"      # first-order optimal at the start: the run stops after its first row
    scene.write_text(OPTIMIZE.replace("max_iterations = 3", "max_iterations = 3\noptimality_tolerance = 0.845"))
    out = directory / "o1"
    assert main(["optimize", str(scene), "--out", str(out)]) == 0
    return directory, str(scene), out


def test_optimize_resume_refuses_another_weight(tmp_path, capsys):
    scene = tmp_path / "co.toml"
    scene.write_text(CO)
    out = tmp_path / "o"
    out.mkdir()
    (out / "checkpoint.json").write_text("{}")
    from aquarom_fenics.io.run_record import write_run_record
    from aquarom_fenics.io.scene import Scene
    from aquarom_fenics.optimization.cost import CostWeights
    from aquarom_fenics.studies.study import optimization_record

    loaded = Scene.load(str(scene))
    write_run_record(out, optimization_record(loaded, CostWeights(0.5, 0.5, loaded.cooptimization.energy_weight), None))
    before = sorted(os.listdir(out))
    assert main(["optimize", str(scene), "--out", str(out), "--resume", "--weight", "0.7"]) == 2
    message = one_line(capsys)
    assert "--weight" in message and "--resume" in message
    assert sorted(os.listdir(out)) == before


def test_a_resume_after_an_interrupt_in_the_fom_check_repeats_no_iteration(optimized, tmp_path, capsys, monkeypatch):
    from aquarom_fenics.studies import study

    _, scene, fresh = optimized
    original = study.fom_check

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(study, "fom_check", interrupted)
    out = tmp_path / "o"
    assert main(["optimize", scene, "--out", str(out)]) == 130
    monkeypatch.setattr(study, "fom_check", original)
    assert main(["optimize", scene, "--out", str(out), "--resume"]) == 0
    resumed = (out / "history.csv").read_text().splitlines()
    straight = (fresh / "history.csv").read_text().splitlines()
    assert len(resumed) == len(straight)
    iterations = [line.split(",")[0] for line in resumed[1:]]
    assert len(set(iterations)) == len(iterations)
    summaries = [json.loads((folder / "summary.json").read_text()) for folder in (out, fresh)]
    assert summaries[0]["optimum"] == summaries[1]["optimum"]
    assert summaries[0]["prom_builds"] == summaries[1]["prom_builds"]


# ---------------------------------------------------------------------- Pareto weights: one folder per exact value
def test_pareto_weights_that_print_alike_get_their_own_folders():
    from aquarom_fenics.studies.study import weight_folder

    assert weight_folder(0.9) == "w1_0.9" and weight_folder(0.25) == "w1_0.25"
    assert weight_folder(0.9000001) != weight_folder(0.9)
    assert float(weight_folder(0.9000001)[3:]) == 0.9000001


def test_a_pareto_weight_given_twice_is_refused(tmp_path, capsys):
    scene = tmp_path / "co.toml"
    scene.write_text(CO.replace("weights = [0.5, 0.9]", "weights = [0.5, 0.9, 0.5]"))
    assert main(["pareto", str(scene), "--out", str(tmp_path / "p"), "--dry-run"]) == 2
    assert "twice" in one_line(capsys)


# ---------------------------------------------------------------------- bounds before allocation, odd files
@pytest.mark.parametrize("options, named", [
    (["--grid", "z_tail=0:1:999999999999"], "designs"),
    (["--grid", "z_tail=0:0.1:1000", "--grid", "y_thin=0:0.1:1000"], "designs"),
    (["--samples", "1000000000000"], "--samples"),
])
def test_sweep_sizes_are_bounded_before_allocation(tmp_path, capsys, options, named):
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, *options, "--dry-run"]) == 2
    assert named in one_line(capsys)


@pytest.mark.parametrize("setting, named", [
    ("solver.time_step=5e-324", "time_step"),
    ("solver.duration=1e300", "duration"),
    ("reduction.vibration_modes=2000", "vibration_modes"),
    ("reduction.vibration_modes=40", "--allow-large"),
])
def test_scene_values_that_would_allocate_without_bound_are_refused(tmp_path, capsys, setting, named):
    scene = write_scene(tmp_path)
    assert main(["build", scene, "--set", setting, "--dry-run"]) == 2
    assert named in one_line(capsys)


def test_a_plan_over_an_hour_needs_allow_large(tmp_path, capsys):
    scene = write_scene(tmp_path)
    assert main(["simulate", scene, "--level", "5", "--degree", "2", "--set", "solver.duration=60", "--dry-run"]) == 2
    message = one_line(capsys)
    assert "--allow-large" in message and " h " in message


def test_the_dry_run_estimate_covers_the_eigensolves(tmp_path, capsys):
    scene = write_scene(tmp_path)
    estimates = []
    for modes in (1, 6):
        assert main(["build", scene, "--set", f"reduction.vibration_modes={modes}", "--dry-run"]) == 0
        out = capsys.readouterr().out
        assert "vibration mode(s)" in out
        estimates.append(float(out.split("estimate: ~")[1].split(" s")[0]))
    assert estimates[1] > 2 * estimates[0]


@pytest.mark.parametrize("kind", ["fifo", "device", "loop"])
@pytest.mark.parametrize("option", ["--designs", "--prom", "mesh"])
def test_odd_files_are_refused_without_hanging(tmp_path, capsys, kind, option):
    odd = tmp_path / ("odd.inp" if option == "mesh" else "odd.csv" if option == "--designs" else "odd.npz")
    if kind == "fifo":
        os.mkfifo(odd)
    elif kind == "device":
        odd = Path("/dev/zero")
    else:
        os.symlink(tmp_path / "loop", tmp_path / "loop")
        os.symlink(tmp_path / "loop", odd)
    if option == "mesh":
        scene = tmp_path / "m.toml"
        scene.write_text(f'[mesh]\nfile = "{odd}"\n')
        argv = ["mesh", str(scene)]
    elif option == "--designs":
        argv = ["sweep", write_scene(tmp_path), "--designs", str(odd), "--dry-run"]
    else:
        argv = ["simulate", write_scene(tmp_path), "--model", "prom", "--prom", str(odd), "--out", str(tmp_path / "r")]
    assert main(argv) == 2
    message = one_line(capsys)
    assert str(odd) in message


def test_a_design_csv_with_a_byte_order_mark_is_read(tmp_path, capsys):
    scene = write_scene(tmp_path)
    (tmp_path / "d.csv").write_bytes("\ufeffz_tail,y_thin\n0.1,0.0\n".encode("utf-8"))
    assert main(["sweep", scene, "--designs", str(tmp_path / "d.csv"), "--dry-run"]) == 0
    assert "designs: 1" in capsys.readouterr().out


def test_a_design_csv_field_over_the_csv_limit_is_one_line(tmp_path, capsys):
    scene = write_scene(tmp_path)
    (tmp_path / "d.csv").write_text("z_tail\n" + "1" * 200_000 + "\n")
    assert main(["sweep", scene, "--designs", str(tmp_path / "d.csv"), "--dry-run"]) == 2
    assert "--designs" in one_line(capsys)


def test_an_abaqus_label_beyond_64_bits_is_one_line(tmp_path, capsys):
    mesh = tmp_path / "big.inp"
    mesh.write_text("*Node\n100000000000000000000, 0, 0, 0\n2, 1, 0, 0\n3, 0, 1, 0\n4, 0, 0, 1\n"
                    "*Element, type=C3D4\n1, 100000000000000000000, 2, 3, 4\n")
    scene = tmp_path / "m.toml"
    scene.write_text(f'[mesh]\nfile = "{mesh}"\n')
    assert main(["mesh", str(scene)]) == 2
    assert "big.inp" in one_line(capsys)


@pytest.mark.parametrize("options, named", [
    (["--scheduler", ""], "--scheduler"),
    (["--scheduler", "ucx://127.0.0.1:8786"], "ucx://"),
    (["--scheduler", "tcp://host:99999"], "port"),
    (["--scheduler", "tcp://127.0.0.1:1", "--connect-timeout", "inf"], "--connect-timeout"),
])
def test_cluster_options_are_checked_in_one_line(tmp_path, capsys, options, named):
    scene = write_scene(tmp_path)
    assert main(["sweep", scene, "--samples", "2", *options, "--dry-run"]) == 2
    assert named in one_line(capsys)


@pytest.mark.parametrize("content, named", [
    ("", "scheduler file"), ('{"address": ', "scheduler file"), ("garbage", "scheduler file"),
    ('{"address": 8786}', "address"), ('{"address": "ucx://127.0.0.1:1"}', "ucx://"),
])
def test_damaged_scheduler_files_are_one_line(tmp_path, capsys, content, named):
    scene = write_scene(tmp_path)
    (tmp_path / "scheduler.json").write_text(content)
    assert main(["sweep", scene, "--samples", "2", "--scheduler-file", str(tmp_path / "scheduler.json"),
                 "--connect-timeout", "1", "--out", str(tmp_path / "s")]) == 2
    assert named in one_line(capsys)
    assert not (tmp_path / "s").exists()


def test_the_root_folder_is_no_output(tmp_path, capsys):
    scene = write_scene(tmp_path)
    assert simulate(scene, "/") == 2
    assert "root folder" in one_line(capsys)


def test_local_pool_workers_know_they_are_workers():
    from aquarom_fenics.parallel import LocalProcesses, in_worker

    pool = LocalProcesses(1)
    try:
        assert pool.submit(in_worker).result(timeout=120) is True
    finally:
        pool.shutdown()
    assert in_worker() is False


# ---------------------------------------------------------------------- every process it starts, it stops
def test_ctrl_c_of_a_pareto_sweep_on_two_workers_leaves_no_process(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    psutil = pytest.importorskip("psutil")
    scene = tmp_path / "co.toml"
    # long enough that the interrupt always lands inside the weights' tasks, however fast the host
    scene.write_text(CO.replace("duration = 0.4", "duration = 2.0").replace("max_iterations = 3", "max_iterations = 200"))
    command = [str(Path(sys.executable).with_name("aquarom")), "pareto", str(scene), "--workers", "2",
               "--out", str(tmp_path / "p")]
    # as in an interactive terminal: a shell starts background jobs (a background `make test`) with
    # SIGINT ignored, which the command rightly keeps ignored; the child gets Ctrl-C's default back
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True, env=os.environ | {"AQUAROM_CACHE": str(tmp_path / "cache")},
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    parent = psutil.Process(process.pid)
    everything = []
    try:
        deadline = time.monotonic() + 240
        workers = []
        while time.monotonic() < deadline and process.poll() is None:
            workers = [child for child in parent.children(recursive=True) if "python" in child.name()]
            if len(workers) >= 2:
                break
            time.sleep(0.5)
        assert len(workers) >= 2, "the two workers did not start"
        time.sleep(5)                                   # inside their tasks
        everything = parent.children(recursive=True)
        os.killpg(process.pid, signal.SIGINT)           # Ctrl-C reaches the whole process group
        _, err = process.communicate(timeout=120)
        assert process.returncode == 130, err
        assert "Traceback" not in err and len([line for line in err.splitlines() if line.strip()]) == 1, err
        gone, alive = psutil.wait_procs(everything, timeout=15)
        assert not alive, [p.cmdline() for p in alive]
    finally:                                            # whatever failed, this test leaves nothing running
        for leftover in [parent, *everything]:
            try:
                leftover.kill()
            except psutil.Error:
                pass


def test_a_dry_run_refuses_a_missing_mesh_file(tmp_path, capsys):
    scene = tmp_path / "m.toml"
    scene.write_text('[mesh]\nfile = "nope.inp"\n[solver]\nduration = 0.2\n')
    assert main(["simulate", str(scene), "--dry-run"]) == 2
    message = one_line(capsys)
    assert "nope.inp" in message and "not found" in message
