"""The shared time integrator (SPEC §6) on one-dof systems: generalized-α accuracy and damping, step control."""
import dataclasses
import warnings

import numpy as np
import pytest

from aquarom_fenics.errors import SolverError
from aquarom_fenics.dynamics.integrator import BroydenSteps, IntegrationStopped, NewtonSettings, TimeScheme, integrate


class Oscillator:
    """ü + c u̇ + k u + k₃ u³ = sin t, one dof, exact Newton matrix S = ∂r/∂u_{n+1}."""

    def __init__(self, scheme, damping=0.3, stiffness=4.0, cubic=0.5):
        self.scheme, self.damping, self.stiffness, self.cubic = scheme, damping, stiffness, cubic
        self.matrix = None

    def residual(self, time, u, v, a):
        internal = self.stiffness * u + self.cubic * u ** 3
        return a + self.damping * v + internal - np.sin(time), float(max(abs(internal[0]), abs(a[0]), 1.0))

    def set_time_step(self, scheme):
        self.scheme = scheme

    def factorize(self, time, u, v, a):
        # S = (1 - α_f)(k + 3 k₃ u²) + (1 - α_f)(γ/(βh)) c + (1 - α_m)/(βh²)
        scheme = self.scheme
        self.matrix = (scheme.stiffness_factor * (self.stiffness + 3 * self.cubic * u[0] ** 2)
                       + scheme.velocity_factor * self.damping + scheme.acceleration_factor)

    def solve(self, rhs):
        return rhs / self.matrix

    def norm(self, vector):
        return float(np.linalg.norm(vector))

    def dot(self, left, right):
        return float(left @ right)


def displacements(scheme, duration, system=None, settings=None):
    samples = []
    system = system or Oscillator(scheme)
    integrate(system, scheme, int(round(duration / scheme.time_step)), np.zeros((3, 1)),
              settings or NewtonSettings(tolerance=1e-11), lambda report, u, v, a: samples.append(u[0]))
    return np.array(samples)


def halving_ratios(make_scheme):
    steps = (0.1, 0.05, 0.025, 0.0125)
    runs = [displacements(make_scheme(h), 4.0)[int(round(0.1 / h)) - 1::int(round(0.1 / h))] for h in steps]
    differences = [np.abs(a - b).max() for a, b in zip(runs, runs[1:])]
    return [first / second for first, second in zip(differences, differences[1:])]


def test_generalized_alpha_parameters_of_chung_and_hulbert():
    undamped = TimeScheme.generalized_alpha(0.1, 1.0)
    assert (undamped.alpha_m, undamped.alpha_f, undamped.gamma, undamped.beta) == (0.5, 0.5, 0.5, 0.25)
    strongest = TimeScheme.generalized_alpha(0.1, 0.0)
    assert (strongest.alpha_m, strongest.alpha_f, strongest.gamma, strongest.beta) == (-1.0, 0.0, 1.5, 1.0)
    newmark = TimeScheme.newmark(0.1, 0.02)
    assert (newmark.alpha_m, newmark.alpha_f, newmark.gamma) == (0.0, 0.0, 0.52)


@pytest.mark.parametrize("rho_infinity", [0.0, 0.5, 0.8, 1.0])
def test_generalized_alpha_is_second_order_on_a_nonlinear_oscillator(rho_infinity):
    ratios = halving_ratios(lambda h: TimeScheme.generalized_alpha(h, rho_infinity))
    assert all(3.5 < ratio < 4.5 for ratio in ratios), ratios


def test_damped_newmark_is_first_order():
    """γ = ½ + α_N leaves an O(α_N h) error: ratios towards 2."""
    ratios = halving_ratios(lambda h: TimeScheme.newmark(h, 0.1))
    assert all(1.8 < ratio < 2.6 for ratio in ratios), ratios


def amplification_matrix(scheme, frequency):
    """A with (u, h u̇, h² ü)_{n+1} = A (u, h u̇, h² ü)_n for ü + ω² u = 0, column by column."""
    h = scheme.time_step
    columns = []
    for column in np.eye(3):
        state = column[:, None] / np.array([1.0, h, h * h])[:, None]
        system = Oscillator(scheme, damping=0.0, stiffness=frequency ** 2, cubic=0.0)
        system.residual = lambda time, u, v, a: (a + frequency ** 2 * u, float(max(abs(a[0]), frequency ** 2 * abs(u[0]), 1e-30)))
        new = integrate(system, scheme, 1, state, NewtonSettings(tolerance=1e-6), lambda *step: None)
        columns.append(np.array([new[0][0], h * new[1][0], h * h * new[2][0]]))
    return np.column_stack(columns)


