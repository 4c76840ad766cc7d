"""Shape optimisation (SPEC §10) on the coarsest mesh with a short horizon."""
import re
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.optimization import history, prom_builder
from aquarom_fenics.cli import main
from aquarom_fenics.optimization.cost import CostWeights, cost_value, design_space, evaluate
from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.optimization.optimize import optimize
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.studies.study import run_optimization
from conftest import coarse_scene

TOY_SHAPES = {"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1]}}
CONSTRAINED_SHAPES = {"z_tail": {"bounds": [-0.3, 0.3]}, "z_tail_lin": {"bounds": [-0.3, 0.3]},
                      "y_thin": {"bounds": [-0.1, 0.1]}}
CONSTRAINT = [{"coefficients": {"z_tail": 1.0, "z_tail_lin": 1.0}, "lower": -0.25, "upper": 0.25}]


def toy_scene(method="trust-region", tolerance=1e-6, **sections):
    return coarse_scene(shapes=TOY_SHAPES, solver={"duration": 1.0, "tolerance": tolerance},
                        optimizer={"method": method, "max_iterations": 12}, **sections)


def constrained_scene(method):
    scene = coarse_scene(shapes=CONSTRAINED_SHAPES, solver={"duration": 1.0},
                         optimizer={"method": method, "max_iterations": 10})
    from aquarom_fenics.io.scene import scene_from_dict

    data = {"mesh": {"level": 1}, "shapes": CONSTRAINED_SHAPES, "constraints": CONSTRAINT,
            "solver": {"duration": 1.0}, "optimizer": {"method": method, "max_iterations": 10}}
    return scene_from_dict(data, source="<test>") if scene else None


@pytest.fixture(scope="module")
def toy_fish():
    return load_fish(toy_scene())


def test_cost_gradient_matches_central_differences_of_the_prom_cost(toy_fish):
    scene = toy_scene(tolerance=1e-11)   # finite differences of the cost need a converged Newton
    space = design_space(scene)
    prom = build_prom(scene, fish=toy_fish)
    z = np.array([-0.03, 0.02])
    evaluation = evaluate(prom, scene, space, z, CostWeights())
    step = 1e-5
    for k in range(2):
        shift = step * np.eye(2)[k]
        central = (evaluate(prom, scene, space, z + shift, CostWeights()).cost
                   - evaluate(prom, scene, space, z - shift, CostWeights()).cost) / (2 * step)
        assert abs(evaluation.gradient[k] - central) < 1e-6 * abs(central)


def test_amplitude_gradient_of_the_cooptimisation_cost(toy_fish):
    scene = toy_scene(tolerance=1e-11, cooptimization={"enabled": True})
    space = design_space(scene)
    prom = build_prom(scene, fish=toy_fish)
    weights = CostWeights(0.7, 0.3, 1.0)
    z = np.array([-0.03, 0.02, 0.25])
    evaluation = evaluate(prom, scene, space, z, weights)
    assert cost_value(prom, scene, space, z, weights) == evaluation.cost    # the run without sensitivities: same L
    step = 1e-5 * np.eye(3)[2]
    central = (cost_value(prom, scene, space, z + step, weights)
               - cost_value(prom, scene, space, z - step, weights)) / (2 * 1e-5)
    assert abs(evaluation.gradient[2] - central) < 1e-6 * abs(central)


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_iterates_stay_inside_bounds_and_linear_constraints(method):
    scene = constrained_scene(method)
    space = design_space(scene)
    rows = []
    optimize(scene, on_iteration=rows.append)
    assert len(rows) > 2
    for row in rows:
        z = np.array([row[f"xi_{name}"] for name in space.names])
        assert space.is_feasible(z, tolerance=1e-9), row


def test_both_methods_reach_the_same_optimum_of_a_two_parameter_scene(toy_fish):
    # a log-barrier descent approaches an active bound geometrically: ask both for a converged point
    scenes = [coarse_scene(shapes=TOY_SHAPES, solver={"duration": 1.0},
                           optimizer={"method": method, "max_iterations": 30, "step_tolerance": 1e-4})
              for method in ("paper", "trust-region")]
    optima = [optimize(scene, fish=toy_fish).optimum for scene in scenes]
    widths = np.array([0.4, 0.2])
    assert np.all(np.abs(optima[0] - optima[1]) < 0.02 * widths), optima


def test_killed_and_resumed_run_ends_at_the_same_optimum(tmp_path, toy_fish, monkeypatch):
    scene = toy_scene("paper")
    uninterrupted, _ = run_optimization(scene, tmp_path / "straight", fish=toy_fish, render=False)

    original_save = history.Checkpoint.save
    calls = {"count": 0}

    def save_then_die(self, *args):
        original_save(self, *args)
        calls["count"] += 1
        if calls["count"] == 4:
            raise KeyboardInterrupt

    monkeypatch.setattr(history.Checkpoint, "save", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_optimization(scene, tmp_path / "killed", fish=toy_fish, render=False)
    monkeypatch.setattr(history.Checkpoint, "save", original_save)
    resumed, _ = run_optimization(scene, tmp_path / "killed", resume=True, fish=toy_fish, render=False)
    np.testing.assert_allclose(resumed.optimum, uninterrupted.optimum, rtol=0, atol=1e-12)
    straight_history = (tmp_path / "straight" / "history.csv").read_text().splitlines()
    resumed_history = (tmp_path / "killed" / "history.csv").read_text().splitlines()
    assert len(resumed_history) == len(straight_history)


def test_a_co_optimisation_checkpoint_with_a_basis_centre_reads_back(tmp_path):
    # the co-optimisation's design adds the amplitude; the basis centre is a shape, one entry shorter
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load("co")
    space = design_space(scene)
    assert len(space.names) == space.n_shapes + 1
    z = space.start.tolist()
    builder = SimpleNamespace(builds=3, reused=0, build_time=1.0, solve_time=0.1, basis_reuses=1, records=[],
                              basis_center=np.array(z[: space.n_shapes]) + 0.01)
    state = {"z": z, "iteration": 2, "scaling": [1.0] * len(z), "previous_gradient": None, "since_build": 1,
             "center": {"z": z, "distance": 0.1, "distance_gradient": [0.0] * len(z), "prom_z": z}}
    checkpoint = history.Checkpoint(tmp_path / "checkpoint.json", scene, "paper")
    checkpoint.save(state, [], builder)
    saved = checkpoint.load()
    np.testing.assert_array_equal(saved["basis_center"], builder.basis_center)
    assert saved["state"]["iteration"] == 2


def test_optimize_command_writes_its_outputs(tmp_path, capsys):
    scene = tmp_path / "toy.toml"
    scene.write_text('[mesh]\nlevel = 1\n[solver]\nduration = 1.0\n[optimizer]\nmethod = "trust-region"\n'
                     'max_iterations = 3\n[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n'
                     'y_thin = { bounds = [-0.1, 0.1] }\n')
    out = tmp_path / "run"
    assert main(["optimize", str(scene), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fom_check"]["ratio"] > 1.0 and summary["prom_builds"] >= 2
    for name in ("history.csv", "checkpoint.json", "cost.png", "parameters.png", "start_vs_optimal.png",
                 "optimal/design.xdmf", "optimal/design.stl"):
        assert (out / name).exists(), name
    assert "FOM check" in capsys.readouterr().out
    assert_optimum_stl_encloses_its_design(scene, summary["optimum"], out / "optimal" / "design.stl")


def assert_optimum_stl_encloses_its_design(scene_path, optimum, stl_path):
    """The optimum's STL (millimetres) reads back closed, with the volume of the optimum's design mesh."""
    from aquarom_fenics.geometry.export import design_body, read_stl
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load(scene_path)
    expected = design_body(scene, load_fish(scene), optimum).volume
    header, _, corners = read_stl(stl_path.read_bytes())
    points, triangles = np.unique(corners.reshape(-1, 3) / 1000.0, axis=0, return_inverse=True)
    triangles = triangles.reshape(-1, 3)
    edges = np.sort(triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    assert (np.unique(edges, axis=0, return_counts=True)[1] == 2).all()          # closed
    x = points[triangles] - points.mean(axis=0)
    volume = np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0
    assert header.startswith("aquarom export") and volume == pytest.approx(expected, rel=1e-6)


@pytest.mark.mpi
def test_optimize_under_mpirun_renders_the_optimum_and_ends(tmp_path):
    """Every rank takes part in the optimum's collective XDMF write (rank 0 alone waited there for ever)."""
    import os
    import shutil
    import subprocess
    import sys

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene = tmp_path / "toy.toml"
    scene.write_text('[mesh]\nlevel = 1\n[solver]\nduration = 1.0\n[optimizer]\nmax_iterations = 1\n'
                     '[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n')
    out = tmp_path / "run"
    aquarom = Path(sys.executable).with_name("aquarom")
    completed = subprocess.run(["mpirun", "-n", "2", str(aquarom), "optimize", str(scene), "--out", str(out)],
                               capture_output=True, text=True, timeout=600, env=os.environ)
    assert completed.returncode == 0, completed.stderr
    for name in ("summary.json", "cost.png", "start_vs_optimal.png", "optimal/design.xdmf", "optimal/design.png",
                 "manifest.json"):
        assert (out / name).exists(), name


def test_infeasible_constraints_are_refused():
    from aquarom_fenics.io.scene import scene_from_dict

    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": TOY_SHAPES,
                             "constraints": [{"coefficients": {"z_tail": 1.0}, "lower": 0.5}]})
    with pytest.raises(InputError, match="no feasible design"):
        design_space(scene)


def test_start_violating_the_constraints_is_refused():
    from aquarom_fenics.io.scene import scene_from_dict

    shapes = {"z_tail": {"bounds": [-0.2, 0.2], "start": 0.15}, "y_thin": {"bounds": [-0.1, 0.1]}}
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": shapes,
                             "constraints": [{"coefficients": {"z_tail": 1.0}, "upper": 0.1}]})
    with pytest.raises(InputError, match="violates"):
        design_space(scene)


def test_non_finite_gradient_stops_with_history_and_checkpoint_intact(tmp_path, toy_fish, monkeypatch):
    scene = toy_scene("paper")
    original = prom_builder.PromBuilder.evaluate
    calls = {"count": 0}

    def poisoned(self, prom, z, weights):
        calls["count"] += 1
        if calls["count"] == 3:
            raise SolverError(f"non-finite cost or gradient at {self.space.as_dict(z)}: cost nan")
        return original(self, prom, z, weights)

    monkeypatch.setattr(prom_builder.PromBuilder, "evaluate", poisoned)
    with pytest.raises(SolverError, match="non-finite"):
        run_optimization(scene, tmp_path / "run", fish=toy_fish, render=False)
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    history = (tmp_path / "run" / "history.csv").read_text().splitlines()
    assert len(history) - 1 == len(checkpoint["history"]) >= 2


def test_prom_build_failing_mid_run_keeps_history_and_checkpoint(tmp_path, toy_fish, monkeypatch, capsys):
    scene = toy_scene("trust-region")
    original = prom_builder.PromBuilder.build
    calls = {"count": 0}

    def failing(self, z):
        calls["count"] += 1
        if calls["count"] == 3:
            raise SolverError("Newton did not converge at t = 0.1 s (step 5 of 50) in the basis solve")
        return original(self, z)

    monkeypatch.setattr(prom_builder.PromBuilder, "build", failing)
    with pytest.raises(SolverError):
        run_optimization(scene, tmp_path / "run", fish=toy_fish, render=False)
    checkpoint = json.loads((tmp_path / "run" / "checkpoint.json").read_text())
    assert checkpoint["builds"] == 2 and len(checkpoint["history"]) >= 2


def test_fom_check_that_stops_is_reported_and_the_outputs_are_kept(tmp_path, capsys, monkeypatch):
    from aquarom_fenics.studies import fom_cache, study

    original = fom_cache.simulate_fom

    def diverging(scene, design, **options):
        result = original(scene.replace("actuation", stiffness=1e6), design, **options)
        assert not result.completed
        return result

    monkeypatch.setattr(fom_cache, "simulate_fom", diverging)
    monkeypatch.setattr(study, "start_if_useful", lambda *args, **options: None)   # no unpatched FOM in a child
    scene = tmp_path / "toy.toml"
    scene.write_text('[mesh]\nlevel = 1\n[solver]\nduration = 1.0\n[optimizer]\nmax_iterations = 2\n'
                     '[shapes]\nz_tail = { bounds = [-0.2, 0.2] }\n')
    out = tmp_path / "run"
    assert main(["optimize", str(scene), "--out", str(out)]) == 3
    message = capsys.readouterr().err.strip()
    assert len(message.splitlines()) == 1 and "FOM check" in message
    assert re.search(r"at t = [\d.]+ s \(step \d+ of 50\)", message), message     # says when it stopped
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fom_check"]["ratio"] is None and "stopped" in summary["fom_check"]["error"]
    assert (out / "history.csv").exists()


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_a_parameter_with_equal_bounds_stays_fixed_and_no_design_is_nan(method, toy_fish):
    scene = coarse_scene(shapes={"z_tail": {"bounds": [0.0, 0.0]}, "y_thin": {"bounds": [-0.1, 0.1]}},
                         solver={"duration": 1.0}, optimizer={"method": method, "max_iterations": 4})
    result = optimize(scene, fish=toy_fish)
    designs = np.array([[row["xi_z_tail"], row["xi_y_thin"]] for row in result.history])
    assert np.all(np.isfinite(designs)) and np.all(designs[:, 0] == 0.0)
    assert result.optimum[1] > 0.05          # thinner swims further (the free parameter still moves)


def test_every_bound_equal_is_refused():
    scene = coarse_scene(shapes={"z_tail": {"bounds": [0.1, 0.1], "start": 0.1}})
    with pytest.raises(InputError, match="nothing to optimise"):
        design_space(scene)


def test_paper_method_refuses_a_feasible_set_without_interior(toy_fish):
    from aquarom_fenics.io.scene import scene_from_dict

    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": TOY_SHAPES, "solver": {"duration": 1.0},
                             "optimizer": {"method": "paper", "max_iterations": 3},
                             "constraints": [{"coefficients": {"z_tail": 1.0, "y_thin": 1.0}, "lower": 0.0,
                                              "upper": 0.0}]})
    with pytest.raises(InputError, match="no interior"):
        optimize(scene, fish=toy_fish)


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_wall_time_safeguard_stops_the_optimiser(method, toy_fish):
    result = optimize(toy_scene(method), fish=toy_fish, max_time=0.0)
    assert result.stop_reason == "wall-time limit of 0 s reached"
    assert all(np.isfinite(row["cost"]) for row in result.history)


