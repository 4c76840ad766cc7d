"""Frozen-coefficient local stability: the step map of generalized-α and the FOM's tangents."""
import re

import numpy as np
import pytest

from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import InputError
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.reduction.reductor import build_prom, reused_basis
from aquarom_fenics.verification.local_stability import (local_stability, pencil_eigenvalues, prom_tail_growth,
                                                         prom_tail_stability, region_dofs, step_matrix,
                                                         region_tangents, tail_sample_steps, tangents)
from conftest import coarse_scene


def oscillator(omega, damping_ratio):
    """1-dof ü + 2ζω u̇ + ω² u = 0 as (K, C, M)."""
    return np.array([[omega ** 2]]), np.array([[2 * damping_ratio * omega]]), np.array([[1.0]])


def radius(matrices, scheme):
    return np.abs(np.linalg.eigvals(step_matrix(*matrices, scheme))).max()


def test_step_map_damps_unresolved_modes_to_rho_infinity_and_follows_resolved_ones():
    omega = 2 * np.pi * 1000.0
    undamped = oscillator(omega, 0.0)
    # ρ → ρ∞ as ωh → ∞ (slowly: the double root at infinity; 0.808 at ωh = 1e3)
    assert radius(undamped, TimeScheme.generalized_alpha(1e6 / omega, 0.8)) == pytest.approx(0.8, abs=1e-3)
    assert radius(undamped, TimeScheme.generalized_alpha(1e-3 / omega, 0.8)) == pytest.approx(1.0, abs=1e-6)
    # negative damping: a resolved mode grows by e^{ζω h} per step, as the ODE does
    growing = oscillator(omega, -0.05)
    h = 0.01 / omega
    assert radius(growing, TimeScheme.generalized_alpha(h, 0.8)) == pytest.approx(np.exp(0.05 * omega * h), rel=1e-6)
    eigenvalues = pencil_eigenvalues(*growing)
    assert np.sort(eigenvalues.imag) == pytest.approx([-omega * np.sqrt(1 - 0.05 ** 2), omega * np.sqrt(1 - 0.05 ** 2)])
    assert eigenvalues.real == pytest.approx([0.05 * omega] * 2)


def test_step_map_is_the_integrators_linear_step():
    """G applied to a state equals one generalized-α step of M ü + C u̇ + K u = 0 solved directly."""
    rng = np.random.default_rng(3)
    mass = np.diag(rng.uniform(1, 2, 3))
    stiffness = rng.normal(size=(3, 3)); stiffness = stiffness @ stiffness.T + 3 * np.eye(3)
    damping = rng.normal(size=(3, 3))
    scheme = TimeScheme.generalized_alpha(0.05, 0.6)
    u, v = rng.normal(size=3), rng.normal(size=3)
    a = np.linalg.solve(mass, -damping @ v - stiffness @ u)
    u_predicted, v_predicted = scheme.predict(u, v, a)
    # r(u_new) is linear: S u_new = rhs with S = ∂r/∂u_new
    lead = (scheme.acceleration_factor * mass + scheme.velocity_factor * damping + scheme.stiffness_factor * stiffness)

    def residual(u_new):
        v_new, a_new = scheme.correct(u_new, u_predicted, v_predicted)
        _, u_mid, v_mid, a_mid = scheme.evaluation_point(1.0, (u, v, a), (u_new, v_new, a_new))
        return mass @ a_mid + damping @ v_mid + stiffness @ u_mid

    u_new = u_predicted - np.linalg.solve(lead, residual(u_predicted))
    expected = np.concatenate([u_new, *scheme.correct(u_new, u_predicted, v_predicted)])
    assert step_matrix(stiffness, damping, mass, scheme) @ np.concatenate([u, v, a]) == pytest.approx(expected, rel=1e-10)


@pytest.fixture(scope="module")
def swimming_run():
    scene = coarse_scene(solver={"duration": 0.2}, actuation={"amplitude": 0.4})
    result = simulate_fom(scene, fish=load_fish(scene), progress=False, keep_states=True)
    assert result.completed
    yield scene, result
    result.model.destroy()


