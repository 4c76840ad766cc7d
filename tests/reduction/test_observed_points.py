"""The observed points tail x and centre-of-mass y (issue 52): the FOM reports them, the reduced model's
rows give the FOM's values on its basis exactly, both runs write them to trajectory.csv, and a PROM file
written before they existed is refused in one line (and rebuilt when it sits in the cache)."""
import json

import numpy as np
import pytest

from aquarom_fenics.cli import main
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.errors import InputError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.readback import load_trajectory
from aquarom_fenics.io.tables import write_trajectory_csv
from aquarom_fenics.reduction.cache import cached_prom
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene, one_line

POINTS = ("head_x", "tail_y", "com_x", "tail_x", "com_y")


@pytest.fixture(scope="module")
def scene():
    return coarse_scene(solver={"duration": 0.1})


@pytest.fixture(scope="module")
def prom(scene):
    return build_prom(scene, parametric=False)


@pytest.fixture(scope="module")
def fom(scene):
    model = FullOrderModel(scene, load_fish(scene), None)
    yield model
    model.destroy()


def test_a_rigid_translation_moves_every_observed_point_by_itself(fom):
    """u = e_x everywhere: head, tail and centre of mass move 1 in x, 0 in y; u = e_y the converse."""
    for axis, moved in ((0, ("head_x", "com_x", "tail_x")), (1, ("tail_y", "com_y"))):
        nodal = np.zeros((fom.fish.nodes.points.shape[0], 3))
        nodal[:, axis] = 1.0
        values = fom.observables(fom.owned_values(nodal))
        for name in POINTS:
            assert values[name] == pytest.approx(1.0 if name in moved else 0.0, abs=1e-12), (axis, name)


def test_the_reduced_rows_give_the_fom_s_points_on_the_basis(fom, prom):
    """u = V η: the PROM's observables of η equal the FOM's of u to rounding (tail x and com y included)."""
    from aquarom_fenics.dynamics.integrator import TimeScheme
    from aquarom_fenics.dynamics.reduced_dynamics import ReducedSystem

    system = ReducedSystem(prom, fom.scene, prom.xi_center, TimeScheme.from_solver(fom.scene.solver))
    eta = np.random.default_rng(5).standard_normal(prom.size) * 1e-3
    u = sum(fom.owned_values(prom.basis[:, :, j]) * eta[j] for j in range(prom.size))
    values = fom.observables(u)
    reduced = dict(zip(POINTS, system.observables(eta)))
    for name in POINTS:
        assert reduced[name] == pytest.approx(values[name], rel=1e-10, abs=1e-15), name
    assert abs(values["tail_x"]) > 0 and abs(values["com_y"]) > 0


def test_reduced_and_fom_runs_write_tail_x_and_com_y(scene, prom, tmp_path):
    arrays = simulate_reduced(prom, scene).trajectory.arrays()
    assert np.abs(arrays["tail_y"]).max() > 0 and np.abs(arrays["tail_x"]).max() > 0
    write_trajectory_csv(tmp_path / "trajectory.csv", arrays)
    header = (tmp_path / "trajectory.csv").read_text().splitlines()[0]
    assert header == "time_s,head_x_m,tail_y_m,com_x_m,tail_x_m,com_y_m,newton_iterations"
    read = load_trajectory(tmp_path / "trajectory.csv")
    for name in POINTS:
        np.testing.assert_array_equal(read[name], arrays[name])


def test_a_trajectory_written_before_the_new_columns_still_reads(tmp_path):
    path = tmp_path / "trajectory.csv"
    path.write_text("time_s,head_x_m,tail_y_m,com_x_m,newton_iterations\n0,0,0,0,0\n0.02,1e-4,2e-3,5e-5,3\n")
    read = load_trajectory(path)
    assert sorted(read) == ["com_x", "head_x", "newton_iterations", "tail_y", "time"]
    np.testing.assert_array_equal(read["tail_y"], [0, 2e-3])


def format_3_file(prom: ReducedModel, path):
    """``prom`` saved as a file of format 3: without the tail's x row and the mass moment in y."""
    prom.save(path)
    with np.load(path) as data:
        arrays = {key: data[key] for key in data.files if "tail_x_row" not in key and "mass_moment_y" not in key}
    header = json.loads(arrays["header"].tobytes().decode())
    header["format_version"] = 3
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(path, **arrays)


def test_a_prom_file_without_the_new_rows_is_refused_in_one_line(scene, prom, tmp_path, capsys):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(scene.to_toml())
    format_3_file(prom, tmp_path / "old.npz")
    with pytest.raises(InputError, match="format version 3"):
        ReducedModel.load(tmp_path / "old.npz")
    assert main(["simulate", str(scene_file), "--model", "prom", "--prom", str(tmp_path / "old.npz"),
                 "--out", str(tmp_path / "run")]) == 2
    line = one_line(capsys)
    assert "format version 3" in line and "aquarom build" in line


def test_a_cached_prom_without_the_new_rows_is_rebuilt(scene, prom, tmp_path, monkeypatch):
    monkeypatch.setenv("AQUAROM_CACHE", str(tmp_path / "cache"))
    builds = []

    def build():
        builds.append(1)
        return prom

    cached_prom(scene, prom.xi_center, build, parametric=False)
    [entry] = (tmp_path / "cache" / "prom").glob("*.npz")
    format_3_file(prom, entry)
    from aquarom_fenics.io.persistence import store
    old = entry.read_bytes()
    store(entry, lambda target: target.write_bytes(old))       # sealed as the cache seals entries
    again = cached_prom(scene, prom.xi_center, build, parametric=False)
    assert len(builds) == 2 and again.observation.tail_x_row.shape == (prom.size,)
    assert ReducedModel.load(entry).inertia.mass_moment_y.constant.shape == (prom.size,)
