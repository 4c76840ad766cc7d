"""Per-force discrete energy balance of FOM runs (nominal fish, coarsest mesh, short horizon)."""
from types import SimpleNamespace

import pytest

from aquarom_fenics.verification.energy import energy_balance
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.dynamics.simulate import simulate_fom
from conftest import coarse_scene


@pytest.fixture(scope="module")
def fish():
    return load_fish(coarse_scene())


def balance(fish, **solver):
    result = simulate_fom(coarse_scene(solver={"duration": 0.4, **solver}), fish=fish, progress=False,
                          keep_states=True)
    assert result.completed
    return energy_balance(result)


def test_balance_of_the_nominal_fom_closes_and_names_who_feeds_the_energy(fish):
    energy = balance(fish)
    assert energy.relative_imbalance < 5e-3
    assert len(energy.time) == 21 and energy.work_actuation[0] == 0.0
    # the muscles supply the energy; damping and the drag take it out
    others = [abs(work[-1]) for name, work in energy.works.items() if name != "actuation"]
    assert energy.work_actuation[-1] > 5 * max(others)
    assert energy.dissipated_rayleigh[-1] > 0 and energy.work_drag[-1] < 0
    assert energy.dissipated_numerical[-1] > 0        # ρ∞ < 1 damps


def test_trapezoidal_newmark_has_no_numerical_dissipation(fish):
    """γ = ½, β = ¼: the scheme conserves energy up to the third-order quadrature of the nonlinear forces."""
    energy = balance(fish, integrator="newmark", newmark_alpha=0.0)
    assert energy.relative_imbalance < 5e-3
    assert abs(energy.dissipated_numerical[-1]) < 1e-3 * energy.throughput
    damped = balance(fish, integrator="newmark", newmark_alpha=0.02)
    assert damped.dissipated_numerical[-1] > 5 * abs(energy.dissipated_numerical[-1])


def test_a_run_with_cut_steps_is_refused():
    with pytest.raises(ValueError, match="cut 2 steps"):
        energy_balance(SimpleNamespace(cut_steps=2))
