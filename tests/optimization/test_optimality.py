"""First-order optimality, active sets and multi-start (SPEC §10) on analytic costs.

The multi-start test runs the optimiser and the study driver unchanged, with the PROM builder and
the FOM distance replaced by an analytic two-well swimming distance (a seam of ``optimize``)."""
import json

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.optimization import optimize as optimize_module
from aquarom_fenics.studies import study
from aquarom_fenics.optimization.cost import CostWeights, Evaluation, design_space, first_order
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.optimization.optimize import optimize, start_points
from aquarom_fenics.optimization.prom_builder import PromBuilder
from aquarom_fenics.io.scene import scene_from_dict

SHAPES = {"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1]}}
WIDTHS = np.array([0.4, 0.2])
# two wells of the distance in u = z / (upper - lower) · 2: the deeper at A, the shallower at B
WELL_A, WELL_B = np.array([-0.5, -0.5]), np.array([0.5, 0.5])
DEPTH_A, DEPTH_B, SPREAD, OFFSET = 0.03, 0.024, 0.18, 0.01


def two_wells(z: np.ndarray) -> tuple[float, np.ndarray]:
    """d(z) = offset + Σ_w depth_w exp(-‖u - u_w‖² / spread), u = 2 z / width; and ∂d/∂z."""
    u = 2 * np.asarray(z, dtype=float) / WIDTHS
    distance, gradient = OFFSET, np.zeros(2)
    for centre, depth in ((WELL_A, DEPTH_A), (WELL_B, DEPTH_B)):
        bump = depth * np.exp(-np.sum((u - centre) ** 2) / SPREAD)
        distance += bump
        gradient += bump * (-2 * (u - centre) / SPREAD) * 2 / WIDTHS
    return distance, gradient


class AnalyticBuilder(PromBuilder):
    """A builder whose 'PROM' is the analytic distance: same counters, no mesh work."""

    def build(self, z):
        self.builds += 1
        return np.array(z, dtype=float)

    def evaluate(self, prom, z, weights):
        distance, gradient = two_wells(z)
        return Evaluation(np.array(z, dtype=float), -distance, -gradient, distance, gradient)

    def cost(self, prom, z, weights):
        return self.evaluate(prom, z, weights).cost

    def meshes(self, z):
        return True

    def validity_radius(self, prom):
        """The scene's radius, as a PROM whose tensors change slowly carries it."""
        return self.radius

    def trusts(self, prom, z):
        """The 'PROM' is the design it was built at: trusted within the scene's validity radius of it."""
        return prom is not None and bool(np.all(np.abs(np.asarray(z) - prom) <= self.radius))

    def refuse_infeasible(self, prom, z):
        pass

    @staticmethod
    def shares_basis(prom, other):
        """One analytic cost: every 'PROM' on the same (no) basis."""
        return True


def toy(method, **optimizer):
    """The toy scene; the paper method's linearised steps re-linearise within a tenth of the wells' spacing."""
    paper = {"rebuild_threshold": 0.02, "n_rebuild": 2, "step_tolerance": 1e-5} if method == "paper" else {}
    return scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES, "solver": {"duration": 1.0},
                            "optimizer": {"method": method, "max_iterations": 60, **paper, **optimizer}},
                           source="<toy>")


@pytest.fixture(scope="module")
def fish():
    return load_fish(toy("paper"))


def test_measure_is_zero_at_a_bound_optimum_and_names_it_active_with_a_positive_multiplier():
    space = design_space(toy("trust-region"))
    z = np.array([0.2, 0.0])                      # z_tail on its upper bound, y_thin interior
    gradient = np.array([-0.5, 0.0])              # L decreases beyond the bound: held by it
    result = first_order(space, z, -1.0, gradient, tolerance=1e-2)
    assert result.measure < 1e-14
    assert [row["constraint"] for row in result.active] == ["z_tail = upper"]
    assert result.active[0]["multiplier"] > 0


