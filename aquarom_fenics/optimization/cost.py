"""Cost of a design and its gradient from the PROM (SPEC §10), and the feasible set.

The design vector z is ξ (the scene's shape parameters), followed by the actuation amplitude A
when co-optimisation is on, then the ``[gait]`` variables g (io/scene_gait.py). Cost
L(z) = w_1 (-d(z)) + w_2 α E, d the swimming distance [m] and E the effort: A² or, with
``[cooptimization] effort = "power"``, the muscles' mean positive power P̄ [W] (dynamics/muscle_power.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog, nnls

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.dynamics.batched import simulate_batch
from aquarom_fenics.io.scene import Scene


@dataclass(frozen=True)
class DesignSpace:
    """Names, box bounds and linear constraints A z ≤ b of the design vector z."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    start: np.ndarray
    constraint_matrix: np.ndarray     # (n_rows, n) rows of A z ≤ b
    constraint_bound: np.ndarray      # (n_rows,)
    with_amplitude: bool
    n_gait: int = 0                   # the [gait] variables, last in z

    @property
    def n_shapes(self) -> int:
        return len(self.names) - int(self.with_amplitude) - self.n_gait

    @property
    def amplitude_index(self) -> int:
        """The index of A in z (with co-optimisation): right after the shapes."""
        return self.n_shapes

    def gait_values(self, z: np.ndarray) -> dict[str, float]:
        """{gait variable: value} of z (empty without [gait])."""
        first = len(self.names) - self.n_gait
        return dict(zip(self.names[first:], map(float, z[first:])))

    def slacks(self, z: np.ndarray) -> np.ndarray:
        """Every inequality as s(z) ≥ 0: z - lower, upper - z, b - A z."""
        return np.concatenate([z - self.lower, self.upper - z, self.constraint_bound - self.constraint_matrix @ z])

    @property
    def free(self) -> np.ndarray:
        """Parameters with room to move (lower < upper); the others are fixed at their bound."""
        return self.upper > self.lower

    @property
    def slack_jacobian(self) -> np.ndarray:
        """∂s/∂z of :meth:`slacks`: rows I, -I, -A."""
        n = len(self.names)
        return np.vstack([np.eye(n), -np.eye(n), -self.constraint_matrix])

    @property
    def barrier_rows(self) -> np.ndarray:
        """The slacks that must stay positive inside the set: all but the box rows of fixed parameters."""
        return np.concatenate([self.free, self.free, np.ones(self.constraint_bound.size, dtype=bool)])

    @property
    def descent_barrier_rows(self) -> np.ndarray:
        """The rows the paper method's log-barrier covers: :attr:`barrier_rows` without the
        amplitude's two (A is set to its conditional optimum at every PROM, not held off its bounds)."""
        rows = self.barrier_rows.copy()
        if self.with_amplitude:
            n, index = len(self.names), self.amplitude_index
            rows[index] = rows[n + index] = False
        return rows

    def most_interior_point(self) -> np.ndarray:
        """argmax_z min_i s_i(z) over the barrier rows (a linear programme in (z, t))."""
        rows = self.barrier_rows
        jacobian, n = self.slack_jacobian[rows], len(self.names)
        offsets = self.slacks(np.zeros(n))[rows]            # s(z) = offsets + J z
        # maximise t subject to t - J z <= offsets  (every slack >= t)
        bounds = [(lo, hi) for lo, hi in zip(self.lower, self.upper)] + [(None, None)]
        solution = linprog(np.r_[np.zeros(n), -1.0], A_ub=np.hstack([-jacobian, np.ones((rows.sum(), 1))]),
                           b_ub=offsets, bounds=bounds, method="highs")
        return solution.x[:n]

    def interior_depth(self) -> float:
        """max_z min_i s_i(z) over the barrier rows: > 0 when the feasible set has an interior."""
        z = self.most_interior_point()
        return float(self.slacks(z)[self.barrier_rows].min()) if self.barrier_rows.any() else 0.0

    def is_feasible(self, z: np.ndarray, tolerance: float = 1e-12) -> bool:
        return bool(np.all(self.slacks(z) >= -tolerance))

    @property
    def slack_ranges(self) -> np.ndarray:
        """Range of every slack over the box: the width for a bound, Σ_j |A_ij| (upper_j - lower_j)
        for a linear row; activity tolerances are fractions of it."""
        width = self.upper - self.lower
        return np.concatenate([width, width, np.abs(self.constraint_matrix) @ width])

    def row_names(self) -> list[str]:
        """A name for every slack row: ``z_tail = lower``, ``z_tail = upper``, ``constraint 1``, …"""
        return ([f"{n} = lower" for n in self.names] + [f"{n} = upper" for n in self.names]
                + [f"constraint row {i + 1}" for i in range(self.constraint_bound.size)])

    def active_rows(self, z: np.ndarray, tolerance: float) -> np.ndarray:
        """Rows with s_i(z) ≤ tolerance · range_i (fixed parameters' bounds excluded)."""
        return np.flatnonzero((self.slacks(z) <= tolerance * self.slack_ranges) & self.barrier_rows)

    def as_dict(self, z: np.ndarray) -> dict[str, float]:
        return dict(zip(self.names, map(float, z)))


