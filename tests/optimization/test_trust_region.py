"""The trust region's ratio test across PROMs on different bases, on an analytic cost.

Each 'PROM' is exact in its slopes but carries the projection error of its basis: an offset of L
that depends on where the basis was built. The builder reuses the last basis within half the
validity radius of its centre and builds a new one beyond (as ``PromBuilder`` does)."""
import numpy as np
import pytest

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.optimization import optimize as optimize_module
from aquarom_fenics.optimization.cost import Evaluation
from aquarom_fenics.optimization.optimize import optimize
from aquarom_fenics.optimization.prom_builder import BASIS_REUSE_FRACTION, PromBuilder

SHAPES = {"z_tail": {"bounds": [-0.2, 0.2]}, "y_thin": {"bounds": [-0.1, 0.1]}}
SLOPES = np.array([0.02, 0.01])      # d = 0.01 + SLOPES · z [m]: the optimum is the upper corner
OFFSET_SLOPE = 0.06                  # a basis built at ξ_b lowers d by this × z_tail(ξ_b) [m]


class BasisOffsetBuilder(PromBuilder):
    """'PROM' = (centre, basis centre); L_c(z) = -(0.01 + SLOPES · z) + OFFSET_SLOPE · z_tail(basis centre)."""

    def build(self, z):
        self.builds += 1
        z = np.array(z, dtype=float)
        if self.basis_center is None or np.any(np.abs(z - self.basis_center) > BASIS_REUSE_FRACTION * self.radius):
            self.basis_center = z.copy()
        return z, self.basis_center.copy()

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        distance = 0.01 + SLOPES @ z - OFFSET_SLOPE * prom[1][0]
        return Evaluation(z, -distance, -SLOPES.copy(), distance, SLOPES.copy())

    def cost(self, prom, z, weights):
        return self.evaluate(prom, z, weights).cost

    @staticmethod
    def shares_basis(prom, other):
        return bool(np.array_equal(prom[1], other[1]))

    def validity_radius(self, prom):
        """The scene's radius, as a PROM whose tensors change slowly carries it."""
        return self.radius

    def meshes(self, z):
        return True


@pytest.fixture(scope="module")
def scene():
    return scene_from_dict({"mesh": {"level": 1}, "shapes": SHAPES, "solver": {"duration": 1.0},
                            "optimizer": {"method": "trust-region", "max_iterations": 60}}, source="<toy>")


def test_a_new_basis_offset_is_no_loss_of_the_step_and_the_run_reaches_the_first_order_point(scene):
    """Judged by L_c(z_c) - L_z(z) across bases, every step past half the validity radius of the
    start's basis lost more to the new basis's offset than it gained: rejected until the radius
    fell below the step tolerance, at the start, first-order measure 0.8."""
    fish = load_fish(scene)
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=BasisOffsetBuilder(scene, fish, space))
    assert result.converged, (result.stop_reason, result.optimality.measure, result.optimum)
    assert result.optimum == pytest.approx(space.upper, abs=1e-9)
    assert sum(row["prom"] == "rejected" for row in result.history) == 0


def test_the_trust_box_is_capped_by_the_centre_prom_radius():
    """A PROM whose radius ``[reduction] validity_change`` capped below the scene's bounds the trust box
    (the CO sweep's first trust-region weight stopped on a candidate outside it); the amplitude's width stays."""
    from types import SimpleNamespace

    from aquarom_fenics.optimization.trust_region import trust_box

    prom = SimpleNamespace(validity_radius=np.array([0.0186, 0.125]))
    box = trust_box(np.array([0.125, 0.125, 0.35]), PromBuilder.validity_radius(prom), 2)
    assert np.allclose(box, [0.0186, 0.125, 0.35])


class CountingBuilder(BasisOffsetBuilder):
    """``BasisOffsetBuilder`` that records every simulation: (PROM, design) and whether with gradient."""

    def __init__(self, *args):
        super().__init__(*args)
        self.runs = []

    def evaluate(self, prom, z, weights):
        self.runs.append((tuple(prom[0]), tuple(prom[1]), tuple(np.asarray(z, dtype=float))))
        return super().evaluate(prom, z, weights)

    def cost(self, prom, z, weights):
        self.runs.append((tuple(prom[0]), tuple(prom[1]), tuple(np.asarray(z, dtype=float))))
        return BasisOffsetBuilder.evaluate(self, prom, z, weights).cost


