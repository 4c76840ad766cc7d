"""Generalized-α time integration with Newton iterations (SPEC §6), shared by the FOM and the reduced models.

The integrator works on plain numpy arrays (for the FOM: the owned dofs of this rank) and asks
a :class:`NewtonSystem` for residuals and solves, so that models stay replaceable. Newmark is
the member α_m = α_f = 0 of the same scheme.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem.time_scheme import TimeScheme


class NewtonSystem(Protocol):
    """What the integrator needs from a model at time t and state (u, u̇, ü)."""

    def residual(self, time: float, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, float]:
        """r = M ü + C u̇ + f_int - f_ext (zero on fixed dofs) and the force scale of the test."""

    def set_time_step(self, scheme: TimeScheme) -> None:
        """Use this scheme's factors in the Newton matrix from now on."""

    def factorize(self, time: float, u: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Assemble and factorise S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t,
        the tangents taken at this (intermediate) state: S = ∂r_{n+1-α}/∂u_{n+1}."""

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """S⁻¹ rhs with the current factors."""

    def norm(self, vector: np.ndarray) -> float:
        """Global Euclidean norm."""

    def dot(self, left: np.ndarray, right: np.ndarray) -> float:
        """Global Euclidean inner product."""


@dataclass
class NewtonSettings:
    """Newton's test ‖r‖ ≤ tolerance · max(scale, force_floor) and the step control.

    min_time_step [s]: a step that fails is retried with a residual line search, then with h/2,
    h/4, … down to this; None never cuts (a failed step stops the run).

    secant_updates: Broyden updates of S⁻¹ between factorisations (``BroydenSteps``), for systems
    whose factorisation costs many solves; see ``secant_settings``.

    refresh_each_step: every step's first iteration factorises S at the predictor (the reduced solves,
    ``reduced_settings``); else the factors of earlier steps serve until a refresh rule asks.
    """

    tolerance: float = 1e-6
    max_iterations: int = 30
    contraction_to_refactor: float = 0.25
    iterations_per_factorization: int = 4
    secant_updates: bool = False
    force_floor: float = 1e-12
    min_time_step: float | None = None
    line_search_halvings: int = 8
    sufficient_decrease: float = 1e-4
    refresh_each_step: bool = False

    @classmethod
    def from_solver(cls, solver) -> "NewtonSettings":
        """The settings of a scene's [solver] section."""
        return cls(tolerance=solver.tolerance, max_iterations=solver.max_iterations,
                   min_time_step=solver.min_time_step)

    @classmethod
    def reduced_settings(cls, solver) -> "NewtonSettings":
        """The settings of a reduced solve: ``from_solver``'s with each step's factors refreshed at its predictor.
        The reduced Newton matrix changes much from one step to the next: the factors of the step before contracted
        the first residual by only 0.3-0.8 and were refreshed at the second iteration in 92 % of SO1's steps; at the
        predictor they contract it by about 1e-2 (docs/devlog.md, 2026-12-07, "one Newton refresh per step").
        The FOM keeps ``from_solver``'s rule."""
        return dataclasses.replace(cls.from_solver(solver), refresh_each_step=True)

    def secant_settings(self) -> "NewtonSettings":
        """These settings with Broyden updates, factors refreshed after 20 iterations of a step or an
        iteration contracting the residual by less than 0.7 (Broyden's residuals need not decrease
        monotonically): fewer factorisations for somewhat more iterations per step (docs/devlog.md,
        "FOM speed")."""
        return dataclasses.replace(self, secant_updates=True, contraction_to_refactor=0.7,
                                   iterations_per_factorization=20)


@dataclass
class StepReport:
    step: int
    time: float
    iterations: int
    factorizations: int
    cut_steps: int = 0      # sub-steps taken below the scheme's step so far in the run


Observer = Callable[[StepReport, np.ndarray, np.ndarray, np.ndarray], None]
StepHook = Callable[[TimeScheme, float, tuple, tuple], None]
"""Called with (scheme, t_{n+1}, old state, new state) after every accepted (sub-)step."""


class IntegrationStopped(SolverError):
    """A step that failed (at the minimum step if cuts are allowed); results are kept up to the step before."""

    def __init__(self, message: str, cut_steps: int):
        super().__init__(message)
        self.cut_steps = cut_steps     # sub-steps shorter than h taken before the failure


class StepFailure(Exception):
    """A (sub-)step that Newton could not solve: "{what} at <where>{detail}" and the relative residuals."""

    def __init__(self, what: str, detail: str, history: list[float], cut_steps: int = 0):
        super().__init__(what)
        self.what, self.detail, self.history, self.cut_steps = what, detail, history, cut_steps

    def at(self, where: str) -> str:
        return f"{self.what} at {where}{self.detail}"