@dataclass
class FirstOrder:
    """First-order optimality at z of min L(z) s.t. s(z) = s_0 + J z ≥ 0.

    KKT: ∇L = Jᵀ λ, λ ≥ 0, λ_i s_i = 0. The rows within ``tolerance`` of their range are the
    active set A; λ_A ≥ 0 minimises ‖D(∇L - J_Aᵀ λ_A - J_Iᵀ λ_I)‖ (non-negative least squares),
    λ_I the barrier's multipliers μ / s_i of the inactive rows (zero without a barrier) and
    D = diag(upper - lower). ``measure`` = ‖D r‖_∞ / |L| for that residual r: the relative cost
    change, to first order, still to be had by moving one free parameter across its range.
    """

    measure: float
    active: list[dict]          # name, slack / range, multiplier (least squares, its sign free)


def first_order(space: DesignSpace, z: np.ndarray, cost: float, gradient: np.ndarray, tolerance: float,
                barrier_scale: float = 0.0, barrier_rows: np.ndarray | None = None) -> FirstOrder:
    """The optimality measure and active set of :class:`FirstOrder` (``barrier_scale`` = μ over
    ``barrier_rows``, by default :attr:`DesignSpace.barrier_rows`)."""
    free = space.free
    scale = space.upper - space.lower
    slacks, ranges, jacobian = space.slacks(z), space.slack_ranges, space.slack_jacobian
    active = space.active_rows(z, tolerance)
    inactive = np.setdiff1d(np.flatnonzero(space.barrier_rows if barrier_rows is None else barrier_rows), active)
    residual = np.asarray(gradient, dtype=float).copy()
    if barrier_scale > 0 and inactive.size:
        residual -= jacobian[inactive].T @ (barrier_scale / slacks[inactive])
    columns = (scale[:, None] * jacobian[active].T)[free]
    target = (scale * residual)[free]
    if active.size:
        positive, _ = nnls(columns, target)
        stationary = target - columns @ positive
        multipliers = np.linalg.lstsq(columns, target, rcond=None)[0]
    else:
        stationary, multipliers = target, np.zeros(0)
    names = space.row_names()
    rows = [{"constraint": names[i], "slack_over_range": float(slacks[i] / max(ranges[i], 1e-300)), "multiplier": float(m)}
            for i, m in zip(active, multipliers)]
    measure = float(np.abs(stationary).max(initial=0.0) / max(abs(cost), 1e-300))
    return FirstOrder(measure, rows)


def design_space(scene: Scene) -> DesignSpace:
    """The scene's design space; refuses infeasible constraints and an infeasible start."""
    names = list(scene.shape_names)
    lower = [s.lower for s in scene.shapes]
    upper = [s.upper for s in scene.shapes]
    start = [s.start for s in scene.shapes]
    co = scene.cooptimization
    if co.enabled:
        names.append("amplitude")
        lower.append(co.amplitude_bounds[0])
        upper.append(co.amplitude_bounds[1])
        start.append(float(np.clip(scene.actuation.amplitude, *co.amplitude_bounds)))
    for variable in scene.gait:
        names.append(variable.name)
        lower.append(variable.lower)
        upper.append(variable.upper)
        start.append(variable.start)
    rows, bounds = [], []
    for constraint in scene.constraints:
        row = np.zeros(len(names))
        for name, coefficient in constraint.coefficients:
            row[names.index(name)] = coefficient
        if np.isfinite(constraint.upper):
            rows.append(row)
            bounds.append(constraint.upper)
        if np.isfinite(constraint.lower):
            rows.append(-row)
            bounds.append(-constraint.lower)
    space = DesignSpace(tuple(names), np.array(lower), np.array(upper), np.array(start),
                        np.array(rows).reshape(-1, len(names)), np.array(bounds), co.enabled, len(scene.gait))
    if space.constraint_matrix.size:
        feasible = linprog(np.zeros(len(names)), A_ub=space.constraint_matrix, b_ub=space.constraint_bound,
                           bounds=list(zip(space.lower, space.upper)), method="highs")
        if feasible.status == 2:
            raise InputError(f"scene {scene.source}: the linear constraints and the bounds leave no feasible design")
    if not space.free.any():
        raise InputError(f"scene {scene.source}: every design parameter has equal bounds "
                         f"({', '.join(space.names)}): nothing to optimise; widen a bound")
    violated = np.flatnonzero(space.constraint_bound - space.constraint_matrix @ space.start < -1e-12)
    if violated.size:
        raise InputError(f"scene {scene.source}: the start point {space.as_dict(space.start)} violates linear "
                         f"constraint row(s) {', '.join(str(i + 1) for i in violated)}; move the start values inside")
    return space