def test_measure_sees_a_gradient_pointing_into_the_set_and_the_multiplier_turns_negative():
    space = design_space(toy("trust-region"))
    z = np.array([0.2, 0.0])
    gradient = np.array([0.5, 0.1])               # L decreases inwards: the bound does not hold
    result = first_order(space, z, -1.0, gradient, tolerance=1e-2)
    # ‖D r‖_∞ / |L| with r the whole gradient (λ ≥ 0 cannot absorb it): 0.4 · 0.5 / 1
    assert result.measure == pytest.approx(0.2)
    assert result.active[0]["multiplier"] < 0


def test_linear_constraint_rows_are_active_within_a_fraction_of_their_range():
    data = {"mesh": {"level": 1}, "shapes": SHAPES,
            "constraints": [{"coefficients": {"z_tail": 1.0, "y_thin": 1.0}, "upper": 0.1}]}
    space = design_space(scene_from_dict(data, source="<toy>"))
    # row range Σ|A_ij| width_j = 0.6; slack 0.003 = 0.5 % of it
    z = np.array([0.05, 0.047])
    gradient = -np.array([1.0, 1.0])
    result = first_order(space, z, -1.0, gradient, tolerance=1e-2)
    assert [row["constraint"] for row in result.active] == ["constraint row 1"]
    assert result.active[0]["slack_over_range"] == pytest.approx(0.005)
    assert result.measure < 1e-12 and result.active[0]["multiplier"] == pytest.approx(1.0)
    assert first_order(space, z, -1.0, gradient, tolerance=1e-3).measure > 0.1


@pytest.mark.parametrize("method", ["paper", "trust-region"])
def test_both_methods_stop_by_optimality_at_the_deeper_well(method, fish):
    scene = toy(method)
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=AnalyticBuilder(scene, fish, space), start=np.array([-0.02, -0.01]))
    assert result.stop_reason.startswith("first-order optimality"), result.stop_reason
    assert result.converged and result.iterations < scene.optimizer.max_iterations
    assert np.all(np.abs(result.optimum - WELL_A * WIDTHS / 2) < 0.01 * WIDTHS), result.optimum


def test_start_points_are_seeded_feasible_and_begin_with_the_scene_start(fish):
    data = {"mesh": {"level": 1}, "shapes": SHAPES,
            "constraints": [{"coefficients": {"z_tail": 1.0, "y_thin": 1.0}, "upper": 0.0}]}
    space = design_space(scene_from_dict(data, source="<toy>"))
    points = start_points(space, 6, seed=3, meshes=lambda z: True)
    again = start_points(space, 6, seed=3, meshes=lambda z: True)
    assert len(points) == 6 and np.all(points[0] == space.start)
    assert all(space.is_feasible(z) for z in points)
    np.testing.assert_array_equal(np.array(points), np.array(again))


def test_multistart_finds_both_local_optima_and_picks_the_better_verified_one(fish, tmp_path, monkeypatch):
    monkeypatch.setattr(optimize_module, "PromBuilder", AnalyticBuilder)
    monkeypatch.setattr(study, "PromBuilder", AnalyticBuilder)
    monkeypatch.setattr(study, "fom_distance", lambda scene, fish, design, amplitude: two_wells(
        np.array([design["z_tail"], design["y_thin"]]))[0])
    scene = toy("trust-region", starts=4, seed=0)
    study.run_optimization(scene, tmp_path, fish=fish, render=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    optima = np.array([[row["optimum"]["z_tail"], row["optimum"]["y_thin"]]
                       for row in summary["multistart"]["local_optima"]])
    for well in (WELL_A, WELL_B):
        assert np.any(np.all(np.abs(optima - well * WIDTHS / 2) < 0.01 * WIDTHS, axis=1)), (well, optima)
    assert len(summary["multistart"]["distinct_optima"]) == 2
    best = summary["multistart"]["local_optima"][summary["multistart"]["best_start"] - 1]
    assert np.allclose([best["optimum"]["z_tail"], best["optimum"]["y_thin"]], WELL_A * WIDTHS / 2, atol=0.004)
    assert summary["fom_check"]["optimal_distance"] == pytest.approx(max(r["fom_distance"] for r in
                                                                         summary["multistart"]["local_optima"]))
    for k in range(1, 5):
        assert (tmp_path / f"start_{k}" / "summary.json").exists()


class SlopeBuilder(AnalyticBuilder):
    """d(z) = 0.01 + 0.01 z_tail + 0.01 (1 - (y_thin / 0.05)²): a pull onto z_tail's upper bound,
    an interior optimum in y_thin."""

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        distance = 0.01 + 0.01 * z[0] + 0.01 * (1 - (z[1] / 0.05) ** 2)
        gradient = np.array([0.01, -0.02 * z[1] / 0.05 ** 2])
        return Evaluation(z, -distance, -gradient, distance, gradient)


def test_paper_method_moves_a_bound_the_barrier_holds_off_onto_it(fish):
    scene = toy("paper")
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=SlopeBuilder(scene, fish, space))
    assert "z_tail = upper moved from the barrier iterate onto the bound" in result.stop_reason, result.stop_reason
    assert result.optimum[0] == 0.2 and abs(result.optimum[1]) < 0.01 * 0.2
    assert result.converged
    assert [row["constraint"] for row in result.optimality.active] == ["z_tail = upper"]