@dataclass
class _Newton:
    """Modified Newton on one step, or Broyden's method from its matrix; the factors of S are kept
    across iterations and steps."""

    system: NewtonSystem
    settings: NewtonSettings
    have_factors: bool = False

    def solve_step(self, scheme: TimeScheme, time: float, old, line_search: bool = False):
        """(u, u̇, ü)_{n+1} at ``time`` from ``old``, with (iterations, factorisations) spent.

        Factors are refreshed when an iteration contracts the residual by less than
        ``contraction_to_refactor`` or when they have served ``iterations_per_factorization``
        iterations of the step. The update is u ← u - S⁻¹ r, or with ``secant_updates`` the Broyden
        step from the factors' S (its history restarts with every factorisation and every step).
        With ``line_search`` every iteration refactorises and the update is u ← u - λ S⁻¹ r with the
        largest λ = 2^-k meeting ‖r(λ)‖ ≤ (1 - c λ) ‖r‖.

        An iterate that diverges overflows: the non-finite residual norm it leads to is this step's
        failure (a :class:`StepFailure`, which the step control cuts or reports), so numpy's overflow,
        division and invalid-value warnings on the way are not raised.
        """
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            return self._iterate(scheme, time, old, line_search)

    def _iterate(self, scheme: TimeScheme, time: float, old, line_search: bool):
        settings, system = self.settings, self.system
        u_predicted, v_predicted = scheme.predict(*old)
        u_new = u_predicted.copy()
        factorizations = 0
        iterations_with_factors = 0
        previous_norm = np.inf
        history = []
        secant = BroydenSteps(system.dot)

        def residual_at(u_trial):
            v_trial, a_trial = scheme.correct(u_trial, u_predicted, v_predicted)
            point = scheme.evaluation_point(time, old, (u_trial, v_trial, a_trial))
            residual, scale = system.residual(*point)
            return residual, scale, point, (u_trial, v_trial, a_trial)

        for iteration in range(settings.max_iterations + 1):
            residual, scale, point, new = residual_at(u_new)
            residual_norm = system.norm(residual)
            history.append(residual_norm / max(scale, settings.force_floor))
            if not np.isfinite(residual_norm):
                raise StepFailure("non-finite residual", f", Newton iteration {iteration}", history)
            if residual_norm <= settings.tolerance * max(scale, settings.force_floor):
                return new, iteration, factorizations
            if iteration == settings.max_iterations:
                raise StepFailure("Newton did not converge", f" in {settings.max_iterations} iterations", history)
            slow = residual_norm > settings.contraction_to_refactor * previous_norm
            worn = (iterations_with_factors >= settings.iterations_per_factorization
                    or (iteration == 0 and settings.refresh_each_step))
            try:
                if line_search or not self.have_factors or slow or worn:
                    self.have_factors = False
                    system.factorize(*point)
                    self.have_factors = True
                    factorizations += 1
                    iterations_with_factors = 0
                    secant.clear()
                iterations_with_factors += 1
                previous_norm = residual_norm
                update = system.solve(residual)
            except SolverError as failure:
                raise StepFailure(f"{failure}", f", Newton iteration {iteration}", history) from None
            if line_search:
                u_new = self._search_line(residual_at, u_new, update, residual_norm, history)
            elif settings.secant_updates:
                u_new = u_new + secant.step(-update)
            else:
                u_new = u_new - update

    def _search_line(self, residual_at, u_new, update, residual_norm, history):
        """u - λ Δ for the largest λ = 2^-k with ‖r(u - λΔ)‖ ≤ (1 - c λ) ‖r(u)‖."""
        settings, system = self.settings, self.system
        step = 1.0
        for _ in range(settings.line_search_halvings + 1):
            trial = u_new - step * update
            trial_norm = system.norm(residual_at(trial)[0])
            if np.isfinite(trial_norm) and trial_norm <= (1.0 - settings.sufficient_decrease * step) * residual_norm:
                return trial
            step *= 0.5
        raise StepFailure("line search found no decrease of the residual along the Newton direction", "", history)


class BroydenSteps:
    """Broyden's ("good") update of the inverse Newton matrix, kept as its steps (Kelley 1995, §8.3):
    with H₀ = S⁻¹ of the factorised S and z = -H₀ r_{n+1},

        z ← z + s_{j+1} (s_jᵀ z)/‖s_j‖²  (j = 0 … n-1),   s_{n+1} = z / (1 - s_nᵀ z/‖s_n‖²),

    so that u_{n+2} = u_{n+1} + s_{n+1} uses H_{n+1}, which meets the secant conditions of every
    step so far, without forming it. s₀ = -H₀ r₀ is the modified-Newton step."""

    def __init__(self, dot):
        self.dot = dot
        self.steps: list[np.ndarray] = []
        self.squared_norms: list[float] = []

    def clear(self) -> None:
        self.steps.clear()
        self.squared_norms.clear()

    def step(self, newton_step: np.ndarray) -> np.ndarray:
        """s_{n+1} from z = -H₀ r_{n+1}."""
        z = newton_step
        for j in range(len(self.steps) - 1):
            z = z + self.steps[j + 1] * (self.dot(self.steps[j], z) / self.squared_norms[j])
        if self.steps:
            z = z / (1.0 - self.dot(self.steps[-1], z) / self.squared_norms[-1])
        self.steps.append(z)
        self.squared_norms.append(self.dot(z, z))
        return z


