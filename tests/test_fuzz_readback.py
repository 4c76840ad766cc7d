"""Files read back and sweep/Dask options never end in another exception than a one-line InputError.

Property-based (Hypothesis), derandomised, beside the scene and command-line fuzz: manifests (and
what --force then removes: nothing outside the folder, nothing unlisted), checkpoints, sweep.csv,
PROM headers, scheduler files, and the --grid, --samples, --scheduler and --connect-timeout
values. Every case ends in a value or an InputError whose message is one line.
"""
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aquarom_fenics.errors import InputError
from aquarom_fenics.io import outputs

from conftest import coarse_scene

FUZZ = dict(derandomize=True, database=None, deadline=None, max_examples=150,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                   HealthCheck.data_too_large])

NAMES = st.one_of(
    st.sampled_from(["trajectory.csv", "summary.json", "sub/a.txt", "sub/", "../victim.txt", "/etc/hostname",
                     "sub/../../victim.txt", "link/data.csv", "link", ".", "..", "", "a//b", "./x", "sub/./a.txt",
                     "nul\x00name", "manifest.json", "empty/"]),
    st.text(alphabet="ab./\\-_ ", max_size=12))
JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=False, allow_infinity=False),
              st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12)


def one_line(error: InputError) -> None:
    text = str(error)
    assert text and "\n" not in text and "Traceback" not in text, text


def expect_value_or_input_error(action):
    """``action()``'s value, or None after an InputError of one line; any other exception fails."""
    try:
        return action()
    except InputError as error:
        one_line(error)
        return None