def test_a_non_finite_design_is_refused():
    with pytest.raises(SolverError, match="non-finite design"):
        history.Safeguard.finite(np.array([0.1, np.nan]), 3)


def test_a_design_whose_prom_is_unstable_is_refused_as_infeasible(monkeypatch):
    """PromBuilder asks reduced_stability at every design it builds a PROM on (horizons of two
    strokes or more) and refuses an unstable one like the mesh check, naming the reason."""
    verdicts = []

    def unstable(prom, scene, xi, amplitude):
        verdicts.append(np.array(xi))
        return False, "Floquet multiplier |μ| = 2.48 > 1.01"

    monkeypatch.setattr(prom_builder, "reduced_stability", unstable)
    scene = coarse_scene(shapes=TOY_SHAPES, solver={"duration": 2.0})
    space = design_space(scene)
    builder = prom_builder.PromBuilder(scene, load_fish(scene), space)
    z = np.array([0.1, 0.02])
    with pytest.raises(InputError, match=r"infeasible: its PROM is unstable \(Floquet multiplier \|μ\| = 2.48"):
        builder._refuse_unstable(object(), z)
    np.testing.assert_array_equal(verdicts[0], z[: space.n_shapes])
    short = prom_builder.PromBuilder(toy_scene(), builder.fish, space)
    short._refuse_unstable(object(), z)          # one stroke: no periodic gait to judge, not asked
    assert len(verdicts) == 1