def test_paper_method_confirms_a_bound_optimum_with_one_build_on_the_bound(fish):
    """Optimal by its linearised gradient next to the bound, the barrier iterate is not built: the
    PROM built on the bound judges the first-order measure there."""
    scene = toy("paper")
    space = optimize_module.optimization_space(scene, fish)
    built = []

    class RecordingSlopeBuilder(SlopeBuilder):
        def build(self, z):
            built.append(np.array(z, dtype=float))
            return super().build(z)

    result = optimize(scene, fish=fish, builder=RecordingSlopeBuilder(scene, fish, space))
    assert result.converged
    assert [row["prom"] for row in result.history[-2:]] == ["approximated", "built"]
    np.testing.assert_array_equal(built[-1], result.optimum)
    barrier_iterate = [result.history[-2][f"xi_{name}"] for name in space.names]
    assert not any(np.allclose(design, barrier_iterate) for design in built)


class CheckedSlopeBuilder(SlopeBuilder):
    """SlopeBuilder whose design check refuses z_tail > 0.05 (as the mesh check refuses inverted cells)."""

    def refuse_infeasible(self, prom, z):
        if z[0] > 0.05:
            raise InputError(f"design z_tail = {z[0]:.4f} is refused by the design check")

    def build(self, z):
        self.refuse_infeasible(None, z)
        return super().build(z)

    def meshes(self, z):
        return z[0] <= 0.05


def test_paper_method_stops_at_the_last_accepted_design_when_the_check_refuses_every_step(fish):
    scene = toy("paper")
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=CheckedSlopeBuilder(scene, fish, space))
    assert result.stop_reason.startswith("every step from the last accepted design is refused"), result.stop_reason
    assert 0.04 < result.optimum[0] <= 0.05 and abs(result.optimum[1]) < 0.01 * 0.2


class StrokeBuilder(AnalyticBuilder):
    """Co-optimisation: d(ξ, A) = c(ξ) A^1.5 with c = 1 + 2 z_tail - 10 y_thin² (largest on z_tail's
    upper bound), convex in A as the swimmer's distance is; the amplitude is the last entry of z."""

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        shape = 1.0 + 2.0 * z[0] - 10.0 * z[1] ** 2
        distance = shape * z[2] ** 1.5
        gradient = np.array([2.0 * z[2] ** 1.5, -20.0 * z[1] * z[2] ** 1.5, 1.5 * shape * z[2] ** 0.5])
        cost = -weights.distance * distance + weights.energy * weights.energy_term(z[2])
        cost_gradient = -weights.distance * gradient
        cost_gradient[2] += weights.energy * 2 * weights.alpha * z[2]
        return Evaluation(z, cost, cost_gradient, distance, gradient)

    def trusts(self, prom, z):
        """Valid over the whole amplitude range (as the PROM is), within the radius in the shapes."""
        return prom is not None and bool(np.all(np.abs(np.asarray(z)[:2] - prom[:2]) <= self.radius))