def require_interior(space: DesignSpace, scene: Scene) -> None:
    """The paper method's log-barrier needs a feasible set with an interior (max_z min_i s_i(z) > 0)."""
    if space.interior_depth() <= 1e-12:
        raise InputError(f"scene {scene.source}: the linear constraints leave no interior to the design space "
                         "(an equality, or bounds that meet); the paper method's log-barrier needs one: "
                         "use [optimizer] method = \"trust-region\" or loosen the constraints")


def meshable_space(space: DesignSpace, fish) -> tuple[DesignSpace, list[str]]:
    """The design space with each shape bound pulled in to where the design still meshes.

    One parameter at a time (the others at their start values), bisection on the mesh check of
    SPEC §4 between the start value and the bound. Returns the space and one note per change.
    """
    lower, upper, notes = space.lower.copy(), space.upper.copy(), []
    for k in range(space.n_shapes):
        for bounds, side in ((lower, "lower"), (upper, "upper")):
            if _meshes(fish, space, k, bounds[k]):
                continue
            good, bad = space.start[k], bounds[k]
            for _ in range(30):
                middle = 0.5 * (good + bad)
                good, bad = (middle, bad) if _meshes(fish, space, k, middle) else (good, middle)
            notes.append(f"{space.names[k]} {side} bound {bounds[k]:g} → {good:.4g} (beyond it the design check "
                         "refuses: det F_1 ≤ 0 at a quadrature point)")
            bounds[k] = good
    restricted = DesignSpace(space.names, lower, upper, space.start, space.constraint_matrix, space.constraint_bound,
                             space.with_amplitude, space.n_gait)
    return restricted, notes


def _meshes(fish, space: DesignSpace, index: int, value: float) -> bool:
    xi = space.start[: space.n_shapes].copy()
    xi[index] = value
    try:
        fish.design(xi)
        return True
    except InputError:
        return False


@dataclass
class Evaluation:
    """Cost, its gradient and the swimming distance at one design, as the PROM predicts them."""

    z: np.ndarray
    cost: float
    gradient: np.ndarray
    distance: float
    distance_gradient: np.ndarray


@dataclass(frozen=True)
class CostWeights:
    """L = w_1 (-d) + w_2 α A²."""

    distance: float = 1.0
    energy: float = 0.0
    alpha: float = 1.0

    def energy_term(self, amplitude: float) -> float:
        return self.alpha * amplitude ** 2


@dataclass(frozen=True)
class PromRun:
    """What the cost reads of a PROM run: d [m] and dd/dz (None without sensitivities or design variables), and
    with the effort "power" P̄ [W] and dP̄/dz."""

    distance: float
    distance_gradient: np.ndarray | None
    power: float | None = None
    power_gradient: np.ndarray | None = None


def scene_at(scene: Scene, space: DesignSpace, z: np.ndarray) -> Scene:
    """The scene driven by the gait of z (``apply_gait``); the scene itself without [gait] variables."""
    if not space.n_gait:
        return scene
    from aquarom_fenics.io.scene_gait import apply_gait

    return apply_gait(scene, space.gait_values(z))


def amplitude_of(space: DesignSpace, z: np.ndarray) -> float | None:
    """A of z with co-optimisation, else None (the scene's)."""
    return float(z[space.amplitude_index]) if space.with_amplitude else None


def _prom_run(prom: ReducedModel, scene: Scene, space: DesignSpace, z: np.ndarray, sensitivities: bool) -> PromRun:
    """The PROM's run at z (with dd/dz when ``sensitivities``); SolverError if it stops. A batch of one design
    (``simulate_batch``: the compiled kernel where numba is installed; a step that fails there is integrated by
    ``simulate_reduced`` with its step control, as a single run would be). With [gait] variables the single
    run ``simulate_reduced`` of the scene driven by z's gait, with its gait sensitivities."""
    if space.n_gait or counts_power(scene, space):
        return _gait_run(prom, scene, space, z, sensitivities)
    amplitudes = [float(z[-1])] if space.with_amplitude else None
    batch = simulate_batch(prom, scene, z[None, : space.n_shapes], sensitivities=sensitivities, amplitudes=amplitudes,
                           amplitude_sensitivity=sensitivities and space.with_amplitude)
    if not batch.completed[0]:
        raise SolverError(f"PROM simulation at {space.as_dict(z)} stopped: {batch.errors[0]}")
    gradient = None if batch.distance_gradient is None else batch.distance_gradient[0]
    return PromRun(float(batch.distance[0]), gradient)