def test_the_tail_screen_follows_a_stable_floquet_test_when_the_scene_asks_and_the_thrust_is_on(monkeypatch):
    screened = []

    def tail_unstable(prom, scene, fish, xi, amplitude):
        screened.append(np.array(xi))
        return False, "unstable: the tail region's fastest mode grows at 426 1/s (2.17e+03 Hz) at t = 1.08 s"

    monkeypatch.setattr(prom_builder, "reduced_stability", lambda prom, scene, xi, amplitude: (True, "stable"))
    monkeypatch.setattr(prom_builder, "prom_tail_stability", tail_unstable)
    scene = coarse_scene(shapes=TOY_SHAPES, solver={"duration": 2.0}, optimizer={"tail_screen": True})
    space = design_space(scene)
    z = np.array([0.1, 0.02])
    builder = prom_builder.PromBuilder(scene, load_fish(scene), space)
    assert prom_builder.stability_plan(scene).startswith("the PROM's Floquet test at every PROM build, then the tail screen")
    with pytest.raises(InputError, match=r"infeasible: its PROM is unstable \(unstable: the tail region's fastest "
                                         r"mode grows at 426 1/s"):
        builder._refuse_unstable(object(), z)
    np.testing.assert_array_equal(screened[0], z[: space.n_shapes])
    assert builder.screen_time > 0
    for changed, skipped in ((scene.replace("optimizer", tail_screen=False), "[optimizer] tail_screen = false"),
                             (scene.replace("fluid", thrust=False), "thrust off: nothing drives the tail")):
        other = prom_builder.PromBuilder(changed, builder.fish, space)
        other._refuse_unstable(object(), z)
        assert prom_builder.stability_plan(changed).endswith(f"tail screen skipped ({skipped})")
    assert len(screened) == 1


def test_builder_reuses_the_basis_within_half_the_validity_radius_and_records_it(toy_fish):
    scene = toy_scene("paper")
    space = design_space(scene)
    builder = prom_builder.PromBuilder(scene, toy_fish, space)
    radius = np.array(scene.validity_radii())
    first = builder.build(np.zeros(2))
    near = builder.build(0.4 * radius)                       # within half the radius of the first: reused
    far = builder.build(np.array([0.8 * radius[0], 0.0]))    # beyond it: a basis of its own
    assert [record["basis_from"] for record in builder.records] == [None, {"z_tail": 0.0, "y_thin": 0.0}, None]
    assert builder.records[1]["radius_fraction"] == pytest.approx(0.4)
    assert builder.basis_reuses == 1 and builder.builds == 3
    np.testing.assert_array_equal(near.basis, first.basis)
    assert not np.array_equal(far.basis, first.basis)
    np.testing.assert_array_equal(builder.basis_center, far.xi_center)