@pytest.mark.parametrize("rho_infinity", [0.0, 0.5, 0.8, 1.0])
def test_spectral_radius_at_infinite_frequency_is_rho_infinity(rho_infinity):
    scheme = TimeScheme.generalized_alpha(1.0, rho_infinity)
    radius = np.abs(np.linalg.eigvals(amplification_matrix(scheme, 1e5))).max()
    assert abs(radius - rho_infinity) < 1e-3
    # and no damping of the resolved frequencies beyond O((ω h)³): ω h = 0.05
    low = np.abs(np.linalg.eigvals(amplification_matrix(TimeScheme.generalized_alpha(0.05, rho_infinity), 1.0))).max()
    assert 1.0 - 1e-4 < low <= 1.0 + 1e-12


class FailsOnLongSteps(Oscillator):
    """The oscillator whose linear solve fails for steps longer than 0.03 s ending in (0.26, 0.35] s."""

    def residual(self, time, u, v, a):
        self.time = time
        return super().residual(time, u, v, a)

    def solve(self, rhs):
        if self.scheme.time_step > 0.03 and 0.26 < self.time <= 0.35 + 1e-12:
            raise SolverError("linear solve failed (step too long)")
        return super().solve(rhs)


def test_a_failing_step_is_cut_until_it_converges_then_grows_back():
    scheme = TimeScheme.newmark(0.1, 0.0)
    reports, sub_steps = [], []
    integrate(FailsOnLongSteps(scheme), scheme, 5, np.zeros((3, 1)), NewtonSettings(tolerance=1e-11, min_time_step=0.01),
              lambda report, u, v, a: reports.append(report),
              on_step=lambda step_scheme, time, old, new: sub_steps.append((step_scheme.time_step, time)))
    assert [report.time for report in reports] == [0.1 * step for step in range(1, 6)]
    # 0.3 fails at h = 0.1 and 0.05 (ending at 0.3), converges as 0.05 (to 0.25), 0.025, 0.025; 0.4 is whole again
    assert [h for h, _ in sub_steps] == pytest.approx([0.1, 0.1, 0.05, 0.025, 0.025, 0.1, 0.1])
    assert [t for _, t in sub_steps] == pytest.approx([0.1, 0.2, 0.25, 0.275, 0.3, 0.4, 0.5])
    assert reports[-1].cut_steps == 3
    # the sub-steps land on the same solution as uniform steps of 0.025 to within the scheme's error
    fine = displacements(TimeScheme.newmark(0.025, 0.0), 0.5)
    cut = displacements(scheme, 0.5, FailsOnLongSteps(scheme), NewtonSettings(tolerance=1e-11, min_time_step=0.01))
    assert abs(cut[-1] - fine[-1]) < 0.05 * abs(fine[-1])


def test_a_step_failing_at_the_minimum_stops_the_run_with_the_cuts_counted():
    scheme = TimeScheme.newmark(0.1, 0.0)
    with pytest.raises(IntegrationStopped) as stopped:
        integrate(FailsOnLongSteps(scheme), scheme, 5, np.zeros((3, 1)), NewtonSettings(min_time_step=0.04),
                  lambda *step: None)
    message = str(stopped.value)
    assert message.startswith("linear solve failed (step too long) at t = 0.3 s (step 3 of 5), Newton iteration 0 "
                              "(sub-step to t = 0.3 s cut to h = 0.05 s, the minimum is 0.04 s)")
    assert "results kept up to t = 0.2 s" in message
    assert stopped.value.cut_steps == 1     # the sub-step to 0.25 s converged


class Arctangent(Oscillator):
    """r = arctan(u - 3): Newton from u = 0 overshoots and diverges, a line search converges."""

    def residual(self, time, u, v, a):
        return np.arctan(u - 3.0), 1.0

    def factorize(self, time, u, v, a):
        self.matrix = self.scheme.stiffness_factor / (1.0 + (u[0] - 3.0) ** 2)