def test_tangents_are_the_derivatives_of_the_residual(swimming_run):
    """K_t, C_t, M_t on a region (the tail's) against central differences of r(t, u, u̇, ü) at a swimming
    state (thrust through the stations and drag on): the matrices plus the stations' coupling."""
    scene, result = swimming_run
    model = result.model
    u, v, a = result.states[-1]
    time = scene.solver.duration
    dofs = region_dofs(model, model.tail_point(), scene.optimizer.tail_region_radius)
    rng = np.random.default_rng(0)
    tangents_at = region_tangents(model, time, u, v, a, dofs)
    for position, matrix, scale in ((0, tangents_at[0], 1e-4), (1, tangents_at[1], 1e-2), (2, tangents_at[2], 1.0)):
        direction = np.zeros(u.size)
        direction[dofs] = rng.normal(size=dofs.size)
        state = [u, v, a]
        plus = [x + scale * 1e-4 * direction if i == position else x for i, x in enumerate(state)]
        minus = [x - scale * 1e-4 * direction if i == position else x for i, x in enumerate(state)]
        difference = (model.residual(time, *plus)[0] - model.residual(time, *minus)[0]) / (2 * scale * 1e-4)
        product = matrix @ direction[dofs]
        assert np.linalg.norm(difference[dofs] - product) <= 1e-6 * np.linalg.norm(product)
    # the Newton matrix of the run is left as it was
    assert model.scheme.time_step == scene.solver.time_step


def test_local_stability_of_the_tail_at_rest_is_stable(swimming_run):
    """At rest nothing feeds the tail: every mode decays, the step map contracts."""
    scene, result = swimming_run
    model = result.model
    dofs = region_dofs(model, model.tail_point(), 0.04)
    assert dofs.size > 30 and not np.intersect1d(dofs, model.fixed_dofs).size
    zero = np.zeros(model.n_owned_dofs)
    rest = local_stability(model, 0.0, zero, zero, zero, dofs, model.scheme)
    assert rest.growth_rate < 0 and rest.spectral_radius < 1


