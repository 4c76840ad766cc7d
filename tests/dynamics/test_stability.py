"""PROM stability verdict (Floquet multipliers of the discrete reduced system) and the spine spectrum."""
import numpy as np
import pytest

from aquarom_fenics.verification.energy import spine_spectrum
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.dynamics.integrator import NewtonSettings, TimeScheme, integrate
from aquarom_fenics.dynamics.reduced_dynamics import (FLOQUET_LIMIT, ReducedSystem, reduced_stability, simulate_reduced,
                                             transition_matrix)
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
    scheme, settings = TimeScheme.from_solver(scene.solver), NewtonSettings.from_solver(scene.solver)
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