def counts_power(scene: Scene, space: DesignSpace) -> bool:
    """Whether the cost's effort is the muscles' mean positive power (a co-design with effort = "power")."""
    return space.with_amplitude and scene.cooptimization.effort == "power"


def _gait_run(prom: ReducedModel, scene: Scene, space: DesignSpace, z: np.ndarray, sensitivities: bool) -> PromRun:
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
    from aquarom_fenics.dynamics.muscle_power import mean_positive_power_gradient

    driven, xi, amplitude = scene_at(scene, space, z), z[: space.n_shapes], amplitude_of(space, z)
    result = simulate_reduced(prom, driven, xi, sensitivities=sensitivities, amplitude=amplitude,
                              amplitude_sensitivity=sensitivities and space.with_amplitude,
                              gait_sensitivity=sensitivities and space.n_gait > 0)
    if not result.completed:
        raise SolverError(f"PROM simulation at {space.as_dict(z)} stopped: {result.error}")
    if not counts_power(scene, space):
        return PromRun(float(result.distance), result.distance_gradient)
    columns = (True, space.with_amplitude, space.n_gait > 0) if sensitivities else None
    power, power_gradient = mean_positive_power_gradient(prom, driven, result, xi, amplitude, columns)
    return PromRun(float(result.distance), result.distance_gradient, power, power_gradient)


def weighted_cost(space: DesignSpace, weights: CostWeights, z: np.ndarray, distance: float,
                  distance_gradient: np.ndarray | None = None, run: PromRun | None = None) -> tuple[float, np.ndarray | None]:
    """L = -w_1 d + w_2 α E at z (E = A², or the run's P̄ when it carries one) and, given dd/dz, ∇L (None without)."""
    power = run is not None and run.power is not None
    cost = -weights.distance * distance
    if space.with_amplitude:
        cost += weights.energy * (weights.alpha * run.power if power else weights.energy_term(z[space.amplitude_index]))
    if distance_gradient is None:
        return cost, None
    gradient = -weights.distance * np.asarray(distance_gradient, dtype=float)
    if space.with_amplitude and power:
        gradient = gradient + weights.energy * weights.alpha * np.asarray(run.power_gradient, dtype=float)
    elif space.with_amplitude:
        gradient[space.amplitude_index] += weights.energy * 2 * weights.alpha * z[space.amplitude_index]
    return cost, gradient


def cost_value(prom: ReducedModel, scene: Scene, space: DesignSpace, z: np.ndarray, weights: CostWeights) -> float:
    """L at z without its gradient: a PROM run without sensitivities (a third cheaper; the same
    trajectory, so the same L as :func:`evaluate`'s). Raises SolverError as :func:`evaluate`."""
    run = _prom_run(prom, scene, space, z, sensitivities=False)
    cost, _ = weighted_cost(space, weights, z, run.distance, run=run)
    if not np.isfinite(cost):
        raise SolverError(f"non-finite cost at {space.as_dict(z)}: {cost}")
    return float(cost)


def evaluate(prom: ReducedModel, scene: Scene, space: DesignSpace, z: np.ndarray, weights: CostWeights) -> Evaluation:
    """PROM simulation with sensitivities at z; raises SolverError if it stops or turns non-finite."""
    result = _prom_run(prom, scene, space, z, sensitivities=True)
    distance_gradient = result.distance_gradient
    if distance_gradient is None:
        distance_gradient = np.zeros(len(z))
    cost, gradient = weighted_cost(space, weights, z, result.distance, distance_gradient, run=result)
    if not (np.isfinite(cost) and np.all(np.isfinite(gradient))):
        raise SolverError(f"non-finite cost or gradient at {space.as_dict(z)}: cost {cost}, gradient {gradient}")
    return Evaluation(z.copy(), float(cost), gradient, float(result.distance), distance_gradient)


def barrier_scale_at(settings, cost: float) -> float:
    """μ = barrier_weight · |L| of the paper method's L_b = L + μ B."""
    return settings.barrier_weight * max(abs(cost), 1e-12)


def first_order_at(scene: Scene, space: DesignSpace, evaluation: Evaluation) -> FirstOrder:
    """First-order measure and active set at an evaluated design; the paper method's barrier
    multipliers μ / s_i count for its inactive rows (not the amplitude's: A is under no barrier)."""
    settings = scene.optimizer
    barrier_scale = barrier_scale_at(settings, evaluation.cost) if settings.method == "paper" else 0.0
    return first_order(space, evaluation.z, evaluation.cost, evaluation.gradient, settings.active_tolerance,
                       barrier_scale, space.descent_barrier_rows)
