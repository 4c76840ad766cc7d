"""Taylor tests of a scene's PROM against its own FOM forms and finite differences (SPEC §8–§10).

1. tensors      ‖r_PROM(η, η̇, η̈; ξ_c) - Vᵀ r_FOM(Vη, Vη̇, Vη̈; ξ_c)‖ / ‖Vᵀ r_FOM‖ < 1e-9
2. ∂f_int/∂ξ_k  PROM Taylor term against a 4th-order central difference of Vᵀ f_int of the FOM, < 1e-5
3. Taylor order ‖f_int,PROM - Vᵀ f_int,FOM‖ at ξ_c + ε d, ε = 0.04, 0.02, 0.01: ratios 2^(order+1) ± 25 %
4. S = dη/dξ_k  direct sensitivities against central differences of the PROM, < 1e-5
5. dL/dz_k      cost gradient against central differences of the cost, < 1e-6

The FOM of every comparison is the design pulled back to the nominal mesh with the exact shape
gradient (SPEC §4–§5), as the PROM; the PROM's basis must live on the scene's mesh.
Differences run on a short horizon with a tight Newton tolerance.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np

from aquarom_fenics.optimization.cost import CostWeights, design_space, evaluate
from aquarom_fenics.errors import SolverError
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.reduction.projection import project_vector
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.dynamics.reduced_dynamics import ReducedSystem, simulate_reduced
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.dynamics.trajectory import DISTANCE_WINDOW

TENSOR_TOLERANCE = 1e-9
DERIVATIVE_TOLERANCE = 1e-5
TAYLOR_RATIO_TOLERANCE = 0.25
SENSITIVITY_TOLERANCE = 1e-5
COST_GRADIENT_TOLERANCE = 1e-6

STATE_SCALE = 0.02               # random η, η̇, η̈ ~ 0.02 N(0, 1) (mass-normalised basis)
TENSOR_SAMPLES = 10
DERIVATIVE_STEP = 2e-3           # ξ step of the 4th-order central difference of the FOM
TAYLOR_EPSILONS = (0.04, 0.02, 0.01)
TAYLOR_REACH = 0.1               # ε = 0.04 reaches this fraction of the validity radius
PROBE_REACH = 0.5                # the sensitivity and cost checks run at ξ_c + this fraction of the radius
DIFFERENCE_STEP = 1e-5           # central-difference step of the PROM and cost checks
SHORT_HORIZON = 0.4              # s
TIGHT_TOLERANCE = 1e-11          # Newton tolerance of the differenced runs
ZERO_GUARD = 1e-9                # a reference below this fraction of its scale counts as zero

COLUMNS = (("check", 32), ("measured", 20), ("order", 12), ("tolerance", 14), ("result", 6))


@dataclass
class CheckResult:
    """One row of the table; ``passed`` is None when the check does not apply."""

    check: str
    measured: str
    tolerance: str
    passed: bool | None
    order: str = ""
    note: str = ""

    def __post_init__(self):
        if self.passed is not None:
            self.passed = bool(self.passed)

    @property
    def status(self) -> str:
        return {True: "PASS", False: "FAIL", None: "SKIP"}[self.passed]


def table_header() -> str:
    return format_cells([name for name, _ in COLUMNS])


def table_row(result: CheckResult) -> str:
    cells = [result.check, result.measured, result.order, result.tolerance, result.status]
    row = format_cells(cells)
    return f"{row}  {result.note}" if result.note else row


def format_cells(cells) -> str:
    return "  ".join(f"{cell:<{width}}" for cell, (_, width) in zip(cells, COLUMNS)).rstrip()


def relative(difference: float, reference: float, scale: float) -> float:
    """difference / reference, with a reference below ZERO_GUARD × scale replaced by that floor."""
    return difference / max(reference, ZERO_GUARD * scale)


def taylor_order(prom: ReducedModel) -> int:
    """Order of the PROM's Taylor polynomials in ξ (0 for a plain ROM)."""
    stiffness = prom.elastic.linear
    return 2 if stiffness.second is not None else 1 if stiffness.first is not None else 0


def short_scene(scene: Scene) -> Scene:
    """The scene over ≈ SHORT_HORIZON (whole steps, at least the distance window) with a tight Newton."""
    step = scene.solver.time_step
    steps = max(int(round(SHORT_HORIZON / step)), int(np.ceil(DISTANCE_WINDOW / step - 1e-9)))
    return scene.replace("solver", duration=steps * step, tolerance=TIGHT_TOLERANCE)