def test_each_prom_is_simulated_once_per_design(scene):
    """The centre's evaluation starts the surrogate step and the step's own L at the candidate is
    the predicted one: no PROM is simulated twice at one design (before, every iteration ran the
    centre's PROM at the centre and at the candidate again)."""
    fish = load_fish(scene)
    space = optimize_module.optimization_space(scene, fish)
    builder = CountingBuilder(scene, fish, space)
    result = optimize(scene, fish=fish, builder=builder)
    assert result.converged and result.iterations >= 2
    assert len(builder.runs) == len(set(builder.runs)), [run for run in builder.runs if builder.runs.count(run) > 1]


RATIO = 0.6      # the 'PROM' at a centre overstates every slope by 1/RATIO: every step has ρ = RATIO


class ConstantRatioBuilder(BasisOffsetBuilder):
    """'PROM' = its centre c, one basis: L_c(z) = -(0.01 + SLOPES · c + SLOPES · (z - c) / RATIO), exact at c,
    so a step's actual reduction over the predicted one is RATIO whatever its length."""

    def build(self, z):
        self.builds += 1
        return np.array(z, dtype=float), np.zeros(2)

    def evaluate(self, prom, z, weights):
        z = np.array(z, dtype=float)
        distance = 0.01 + SLOPES @ prom[0] + SLOPES @ (z - prom[0]) / RATIO
        return Evaluation(z, -distance, -SLOPES / RATIO, distance, SLOPES / RATIO)


def _run_at_constant_ratio(scene, **optimizer):
    scene = scene.replace("optimizer", initial_radius=0.25, **optimizer)
    fish = load_fish(scene)
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=ConstantRatioBuilder(scene, fish, space))
    assert result.converged and result.optimum == pytest.approx(space.upper, abs=1e-9), result.stop_reason
    return [row["radius"] for row in result.history[1:]]


def test_the_radius_expands_above_expand_ratio_and_is_kept_below_it(scene):
    """ρ = 0.6 at every step from a quarter of the validity box, the optimum four validity radii away:
    kept at 1/4 by the default expand_ratio 3/4 (16 trial steps); with expand_ratio = 1/2 doubled at each
    step up to the whole box (1/4 + 1/2 + 1 + 1 + 1 + 1/4 of it: 6 steps); with expand_factor = 4 as well,
    straight from 1/4 to the box (5 steps)."""
    kept = _run_at_constant_ratio(scene)
    assert kept == [0.25] * 16
    doubled = _run_at_constant_ratio(scene, expand_ratio=0.5)
    assert doubled == [0.25, 0.5, 1.0, 1.0, 1.0, 1.0]
    quadrupled = _run_at_constant_ratio(scene, expand_ratio=0.5, expand_factor=4.0)
    assert quadrupled == [0.25, 1.0, 1.0, 1.0, 1.0]


def test_the_radius_update():
    """Halved below ρ = 1/4 whatever expand_ratio, kept between 1/4 and expand_ratio, grown by expand_factor
    above it, never beyond the validity box."""
    from aquarom_fenics.optimization.trust_region import resized_radius

    assert resized_radius(0.5, 0.2) == resized_radius(0.5, 0.2, expand_ratio=0.3) == 0.25
    assert resized_radius(0.25, 0.6) == 0.25
    assert resized_radius(0.25, 0.6, expand_ratio=0.5) == 0.5
    assert resized_radius(0.25, 0.6, expand_ratio=0.5, expand_factor=3.0) == 0.75
    assert resized_radius(0.5, 0.9, expand_factor=4.0) == 1.0
    assert resized_radius(1.0, -2.0) == 0.5


def test_the_radius_keys_are_checked_and_hashed_only_off_their_default():
    """expand_ratio and expand_factor came after scenes were hashed: at main's rule (3/4, 2) a scene keeps
    its hash (its checkpoints and caches); other values change it; values outside the rule's range are one
    clear line."""
    from aquarom_fenics.errors import InputError
    from aquarom_fenics.io.scene import Scene

    so3 = Scene.load("so3")
    assert so3.replace("optimizer", expand_ratio=0.75, expand_factor=2.0).hash == so3.hash
    assert so3.replace("optimizer", expand_ratio=0.5).hash != so3.hash
    assert so3.replace("optimizer", expand_factor=4.0).hash != so3.hash
    with pytest.raises(InputError, match=r"\[optimizer\] expand_ratio = 0.2 must be in \(0.25, 1\)"):
        so3.replace("optimizer", expand_ratio=0.2)
    with pytest.raises(InputError, match=r"\[optimizer\] expand_factor = 1.0 must be in \(1, 16\]"):
        so3.replace("optimizer", expand_factor=1.0)