SCENE = coarse_scene(solver={"duration": 0.2},
                     shapes={"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1]}})


# ---------------------------------------------------------------------- manifests and what --force removes
@pytest.fixture
def sandbox(tmp_path):
    return tmp_path


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink()}


@settings(**FUZZ)
@given(files=st.one_of(st.lists(NAMES, max_size=6), JSON_VALUES), raw=st.one_of(st.none(), st.binary(max_size=40)))
def test_a_manifest_of_any_content_removes_nothing_outside_nor_unlisted(sandbox, files, raw):
    root = sandbox / "case"
    shutil.rmtree(root, ignore_errors=True)
    outside = root / "outside"
    outside.mkdir(parents=True)
    (outside / "data.csv").write_text("mine")
    (root / "victim.txt").write_text("mine")
    folder = root / "run"
    (folder / "sub").mkdir(parents=True)
    (folder / "empty").mkdir()
    (folder / "trajectory.csv").write_text("t")
    (folder / "sub" / "a.txt").write_text("a")
    os.symlink(outside, folder / "link")
    manifest = folder / "manifest.json"
    if raw is not None:
        manifest.write_bytes(raw)
    else:
        manifest.write_text(json.dumps({"files": files}))
    before_outside = snapshot(outside) | {"victim.txt": (root / "victim.txt").read_bytes()}
    listed = outputs.manifest_files(folder)
    present = set(outputs.files_in(folder))
    expect_value_or_input_error(lambda: outputs.foreign_files(folder))
    left = outputs.remove_run_folder(folder)
    assert snapshot(outside) | {"victim.txt": (root / "victim.txt").read_bytes()} == before_outside
    unlisted = present - set(listed or []) - {"manifest.json"}
    for name in unlisted:                      # what the manifest does not list stays
        assert name in left, (name, listed, left)


# ---------------------------------------------------------------------- checkpoints
@pytest.fixture(scope="module")
def checkpoint_text():
    state = {"center": [0.0, 0.0], "radius": 0.5, "iteration": 2, "cuts": []}
    history = [{"iteration": 0, "wall_time": 0.1}, {"iteration": 1, "wall_time": 0.2}]
    return json.dumps({"scene_hash": "abc", "method": "trust-region", "state": state, "history": history,
                       "builds": 2, "build_time": 1.0, "solve_time": 0.5})


@settings(**FUZZ)
@given(cut=st.integers(0, 400), insert=st.text(max_size=6), value=JSON_VALUES,
       key=st.sampled_from(["scene_hash", "method", "state", "history", "builds", "build_time", "basis_center"]))
def test_a_damaged_checkpoint_loads_or_is_one_line(tmp_path, checkpoint_text, cut, insert, value, key):
    from aquarom_fenics.io.readback import load_checkpoint

    path = tmp_path / "checkpoint.json"
    data = json.loads(checkpoint_text)
    data[key] = value
    text = json.dumps(data)
    path.write_text(text[:cut] + insert + text[cut:] if cut % 3 else text)
    expect_value_or_input_error(lambda: load_checkpoint(path, 2, "trust-region", 2))


# ---------------------------------------------------------------------- sweep.csv
HEADER = "design,z_tail,y_thin,status,distance_m,tail_amplitude_m,wall_time_s,cached,worker,reason"
CELLS = st.one_of(st.sampled_from(["0", "1", "1.0", "-0.1", "0.1", "nan", "inf", "", "completed", "refused",
                                   "True", "False", "x", "1e400", "\x00", "\ufeff0"]),
                  st.text(max_size=5))


@settings(**FUZZ)
@given(rows=st.lists(st.lists(CELLS, min_size=0, max_size=12), max_size=4), cut=st.integers(0, 3),
       header=st.sampled_from([HEADER, HEADER.replace("design", "desing"), "", HEADER + ",extra"]),
       tail=st.binary(max_size=6))
def test_a_hand_edited_sweep_csv_reads_or_is_one_line(tmp_path, rows, cut, header, tail):
    from aquarom_fenics.studies.sweep import read_rows, resumed_rows

    path = tmp_path / "sweep.csv"
    text = header + "\n" + "".join(",".join(row) + "\n" for row in rows)
    path.write_bytes(text.encode("utf-8", errors="replace")[:len(text) - cut] + (tail if cut == 3 else b""))
    designs = [{"z_tail": -0.1, "y_thin": 0.0}, {"z_tail": 0.1, "y_thin": 0.0}]
    read = expect_value_or_input_error(lambda: read_rows(path, SCENE))
    if read is not None:
        for row in read:
            assert isinstance(row["design"], int) and row["status"] in ("completed", "refused", "stopped", "error")
            if row["status"] == "completed":
                assert math.isfinite(row["distance_m"])
        expect_value_or_input_error(lambda: resumed_rows(path, SCENE, designs))


# ---------------------------------------------------------------------- PROM headers
@pytest.fixture(scope="module")
def prom_arrays(tmp_path_factory):
    from aquarom_fenics.reduction.reductor import build_prom

    path = tmp_path_factory.mktemp("prom") / "p.npz"
    build_prom(SCENE).save(path)
    with np.load(path) as data:
        return {key: data[key] for key in data.files}


@settings(**{**FUZZ, "max_examples": 60})
@given(key=st.sampled_from(["scene_hash", "shape_names", "labels", "design_point", "format_version", "dropped",
                            "software_version", "cells", "inertia.rayleigh_alpha", "elastic.linear.second"]),
       value=JSON_VALUES, whole=st.one_of(st.none(), JSON_VALUES),
       drop=st.one_of(st.none(), st.sampled_from(["basis", "xi_center", "elastic.linear.first", "thrust.rows"])))
def test_a_damaged_prom_header_loads_or_is_one_line(tmp_path, prom_arrays, key, value, whole, drop):
    from aquarom_fenics.reduction.prom import ReducedModel

    arrays = dict(prom_arrays)
    header = json.loads(arrays["header"].tobytes().decode())
    header[key] = value
    arrays["header"] = np.frombuffer(json.dumps(header if whole is None else whole).encode(), dtype=np.uint8)
    if drop is not None:
        arrays.pop(drop)
    path = tmp_path / "p.npz"
    np.savez(path, **arrays)
    model = expect_value_or_input_error(lambda: ReducedModel.load(path))
    if model is not None:
        assert model.xi_center.shape == (len(model.shape_names),)


# ---------------------------------------------------------------------- scheduler files and sweep/Dask options
@settings(**FUZZ)
@given(content=st.one_of(st.binary(max_size=60), JSON_VALUES.map(json.dumps),
                         st.sampled_from(['{"address": "tcp://127.0.0.1:8786"}', '{"address": "ucx://h:1"}',
                                          '{"address": 1}', '{"address": ""}', '{"address": "tcp://:0"}'])))
def test_a_scheduler_file_of_any_content_gives_an_address_or_one_line(tmp_path, content):
    from aquarom_fenics.parallel import scheduler_file_address

    path = tmp_path / "scheduler.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    address = expect_value_or_input_error(lambda: scheduler_file_address(path))
    if address is not None:
        assert address.split("://")[0] in ("tcp", "tls")


AXIS = st.one_of(st.sampled_from(["z_tail", "y_thin", "x", ""]), st.text(max_size=4))
NUMBER = st.one_of(st.sampled_from(["0", "1", "-0.1", "nan", "inf", "1e400", "", "0x10", "999999999999"]),
                   st.text(max_size=4))


@settings(**FUZZ)
@given(specs=st.lists(st.tuples(AXIS, NUMBER, NUMBER, NUMBER, st.sampled_from(["=", ":", ""])), min_size=1,
                      max_size=3),
       samples=st.integers(-5, 10 ** 13), seed=st.integers(-2, 2 ** 40))
def test_sweep_design_options_give_bounded_designs_or_one_line(specs, samples, seed):
    from aquarom_fenics.studies.sweep import MAX_DESIGNS, grid_designs, latin_hypercube

    grid = [f"{name}{sep}{low}:{high}:{count}" for name, low, high, count, sep in specs]
    designs = expect_value_or_input_error(lambda: grid_designs(grid, SCENE))
    if designs is not None:
        assert 1 <= len(designs) <= MAX_DESIGNS
    if samples <= 2000:
        drawn = expect_value_or_input_error(lambda: latin_hypercube(SCENE, samples, seed))
        if drawn is not None:
            assert len(drawn) == samples
    elif samples > MAX_DESIGNS:
        assert expect_value_or_input_error(lambda: latin_hypercube(SCENE, samples, seed)) is None


@settings(**FUZZ)
@given(scheduler=st.one_of(st.none(), st.text(max_size=30),
                           st.sampled_from(["", " ", "tcp://h:8786", "ucx://h:1", "tcp://h:99999", "h:1", "tls://[::1]:1",
                                            "tcp://h:8786/x", "inproc://a"])),
       timeout=st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True)),
       table=st.dictionaries(st.sampled_from(["scheduler", "scheduler_file", "connect_timeout", "other"]),
                             JSON_VALUES, max_size=3))
def test_dask_options_give_settings_or_one_line(tmp_path, scheduler, timeout, table):
    from aquarom_fenics.parallel import choose_cluster, cluster_from_table

    configured = expect_value_or_input_error(lambda: cluster_from_table(table, "scene s.toml", str(tmp_path)))
    chosen = expect_value_or_input_error(lambda: choose_cluster(scheduler, None, configured, timeout))
    if chosen is not None:
        assert chosen.connect_timeout > 0 and math.isfinite(chosen.connect_timeout)