def test_stability_script_writes_the_tail_modes_with_and_without_the_thrust(tmp_path):
    import importlib.util
    import json
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "stability_co.py"
    spec = importlib.util.spec_from_file_location("stability_co", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(["--scene", "nominal", "--level", "1", "--time-steps", "0.02", "--spine-forces", "source",
                        "--no-prom", "--set", "solver.duration=0.2", "--tail-radius", "0.015", "--tail-every", "10",
                        "--out", str(tmp_path), "--name", "short"]) == 0
    case = json.loads((tmp_path / "stability_short.json").read_text())["cases"][0]
    modes = case["tail_modes"]
    assert case["completed"] and modes["region_dofs"] > 30
    assert [m["time"] for m in modes["with_thrust"]] == pytest.approx([0.0, 0.2])
    assert [m["time"] for m in modes["without_thrust"]] == pytest.approx([0.0, 0.2])
    # without the thrust the tail's frozen modes decay at every state of this mild run
    assert all(m["growth_rate"] < 0 and m["spectral_radius"] < 1 for m in modes["without_thrust"])


def test_a_region_without_free_nodes_is_refused_in_one_line(swimming_run):
    _, result = swimming_run
    model = result.model
    with pytest.raises(InputError, match=r"radius 0 m around \(-0.2, [-\d.e]+, [-\d.e]+\) m holds no free node; the nearest free node is "
                                         r"[\d.e-]+ m away: use a larger radius"):
        region_dofs(model, model.tail_point(), 0.0)


@pytest.fixture(scope="module")
def swimming_prom():
    scene = coarse_scene(solver={"duration": 0.2}, actuation={"amplitude": 0.4})
    fish = load_fish(scene)
    return scene, fish, build_prom(scene, fish=fish)


def growth_rates_at(prom, scene, fish, steps) -> np.ndarray:
    """Growth rate of the tail region at the FOM states (V η, V η̇, V η̈) of the PROM's steps k."""
    run = simulate_reduced(prom, scene)
    model = FullOrderModel(scene, fish)
    basis = reused_basis(model, prom).vectors
    dofs = region_dofs(model, model.tail_point(), scene.optimizer.tail_region_radius)
    times = run.trajectory.arrays()["time"]
    rates = [local_stability(model, times[k], basis @ run.states[k], basis @ run.velocities[k],
                             basis @ run.accelerations[k], dofs, model.scheme).growth_rate for k in steps]
    model.destroy()
    return np.array(rates)


def test_the_tail_screen_linearises_the_fom_at_the_proms_rebuilt_states(swimming_prom):
    """prom_tail_growth equals local_stability of the FOM at (V η, V η̇, V η̈) of every PROM step in the
    window (here the whole horizon, shorter than a stroke), and the PROM's rates are those of its η."""
    scene, fish, prom = swimming_prom
    growth = prom_tail_growth(prom, scene, fish)
    run = simulate_reduced(prom, scene)
    h = scene.solver.time_step
    scheme = TimeScheme.from_solver(scene.solver)
    for k in range(len(run.states) - 1):      # (η̇, η̈)_{k+1} are the scheme's corrector of η_{k+1}
        velocity, acceleration = scheme.correct(
            run.states[k + 1], *scheme.predict(run.states[k], run.velocities[k], run.accelerations[k]))
        np.testing.assert_allclose(velocity, run.velocities[k + 1], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(acceleration, run.accelerations[k + 1], rtol=1e-10, atol=1e-9)
    times = run.trajectory.arrays()["time"]
    rates = growth_rates_at(prom, scene, fish, range(1, len(times)))
    assert growth.states == len(rates) == round(scene.solver.duration / h)
    assert growth.growth_rate == pytest.approx(max(rates), rel=1e-8)
    assert growth.time == pytest.approx(times[1 + int(np.argmax(rates))])


@pytest.fixture(scope="module")
def nodal_swimming_prom():
    """The nodal thrust (``stations = "nodes"``), whose point force on the tail node feeds tail modes."""
    scene = coarse_scene(solver={"duration": 0.2}, actuation={"amplitude": 0.4}, fluid={"stations": "nodes"})
    fish = load_fish(scene)
    return scene, fish, build_prom(scene, fish=fish)


def test_through_the_stations_the_tail_modes_decay(swimming_prom):
    scene, fish, prom = swimming_prom
    assert prom_tail_growth(prom, scene, fish).growth_rate < 0


def test_the_tail_screen_refuses_growth_above_the_limit(nodal_swimming_prom):
    scene, fish, prom = nodal_swimming_prom
    growth = prom_tail_growth(prom, scene, fish)
    assert growth.growth_rate > 0         # the 0.4 stroke feeds the tail a little at this mesh
    below = scene.replace("optimizer", tail_growth_limit=0.5 * growth.growth_rate)
    stable, reason = prom_tail_stability(prom, below, fish)
    assert not stable
    radius = scene.optimizer.tail_region_radius
    assert reason.startswith(f"unstable: the tail region's fastest mode (free nodes within {radius:g} m of the tail "
                             f"node, linearised at the PROM's states) grows at ")
    assert reason.endswith(f"above the limit {0.5 * growth.growth_rate:g} 1/s")
    # the first state over the limit ends the screen: its rate is over the limit, at most the largest one
    reported = float(re.search(r"grows at ([0-9.e+-]+) 1/s", reason).group(1))
    assert 0.5 * growth.growth_rate < reported <= growth.growth_rate * (1 + 5e-3)
    stable, reason = prom_tail_stability(prom, scene.replace("optimizer", tail_growth_limit=2 * growth.growth_rate),
                                         fish)
    assert stable and f"({growth.states} PROM states linearised)" in reason


def test_tail_screen_script_records_each_pareto_points_screen_next_to_its_fom_check(tmp_path):
    import importlib.util
    import json
    from pathlib import Path

    repository = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("tail_screen_co", repository / "scripts" / "tail_screen_co.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    scene_file = tmp_path / "co_coarse.toml"
    scene_file.write_text((repository / "scenes" / "co.toml").read_text().replace("level = 2", "level = 1").replace(
        "degree = 2", "degree = 1") + "\n[solver]\nduration = 0.2\n")
    names = ("z_tail", "z_head", "y_lin_long_tail", "y_head", "y_ellipse")
    for w1, amplitude, error in ((0.3, 0.1, None), (0.9, 0.4, "FOM stopped at t = 0.1 s")):
        (tmp_path / "pareto" / f"w1_{w1}").mkdir(parents=True)
        (tmp_path / "pareto" / f"w1_{w1}" / "summary.json").write_text(json.dumps({
            "optimum": {**dict.fromkeys(names, 0.0), "amplitude": amplitude},
            "cost_weights": {"distance": w1, "energy": 1 - w1, "alpha": 1.0},
            "fom_check": {"error": error, "optimal_distance": None if error else 0.01}}))
    assert script.main(["--pareto", str(tmp_path / "pareto"), "--scene", str(scene_file), "--radii", "0.015",
                        "--out", str(tmp_path)]) == 0
    record = json.loads((tmp_path / "tail_screen_co.json").read_text())
    completed, stopped = record["points"]
    assert (completed["w1"], completed["fom_completed"], stopped["fom_completed"]) == (0.3, True, False)
    growth = [point["screen"]["0.015"]["growth_rate"] for point in (completed, stopped)]
    assert all(point["screen"]["0.015"]["states"] == 10 for point in (completed, stopped))
    separation = record["separation"]["0.015"]
    assert (separation["largest_growth_of_completed"], separation["smallest_growth_of_stopped"]) == tuple(growth)
    assert separation["limit_separates"] == (growth[0] <= record["tail_growth_limit"] < growth[1])


SCREEN_UNDER_MPI = """
import json, sys
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.verification.local_stability import prom_tail_growth
from mpi4py import MPI

scene = Scene.load(sys.argv[1])
fish = load_fish(scene)
prom = build_prom(scene, fish=fish)
growths = [prom_tail_growth(prom, scene, fish, stop_above=float(limit)) for limit in sys.argv[2:]]
if MPI.COMM_WORLD.rank == 0:
    print(json.dumps([[g.time, g.growth_rate, g.states] for g in growths]))
"""


def test_threaded_eigenvalues_give_the_screen_of_one_state_after_the_other(swimming_prom, monkeypatch):
    """With the eigenvalues in a thread pool (the default on one rank) the screen meets the same
    fastest mode at the same state and counts the same states, with and without an early stop."""
    import aquarom_fenics.verification.local_stability as screen

    scene, fish, prom = swimming_prom
    rates = growth_rates_at(prom, scene, fish, tail_sample_steps(scene))
    limit = float(np.median(rates))
    assert np.flatnonzero(rates > limit)[0] < rates.size - 1       # the second screen stops early
    for stop_above in (np.inf, limit):
        screens = []
        for threads in (0, 2, 3):
            monkeypatch.setattr(screen, "eigenvalue_threads", lambda comm, threads=threads: threads)
            screens.append(prom_tail_growth(prom, scene, fish, stop_above=stop_above))
        assert screens[0] == screens[1] == screens[2]
    assert screens[0].states < rates.size


@pytest.mark.mpi
def test_ranks_share_the_tail_screens_states_and_answer_as_one_rank(swimming_prom, tmp_path):
    """Under mpirun -n 2 each rank linearises every other state; the fastest mode, its time and the
    states counted up to the first one over the limit are those of the serial screen."""
    import json
    import os
    import shutil
    import subprocess
    import sys

    if shutil.which("mpirun") is None:
        pytest.skip("mpirun not installed")
    scene, fish, prom = swimming_prom
    rates = growth_rates_at(prom, scene, fish, tail_sample_steps(scene))
    limits = [np.inf, float(np.median(rates))]
    assert np.flatnonzero(rates > limits[1])[0] < rates.size - 1       # the second screen stops early
    serial = [prom_tail_growth(prom, scene, fish, stop_above=limit) for limit in limits]
    scene_file, script = tmp_path / "scene.toml", tmp_path / "screen.py"
    scene_file.write_text(scene.to_toml())
    script.write_text(SCREEN_UNDER_MPI)
    completed = subprocess.run(["mpirun", "-n", "2", sys.executable, str(script), str(scene_file), *map(str, limits)],
                               capture_output=True, text=True, timeout=600, env=os.environ)
    assert completed.returncode == 0, completed.stderr
    parallel = json.loads(completed.stdout.strip().splitlines()[-1])
    for one_rank, two_ranks in zip(serial, parallel):
        assert (one_rank.time, one_rank.states) == (two_ranks[0], two_ranks[2])
        assert two_ranks[1] == pytest.approx(one_rank.growth_rate, rel=1e-6, abs=1e-6)