@pytest.mark.parametrize("w1", [0.2, 0.3, 0.9])
def test_paper_method_co_optimisation_ends_at_the_first_order_point_of_every_weight(fish, w1):
    """L = -w₁ c A^1.5 + (1 - w₁) A² on the shape corner c = 1.4: A* = (0.75 w₁ c / (1 - w₁))², or
    the amplitude's upper bound 0.4. The descent on (ξ, A) together ran out of iterations here."""
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES, "solver": {"duration": 1.0},
                             "cooptimization": {"enabled": True, "amplitude_bounds": [0.05, 0.4]},
                             "optimizer": {"method": "paper", "max_iterations": 100}}, source="<toy>")
    space = optimize_module.optimization_space(scene, fish)
    weights = CostWeights(distance=w1, energy=1.0 - w1)
    result = optimize(scene, fish=fish, weights=weights, builder=StrokeBuilder(scene, fish, space))
    assert result.converged, (result.stop_reason, result.optimality.measure)
    expected = min((0.75 * w1 * 1.4 / (1.0 - w1)) ** 2, 0.4)
    assert result.optimum[0] == 0.2 and abs(result.optimum[1]) < 0.01 * 0.2
    assert result.optimum[2] == pytest.approx(expected, rel=1e-3)


class FaceBuilder(AnalyticBuilder):
    """d = 0.01 + 0.02 z_tail + 0.01 y_thin - 0.5 z_tail²: uphill through the face z_tail + y_thin ≤ 0.1,
    whose best point (z_tail, y_thin) = (0.01, 0.09) lies inside the box."""

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        distance = 0.01 + 0.02 * z[0] + 0.01 * z[1] - 0.5 * z[0] ** 2
        gradient = np.array([0.02 - z[0], 0.01])
        return Evaluation(z, -distance, -gradient, distance, gradient)


def test_paper_method_slides_along_a_nearly_active_linear_constraint_to_its_best_point(fish):
    """The fraction to the boundary alone cut every step at the face and halved W of both
    parameters: the run crept along the face (55 iterations here; SO9 stalled on the step tolerance)."""
    scene = scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES, "solver": {"duration": 1.0},
                             "constraints": [{"coefficients": {"z_tail": 1.0, "y_thin": 1.0}, "upper": 0.1}],
                             "optimizer": {"method": "paper", "max_iterations": 100, "rebuild_threshold": 0.02,
                                           "n_rebuild": 2, "step_tolerance": 1e-5}}, source="<toy>")
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=FaceBuilder(scene, fish, space))
    assert result.converged, (result.stop_reason, result.optimality.measure)
    assert [row["constraint"] for row in result.optimality.active] == ["constraint row 1"]
    assert result.optimum[0] == pytest.approx(0.01, abs=0.01 * 0.2)
    assert result.iterations <= 25          # 55 when every step was cut at the face


def test_paper_state_reads_a_checkpoint_state_of_either_format_and_writes_it_back_unchanged():
    """A state written before ``prom_z``, ``confirm`` and ``restarted`` existed loads (the PROM at the
    centre, no confirmation pending, W not restarted); a full one survives the JSON round trip."""
    from aquarom_fenics.optimization.paper_state import PaperState

    old = {"z": [0.1, -0.02], "iteration": 7, "scaling": [0.5, 0.25], "previous_gradient": None, "since_build": 2,
           "center": {"z": [0.1, -0.01], "distance": 0.03, "distance_gradient": [0.2, -0.1]}}
    state = PaperState.from_dict(json.loads(json.dumps(old)))
    assert state.center.prom_z.tolist() == [0.1, -0.01] and not state.confirm and not state.restarted
    assert state.center.at(np.array([0.1, -0.02]))[0] == pytest.approx(0.03 + 0.001)
    full = state.to_dict() | {"previous_gradient": [1e-3, -2e-3], "confirm": True, "restarted": True}
    assert PaperState.from_dict(json.loads(json.dumps(full))).to_dict() == full
