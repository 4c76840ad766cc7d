"""PROM stability verdict (Floquet multipliers of the discrete reduced system) and the spine spectrum."""
import numpy as np
import pytest

from aquarom_fenics.verification.energy import spine_spectrum
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.dynamics.integrator import NewtonSettings, TimeScheme, integrate
from aquarom_fenics.dynamics.reduced_dynamics import (FLOQUET_LIMIT, ReducedSystem, reduced_stability, simulate_reduced,
                                             transition_matrix)
from aquarom_fenics.dynamics.trajectory import last_stroke_start
from aquarom_fenics.reduction.reductor import build_prom
from conftest import coarse_scene


@pytest.fixture(scope="module")
def fish():
    return load_fish(coarse_scene())


def multiplier(reason: str) -> float:
    return float(reason.split("|μ| = ")[1].split()[0])


@pytest.mark.parametrize("solver", [{}, {"integrator": "newmark", "newmark_alpha": 0.02}])
def test_the_transition_matrix_is_the_derivative_of_the_discrete_flow(fish, solver):
    """Φ = ∂s(T)/∂s(0) against central differences of the whole run in each of the 3m directions of s(0)."""
    scene = coarse_scene(solver={"duration": 0.4, "tolerance": 1e-12, **solver})
    prom = build_prom(scene, fish=fish)
    scheme, settings = TimeScheme.from_solver(scene.solver), NewtonSettings.reduced_settings(scene.solver)
    system = ReducedSystem(prom, scene, prom.xi_center, scheme)
    m, n_steps = prom.size, scene.n_steps
    transition = transition_matrix(system, scheme, n_steps, settings, window_start=0.0)

    def final_state(start):
        state = integrate(system, scheme, n_steps, (start[:m], start[m:2 * m], start[2 * m:]), settings,
                          lambda *_: None)
        return np.concatenate(state)

    step = 1e-7
    differences = np.column_stack([(final_state(step * e) - final_state(-step * e)) / (2 * step)
                                   for e in np.eye(3 * m)])
    assert np.linalg.norm(differences - transition) < 1e-7 * np.linalg.norm(transition)


@pytest.mark.parametrize("material, stable", [({}, True), ({"young_modulus": 15e3}, False)])
def test_the_compiled_transition_matrix_is_the_python_one(fish, material, stable):
    """Φ of the last stroke from the compiled kernel (``compiled_transition``) against ``transition_matrix``'s, and
    the verdicts: the nominal gait (|μ| = 1) and E = 15 kPa at h = 10 ms (|μ| ≈ 1.25, a run the kernel completes)."""
    pytest.importorskip("numba")
    from aquarom_fenics.dynamics.floquet_kernel import compiled_transition

    scene = coarse_scene(material=material, solver={"time_step": 0.01})
    prom = build_prom(scene, fish=fish)
    scheme, settings = TimeScheme.from_solver(scene.solver), NewtonSettings.reduced_settings(scene.solver)
    window_start = last_stroke_start(scene.solver.duration, scene.actuation.frequency)
    compiled = compiled_transition(prom, scene, prom.xi_center, None, scene.n_steps, window_start)
    python = transition_matrix(ReducedSystem(prom, scene, prom.xi_center, scheme), scheme, scene.n_steps, settings,
                               window_start)
    assert compiled is not None and np.linalg.norm(compiled - python) < 1e-10 * np.linalg.norm(python)
    radius = [np.max(np.abs(np.linalg.eigvals(matrix))) for matrix in (compiled, python)]
    assert radius[0] == pytest.approx(radius[1], abs=1e-10) and (radius[0] <= FLOQUET_LIMIT) == stable
    assert reduced_stability(prom, scene) == reduced_stability(prom, scene, compiled=False)


def test_the_nominal_gait_is_stable(fish):
    scene = coarse_scene()
    stable, reason = reduced_stability(build_prom(scene, fish=fish), scene)
    assert stable, reason
    # the rigid translation along x is neutral: |μ| = 1; every other perturbation decays
    assert reason.startswith("stable") and multiplier(reason) == pytest.approx(1.0, abs=1e-6)


def test_a_gait_that_completes_can_still_be_unstable(fish):
    """E = 16 kPa (E / 16) completes the 2 s PROM run, yet one stroke multiplies a perturbation by more than
    1.5 (on the conforming level-1 mesh; 13 kPa did on the centroid-region mesh, and stops on this one)."""
    scene = coarse_scene(material={"young_modulus": 16e3})
    prom = build_prom(scene, fish=fish)
    assert simulate_reduced(prom, scene).completed
    stable, reason = reduced_stability(prom, scene)
    assert not stable and reason.startswith("unstable: a perturbation grows")
    assert multiplier(reason) > 1.5 > FLOQUET_LIMIT


def test_a_prom_that_stops_is_unstable_with_the_stop_as_reason(fish):
    """E = 6 kPa (k·A = 200 % of E) stops the PROM near t = 0.96 s (at 8 kPa it now swims to the end,
    with a growing perturbation)."""
    scene = coarse_scene(material={"young_modulus": 6e3})
    stable, reason = reduced_stability(build_prom(scene, fish=fish), scene)
    assert not stable and reason.startswith("unstable: the PROM stops") and "t = " in reason


def test_spine_spectrum_finds_a_growing_zigzag_beside_the_gait():
    times = np.arange(0.0, 2.0 + 1e-9, 0.01)
    along = np.linspace(0.0, 1.0, 10)
    gait = np.sin(2 * np.pi * times)[:, None] * along ** 2
    zigzag = 1e-3 * np.exp(3 * times)[:, None] * np.sin(2 * np.pi * 12 * times)[:, None] * (-1.0) ** np.arange(10)
    spectrum = spine_spectrum(times, gait + zigzag, frequency=1.0)
    assert spectrum["peak"] == pytest.approx(1.0, abs=0.02) and spectrum["sign_changes"] == 0
    assert spectrum["high"]["peak"] == pytest.approx(12.0, abs=0.2) and spectrum["high"]["sign_changes"] == 9
    assert spectrum["growth"] > 4.0          # e^{3 · 0.75 s} between the window's first and last quarters
    steady = spine_spectrum(times, gait + 1e-3 * np.sin(2 * np.pi * 12 * times)[:, None], frequency=1.0)
    assert steady["growth"] == pytest.approx(1.0, abs=0.05)