def probe_offset(prom: ReducedModel, reach: float) -> np.ndarray:
    """A fixed direction in ξ, each component within ``reach`` × the PROM's validity radius."""
    pattern = np.random.default_rng(4).uniform(0.3, 1.0, prom.n_parameters)
    signs = np.resize([1.0, -1.0], prom.n_parameters)
    return reach * prom.validity_radius * pattern * signs


class ProjectedFOM:
    """Vᵀ r_FOM(V η, V η̇, V η̈) of the design ξ (pulled back with its exact shape gradient, as the
    PROM), with the PROM's basis V."""

    def __init__(self, scene: Scene, fish: Fish, prom: ReducedModel, xi: np.ndarray):
        self.fish, self.prom = fish, prom
        self.model = FullOrderModel(scene, fish, self.design(xi))
        self.vectors = np.column_stack([self.model.owned_values(prom.basis[:, :, j]) for j in range(prom.size)])

    def design(self, xi: np.ndarray) -> np.ndarray:
        """The full design vector: the PROM's shapes at ξ, the scene's other shapes at its design point."""
        return self.fish.parameter_vector(self.prom.design_point | dict(zip(self.prom.shape_names, map(float, xi))))

    def internal_force_at(self, xi: np.ndarray, eta) -> np.ndarray:
        """Vᵀ f_int(V η) of the design ξ, on this model's mesh and forms.

        f_int = ∂Π/∂u involves ξ only through ∇u_ξ at the points of the stiffness rule (ElasticTerm):
        with that field set to ξ's (and set back after) the force is the one of a model built at ξ,
        without building its other terms (the differences of checks 2 and 3 need a few dozen designs).
        """
        gradient, points = self.model.shape_gradients["stiffness"], self.model.quadrature_points["stiffness"]
        try:
            fx.set_quadrature_values(gradient, self.fish.shape_gradient(self.design(xi), points.reshape(-1, 3)))
            return self.internal_force(eta)
        finally:
            fx.set_quadrature_values(gradient, self.fish.shape_gradient(self.model.xi, points.reshape(-1, 3)))

    def project(self, owned: np.ndarray) -> np.ndarray:
        return project_vector(self.model.comm, self.vectors, owned)

    def residual(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        V = self.vectors
        return self.project(self.model.residual(time, V @ eta, V @ eta_dot, V @ eta_ddot)[0])

    def internal_force(self, eta) -> np.ndarray:
        return self.project(self.model.internal_force(self.vectors @ eta))


def basis_mismatch(prom: ReducedModel, fish: Fish) -> str | None:
    """Why the PROM's basis cannot live on the scene's mesh, or None."""
    nodes, cells = fish.nodes.points.shape[0], fish.mesh.cells.shape[0]
    if prom.basis.shape[0] != nodes or prom.cells != cells:
        return (f"the PROM's basis is on a mesh of {prom.basis.shape[0]} nodes, {prom.cells} cells; the scene's "
                f"mesh has {nodes} nodes, {cells} cells (built from another mesh)")
    return None


def reduced_system(prom: ReducedModel, scene: Scene, xi: np.ndarray) -> ReducedSystem:
    return ReducedSystem(prom, scene, xi, TimeScheme.from_solver(scene.solver))


def check_tensors(prom: ReducedModel, scene: Scene, projected: ProjectedFOM) -> CheckResult:
    """Check 1: at ξ_c and random (η, η̇, η̈), max of the relative errors of r and f_int < 1e-9."""
    system = reduced_system(prom, scene, prom.xi_center)
    rng = np.random.default_rng(0)
    worst = 0.0
    for sample in range(TENSOR_SAMPLES):
        eta, eta_dot, eta_ddot = (STATE_SCALE * rng.standard_normal(prom.size) for _ in range(3))
        time = 0.05 * (sample + 1)
        expected = projected.residual(time, eta, eta_dot, eta_ddot)
        actual = system.residual(time, eta, eta_dot, eta_ddot)[0]
        expected_force = projected.internal_force(eta)
        worst = max(worst, np.linalg.norm(actual - expected) / np.linalg.norm(expected),
                    np.linalg.norm(system.internal_force(eta) - expected_force) / np.linalg.norm(expected_force))
    return CheckResult("1 tensors at ξ_c", f"{worst:.2e}", f"< {TENSOR_TOLERANCE:.0e}", worst < TENSOR_TOLERANCE,
                       note=f"r and f_int, {TENSOR_SAMPLES} random states")


def check_force_derivatives(prom: ReducedModel, scene: Scene, projected: ProjectedFOM) -> Iterator[CheckResult]:
    """Check 2: ∂f_int,r/∂ξ_k at ξ_c against (8 (f(+h) - f(-h)) - (f(+2h) - f(-2h))) / (12 h) of the FOM.

    Relative to the central difference, floored at 1e-9 ‖f_int,r‖ / h: a shape that moves only the
    clamped head has a zero derivative on both sides, and the difference quotient then holds only
    the round-off of the assembly (≈ 1e-16 ‖f_int,r‖ / h, summed in another order on each mesh in parallel).
    """
    eta = STATE_SCALE * np.random.default_rng(2).standard_normal(prom.size)
    derivative = reduced_system(prom, scene, prom.xi_center).internal_force_gradient(eta)
    force_scale = np.linalg.norm(projected.internal_force(eta))

    def force(offset):
        return projected.internal_force_at(prom.xi_center + offset, eta)

    for k, name in enumerate(prom.shape_names):
        unit = DERIVATIVE_STEP * np.eye(prom.n_parameters)[k]
        central = (8 * (force(unit) - force(-unit)) - (force(2 * unit) - force(-2 * unit))) / (12 * DERIVATIVE_STEP)
        error = relative(np.linalg.norm(derivative[k] - central), np.linalg.norm(central),
                         force_scale / DERIVATIVE_STEP)
        yield CheckResult(f"2 ∂f_int/∂ξ {name}", f"{error:.2e}", f"< {DERIVATIVE_TOLERANCE:.0e}",
                          error < DERIVATIVE_TOLERANCE, note=f"FOM central difference, h = {DERIVATIVE_STEP:g}")


def check_taylor_order(prom: ReducedModel, scene: Scene, projected: ProjectedFOM) -> CheckResult:
    """Check 3: e(ε) = ‖f_int,PROM - Vᵀ f_int,FOM‖ at ξ_c + ε d falls like ε^(order+1).

    Passes when every e(2ε)/e(ε) is 2^(order+1) ± 25 %; the order column is log2 of the ratios.
    d is fixed, ε = 0.04 reaching 0.1 of the validity radius. Errors at round-off (below 1e-9 of
    the force) mean the PROM is exact along d and pass.
    """
    order = taylor_order(prom)
    expected = 2.0 ** (order + 1)
    tolerance = f"ratio {expected:g} ± {100 * TAYLOR_RATIO_TOLERANCE:g} %"
    name = f"3 Taylor order {order}"
    direction = probe_offset(prom, TAYLOR_REACH) / TAYLOR_EPSILONS[0]
    eta = STATE_SCALE * np.random.default_rng(3).standard_normal(prom.size)
    errors, force_scale = [], 0.0
    for epsilon in TAYLOR_EPSILONS:
        xi = prom.xi_center + epsilon * direction
        reference = projected.internal_force_at(xi, eta)
        errors.append(np.linalg.norm(reduced_system(prom, scene, xi).internal_force(eta) - reference))
        force_scale = max(force_scale, np.linalg.norm(reference))
    if errors[0] <= ZERO_GUARD * force_scale:
        return CheckResult(name, f"error {errors[0]:.1e}", tolerance, True, note="exact along d (error at round-off)")
    ratios = [errors[i] / errors[i + 1] for i in range(len(errors) - 1)]
    passed = all(abs(ratio / expected - 1) <= TAYLOR_RATIO_TOLERANCE for ratio in ratios)
    return CheckResult(name, "ratios " + ", ".join(f"{r:.3f}" for r in ratios), tolerance, passed,
                       order=", ".join(f"{np.log2(r):.2f}" for r in ratios),
                       note=f"ε = {', '.join(map(str, TAYLOR_EPSILONS))}; error order log2(ratio) ≈ {order + 1}")


def completed_run(prom: ReducedModel, scene: Scene, xi: np.ndarray, **options):
    """``simulate_reduced``; a run that stops raises SolverError."""
    result = simulate_reduced(prom, scene, xi, **options)
    if not result.completed:
        raise SolverError(f"PROM at ξ = {dict(zip(prom.shape_names, np.round(xi, 6).tolist()))}: {result.error}")
    return result


def check_sensitivities(prom: ReducedModel, scene: Scene) -> Iterator[CheckResult]:
    """Check 4: ‖S_k - (η(ξ + h e_k) - η(ξ - h e_k)) / (2h)‖ / ‖…‖ < 1e-5 over all samples, h = 1e-5.

    At ξ = ξ_c + a fixed offset inside the validity radius, over the short horizon.
    """
    short = short_scene(scene)
    xi = prom.xi_center + probe_offset(prom, PROBE_REACH)
    sensitivities = completed_run(prom, short, xi, sensitivities=True).sensitivities
    centrals = []
    for k in range(prom.n_parameters):
        shift = DIFFERENCE_STEP * np.eye(prom.n_parameters)[k]
        plus = completed_run(prom, short, xi + shift).states
        minus = completed_run(prom, short, xi - shift).states
        centrals.append((plus - minus) / (2 * DIFFERENCE_STEP))
    scale = max(np.linalg.norm(central) for central in centrals)
    for k, (name, central) in enumerate(zip(prom.shape_names, centrals)):
        error = relative(np.linalg.norm(sensitivities[:, :, k] - central), np.linalg.norm(central), scale)
        yield CheckResult(f"4 sensitivity {name}", f"{error:.2e}", f"< {SENSITIVITY_TOLERANCE:.0e}",
                          error < SENSITIVITY_TOLERANCE, note=f"over {short.solver.duration:g} s")


def check_cost_gradient(prom: ReducedModel, scene: Scene) -> Iterator[CheckResult]:
    """Check 5: |∂L/∂z_k - (L(z + h e_k) - L(z - h e_k)) / (2h)| / |…| < 1e-6 per component, h = 1e-5.

    z = (ξ_c + a fixed offset, and the start amplitude for co-optimisation); L = -d, or
    ½ (-d) + ½ α A² for co-optimisation.
    """
    short = short_scene(scene)
    space = design_space(short)
    weights = CostWeights(0.5, 0.5, short.cooptimization.energy_weight) if space.with_amplitude else CostWeights()
    z = np.concatenate([prom.xi_center + probe_offset(prom, PROBE_REACH), space.start[space.n_shapes:]])
    gradient = evaluate(prom, short, space, z, weights).gradient
    centrals = []
    for k in range(z.size):
        shift = DIFFERENCE_STEP * np.eye(z.size)[k]
        centrals.append((evaluate(prom, short, space, z + shift, weights).cost
                         - evaluate(prom, short, space, z - shift, weights).cost) / (2 * DIFFERENCE_STEP))
    scale = float(np.linalg.norm(centrals))
    for name, exact, central in zip(space.names, gradient, centrals):
        error = relative(abs(exact - central), abs(central), scale)
        yield CheckResult(f"5 cost gradient {name}", f"{error:.2e}", f"< {COST_GRADIENT_TOLERANCE:.0e}",
                          error < COST_GRADIENT_TOLERANCE, note=f"∂L/∂z = {exact:.4e}")


XI_CHECKS = ("2 ∂f_int/∂ξ", "3 Taylor order", "4 sensitivity", "5 cost gradient")


def skipped(name: str, reason: str) -> CheckResult:
    return CheckResult(name, "-", "", None, note=reason)


def run_checks(scene: Scene, prom: ReducedModel, fish: Fish | None = None) -> Iterator[CheckResult]:
    """Checks 1–5 of the scene's PROM, one result at a time.

    Checks 1–3 compare with the FOM and need the PROM's basis on the scene's mesh: a basis from
    another mesh fails check 1 with the reason and skips 2–3; 4–5 involve the PROM only.
    """
    fish = fish or load_fish(scene)
    mismatch = basis_mismatch(prom, fish)
    if mismatch:
        yield CheckResult("1 tensors at ξ_c", "-", f"< {TENSOR_TOLERANCE:.0e}", False, note=mismatch)
    else:
        projected = ProjectedFOM(scene, fish, prom, prom.xi_center)
        yield check_tensors(prom, scene, projected)
    if prom.n_parameters == 0:
        yield from (skipped(name, "the PROM has no shape parameters") for name in XI_CHECKS)
        return
    if mismatch:
        yield from (skipped(name, "needs the PROM's basis on the scene's mesh") for name in XI_CHECKS[:2])
    else:
        yield from check_force_derivatives(prom, scene, projected)
        yield check_taylor_order(prom, scene, projected)
    yield from check_sensitivities(prom, scene)
    yield from check_cost_gradient(prom, scene)