def integrate(system: NewtonSystem, scheme: TimeScheme, n_steps: int, state, settings: NewtonSettings,
              observe: Observer, explain: Callable[[], str] | None = None, on_step: StepHook | None = None):
    """Integrate from ``state = (u, u̇, ü)`` at t = 0 over ``n_steps`` steps of ``scheme``.

    A step whose Newton fails (no convergence in ``max_iterations``, non-finite values, or a
    linear solve that fails: the system raises :class:`SolverError`) is retried, if
    ``settings.min_time_step`` allows, with a line search, then in sub-steps h/2, h/4, … (each
    with a line search) down to ``min_time_step``; after a successful sub-step the next one
    doubles again, up to h. Only a sub-step that fails at the minimum raises
    :class:`IntegrationStopped` naming the time, with the relative residuals of the step, the system's
    ``linear_solve_status()`` if it has one, and the text of ``explain()`` (called only then) as
    hints, all on one line; ``observe`` has seen every converged step of the scheme's grid
    before that, ``on_step`` every accepted sub-step.
    """
    state = tuple(np.array(x, dtype=float) for x in state)
    newton = _Newton(system, settings)
    h = scheme.time_step
    cut_steps = 0
    for step in range(1, n_steps + 1):
        time = step * h
        where = f"t = {time:.4g} s (step {step} of {n_steps})"
        kept_until = time - h
        try:
            new, iterations, factorizations = newton.solve_step(scheme, time, state)
            if on_step is not None:
                on_step(scheme, time, state, new)
        except StepFailure as failure:
            if settings.min_time_step is None or settings.min_time_step > h:
                raise IntegrationStopped(failure_message(failure.at(where), failure.history, kept_until, system,
                                                         explain), cut_steps) from None
            try:
                new, iterations, factorizations, cuts = _subdivide(newton, scheme, time, state, on_step)
            except StepFailure as cut_failure:
                raise IntegrationStopped(failure_message(cut_failure.at(where), cut_failure.history, kept_until,
                                                         system, explain), cut_steps + cut_failure.cut_steps) from None
            cut_steps += cuts
        state = new
        observe(StepReport(step, time, iterations, factorizations, cut_steps), *state)
    return state


def _subdivide(newton: _Newton, scheme: TimeScheme, end: float, state, on_step):
    """Cover [end - h, end] with line-searched sub-steps: halve a sub-step that fails (not below
    ``min_time_step``), double after one that converges (up to h).

    Sub-steps are dyadic fractions of h (exact in floating point), the last one ends at ``end``.
    Returns the state at ``end``, the iterations and factorisations spent and the number of
    sub-steps shorter than h. Bounded: every success advances by at least the minimum step and
    at most log2(h / min_time_step) + 1 failures separate two successes.
    """
    h, minimum = scheme.time_step, newton.settings.min_time_step
    size, reached = 1.0, 0.0            # fractions of h
    iterations = factorizations = cuts = 0
    try:
        while reached < 1.0:
            size = min(size, 1.0 - reached)
            sub = scheme.with_time_step(size * h)
            newton.system.set_time_step(sub)
            newton.have_factors = False
            sub_end = end if reached + size == 1.0 else end - (1.0 - reached - size) * h
            try:
                new, used, factorised = newton.solve_step(sub, sub_end, state, line_search=True)
            except StepFailure as failure:
                if size * h / 2.0 < minimum:
                    raise StepFailure(failure.what, f"{failure.detail} (sub-step to t = {sub_end:.6g} s cut to "
                                      f"h = {size * h:.3g} s, the minimum is {minimum:g} s)", failure.history, cuts) from None
                size /= 2.0
                continue
            if on_step is not None:
                on_step(sub, sub_end, state, new)
            state, reached = new, reached + size
            iterations, factorizations = iterations + used, factorizations + factorised
            cuts += int(size < 1.0)
            size = min(2.0 * size, 1.0)
    finally:
        newton.system.set_time_step(scheme)
        newton.have_factors = False
    return state, iterations, factorizations, cuts


def failure_message(what: str, history: list[float], kept_until: float, system, explain) -> str:
    """One line: what stopped where, the step's relative residuals, the last linear solve,
    the time [s] up to which results are kept, and the hints of ``explain()``."""
    parts = [what, "relative residuals " + ", ".join(f"{value:.2e}" for value in history[-6:])]
    linear_solve_status = getattr(system, "linear_solve_status", None)
    status = linear_solve_status() if linear_solve_status is not None else ""
    if status and status not in what:
        parts.append(f"last linear solve: {status}")
    parts.append(f"results kept up to t = {kept_until:.4g} s")
    hints = " ".join(explain().split()) if explain is not None else ""
    if hints:
        parts.append(f"hints: {hints}")
    return "; ".join(parts)