WRONG_SLOPES = np.array([0.0, -0.03])     # a reused basis's d-slopes: y_thin's sign wrong, z_tail's lost


class ReusedBasisErrorBuilder(BasisOffsetBuilder):
    """'PROM' = (centre c, basis centre b): exact on its own basis (b = c), d = 0.01 + SLOPES · z; on a basis
    reused from another centre exact at c only, its slopes WRONG_SLOPES, so that every step it predicts from
    a reused-basis centre loses (ρ < 0) however short."""

    def build(self, z, own_basis=False):
        self.builds += 1
        z = np.array(z, dtype=float)
        if (own_basis or self.basis_center is None
                or np.any(np.abs(z - self.basis_center) > BASIS_REUSE_FRACTION * self.radius)):
            self.basis_center = z.copy()
        return z, self.basis_center.copy()

    def on_own_basis(self, prom):
        return bool(np.array_equal(prom[0], prom[1]))

    def evaluate(self, prom, z, weights):
        z, center = np.array(z, dtype=float), prom[0]
        slopes = SLOPES if self.on_own_basis(prom) else WRONG_SLOPES
        distance = 0.01 + SLOPES @ center + slopes @ (z - center)
        return Evaluation(z, -distance, -slopes.copy(), distance, slopes.copy())


def test_a_radius_that_shrinks_on_a_reused_basis_rebuilds_the_centre_on_its_own(scene):
    """SO2's trust region stopped on its radius at a first-order measure of 0.012: every step from a centre
    whose PROM reused another centre's basis was rejected, for the projection error of the reused basis moved
    its slopes, and a shorter step does not cure that. The centre's PROM is rebuilt on its own basis and the
    radius starts again; the run ends at the first-order point (the upper corner), where a stop on the radius
    alone ended at the first reused-basis centre."""
    scene = scene.replace("optimizer", initial_radius=0.25, max_iterations=200)
    fish = load_fish(scene)
    space = optimize_module.optimization_space(scene, fish)
    result = optimize(scene, fish=fish, builder=ReusedBasisErrorBuilder(scene, fish, space))
    assert result.converged, (result.stop_reason, result.optimality.measure, result.optimum)
    assert result.optimum == pytest.approx(space.upper, abs=1e-9)
    assert sum(row["prom"] == "rejected" for row in result.history) > 0      # the reused bases did stall it


def test_a_stall_on_a_prom_on_its_own_basis_stops_the_run(scene):
    """The same slopes with every PROM claimed on its own basis: nothing to rebuild, the run stops at the first
    stall (the first centre whose slopes are wrong) as before, and no PROM is asked for on its own basis."""

    class OwnBasisClaimed(ReusedBasisErrorBuilder):
        own_basis_builds = 0

        def build(self, z, own_basis=False):
            self.own_basis_builds += own_basis
            return super().build(z, own_basis)

        def on_own_basis(self, prom):
            return True

        def evaluate(self, prom, z, weights):
            z, center = np.array(z, dtype=float), prom[0]
            slopes = SLOPES if ReusedBasisErrorBuilder.on_own_basis(self, prom) else WRONG_SLOPES
            distance = 0.01 + SLOPES @ center + slopes @ (z - center)
            return Evaluation(z, -distance, -slopes.copy(), distance, slopes.copy())

    scene = scene.replace("optimizer", initial_radius=0.25, max_iterations=200)
    fish = load_fish(scene)
    space = optimize_module.optimization_space(scene, fish)
    builder = OwnBasisClaimed(scene, fish, space)
    result = optimize(scene, fish=fish, builder=builder)
    assert not result.converged and "stalled before optimality" in result.stop_reason, result.stop_reason
    assert result.optimum == pytest.approx([0.0125, 0.00625], abs=1e-12)
    assert builder.own_basis_builds == 0


def test_a_run_cut_by_max_iterations_after_a_rebuild_says_so(scene):
    """After a stall rebuilt the centre's PROM on its own basis, a run that then uses up ``max_iterations`` stops on
    that safeguard, not on the stall it recovered from (which the stop reason kept before)."""
    for iterations in (6, 9, 12):
        short = scene.replace("optimizer", initial_radius=0.25, max_iterations=iterations)
        fish = load_fish(short)
        space = optimize_module.optimization_space(short, fish)
        result = optimize(short, fish=fish, builder=ReusedBasisErrorBuilder(short, fish, space))
        assert not result.converged and result.iterations == iterations
        assert result.stop_reason == "maximum number of iterations (safeguard)", (iterations, result.stop_reason)