def test_the_line_search_rescues_a_newton_that_overshoots():
    """Plain Newton diverges until its iterate overflows: a step failure, said in the message, not a numpy
    warning (warnings are errors here)."""
    scheme = TimeScheme.generalized_alpha(0.1, 0.8)
    with pytest.raises(IntegrationStopped, match="non-finite residual"), warnings.catch_warnings():
        warnings.simplefilter("error")
        integrate(Arctangent(scheme), scheme, 1, np.zeros((3, 1)), NewtonSettings(), lambda *step: None)
    reports = []
    with warnings.catch_warnings():      # the first plain attempt overflows again before the line search
        warnings.simplefilter("error")
        u, _, _ = integrate(Arctangent(scheme), scheme, 1, np.zeros((3, 1)), NewtonSettings(min_time_step=0.1),
                            lambda report, *state: reports.append(report))
    assert reports[0].cut_steps == 0
    # the residual vanishes at the evaluation point u_{n+1-α_f} = (1 - α_f) u_1 + α_f u_0 = 3
    assert abs((1.0 - scheme.alpha_f) * u[0] - 3.0) < 1e-6


def test_broyden_steps_solve_a_linear_system_from_a_poor_inverse_where_modified_newton_stalls():
    """Broyden's good method ends in at most 2n steps on a linear system (Gay 1979); the
    modified-Newton iteration from the same wrong inverse contracts by ‖I - H₀A‖ per step only."""
    rng = np.random.default_rng(3)
    n = 5
    matrix = np.eye(n) * 4.0 + rng.normal(size=(n, n))
    right = rng.normal(size=n)
    initial_inverse = np.linalg.inv(matrix + 1.5 * rng.normal(size=(n, n)))
    assert np.linalg.norm(np.eye(n) - initial_inverse @ matrix, 2) > 0.5

    secant = BroydenSteps(lambda left, other: float(left @ other))
    broyden, modified = np.zeros(n), np.zeros(n)
    for _ in range(2 * n):
        broyden = broyden + secant.step(-initial_inverse @ (matrix @ broyden - right))
        modified = modified - initial_inverse @ (matrix @ modified - right)
    solution = np.linalg.solve(matrix, right)
    assert np.linalg.norm(broyden - solution) < 1e-9 * np.linalg.norm(solution)
    assert np.linalg.norm(modified - solution) > 1e-3 * np.linalg.norm(solution)


class ThreeMasses(Oscillator):
    """Three masses on cubic springs, M ü + C u̇ + K u + k₃ u³ = f(t), with a Newton matrix that keeps
    only the linear stiffness, so that factors go stale as the cubic springs stretch."""

    def __init__(self, scheme):
        super().__init__(scheme)
        self.stiffness_matrix = np.array([[8.0, -3.0, 0.0], [-3.0, 6.0, -2.0], [0.0, -2.0, 5.0]])
        self.factorizations = 0

    def residual(self, time, u, v, a):
        internal = self.stiffness_matrix @ u + 40.0 * u ** 3
        load = np.array([3.0, -2.0, 4.0]) * np.sin(3.0 * time)
        return a + self.damping * v + internal - load, float(max(np.linalg.norm(internal), np.linalg.norm(load)))

    def factorize(self, time, u, v, a):
        scheme = self.scheme
        self.factorizations += 1
        self.matrix = (scheme.stiffness_factor * (self.stiffness_matrix + np.diag(120.0 * u ** 2))
                       + (scheme.velocity_factor * self.damping + scheme.acceleration_factor) * np.eye(3))

    def solve(self, rhs):
        return np.linalg.solve(self.matrix, rhs)


def test_secant_settings_give_the_same_motion_with_fewer_factorizations():
    """Against modified Newton: the same motion to the tolerance, fewer factorisations; against the
    same refresh policy without the updates: fewer iterations."""
    scheme = TimeScheme.generalized_alpha(0.05, 0.8)
    secant_settings = NewtonSettings(tolerance=1e-10).secant_settings()
    runs = {}
    for label, settings in (("modified", NewtonSettings(tolerance=1e-10)), ("secant", secant_settings),
                            ("stale", dataclasses.replace(secant_settings, secant_updates=False))):
        system, samples, iterations = ThreeMasses(scheme), [], []

        def observe(report, u, v, a):
            samples.append(u.copy())
            iterations.append(report.iterations)

        integrate(system, scheme, 60, np.zeros((3, 3)), settings, observe)
        runs[label] = np.array(samples), system.factorizations, sum(iterations)
    modified, secant, stale = runs["modified"], runs["secant"], runs["stale"]
    assert np.abs(modified[0]).max() > 0.1                       # the cubic springs matter
    np.testing.assert_allclose(secant[0], modified[0], atol=1e-8 * np.abs(modified[0]).max())
    assert secant[1] < modified[1]
    assert secant[2] < stale[2]
