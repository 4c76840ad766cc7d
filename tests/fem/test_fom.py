"""Full-order model on the coarsest mesh (SPEC §5–§6)."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.simulate import simulate_fom
from conftest import coarse_scene

DESIGN = {"y_thin": 0.1, "z_tail": 0.2}
LINEAR_DESIGN = {"y_thin": 0.1}
"""A design field linear in the coordinates: the displacement space represents it exactly, so a
rigid motion of its nodes is a rigid motion of the body and its moved mesh is the exact design
(for the √ profile of z_tail, F_1 = I + ∇u_ξ at the quadrature points is not a nodal field)."""
SHAPES = {"y_thin": {"bounds": [-0.15, 0.15]}, "z_tail": {"bounds": [-0.5, 0.5]}}


@pytest.fixture(scope="module")
def shaped_model():
    scene = coarse_scene(shapes=SHAPES)
    return FullOrderModel(scene, load_fish(scene), DESIGN)


def relative_error(actual, expected):
    return np.linalg.norm(np.asarray(actual) - np.asarray(expected)) / np.linalg.norm(expected)


def free_dofs_mask(model):
    mask = np.ones(model.n_owned_dofs, dtype=bool)
    mask[model.fixed_dofs] = False
    return mask


@pytest.mark.parametrize("xi", [None, LINEAR_DESIGN])
def test_rigid_motions_produce_no_elastic_force(xi):
    scene = coarse_scene(shapes=SHAPES)
    model = FullOrderModel(scene, load_fish(scene), xi)
    rest = model.rest_points[model.layout.owned_nodes]
    rotation = Rotation.from_rotvec([0.3, -0.5, 0.7]).as_matrix()
    translation = np.tile([0.01, -0.02, 0.03], rest.shape[0])
    rotated = (rest @ rotation.T - rest).ravel()
    bending = np.zeros_like(rest)
    bending[:, 1] = 0.01 * ((rest[:, 0] + 0.07) / 0.2) ** 2
    reference = np.linalg.norm(model.internal_force(bending.ravel()))
    assert np.linalg.norm(model.internal_force(translation)) < 1e-10 * reference
    assert np.linalg.norm(model.internal_force(rotated)) < 1e-10 * reference


@pytest.mark.parametrize("integrator, spine_force, spine_rule", [
    ("generalized-alpha", "source", "rear"), ("newmark", "source", "rear"), ("generalized-alpha", "lagrangian", "rear"),
    ("generalized-alpha", "source", "trapezoid"), ("generalized-alpha", "lagrangian", "trapezoid")])
def test_newton_matrix_is_the_derivative_of_the_step_residual(shaped_model, integrator, spine_force, spine_rule):
    """S du = d/dε r(t_{n+1-α_f}, u_{n+1-α_f}, u̇_{n+1-α_f}, ü_{n+1-α_m}) at u_{n+1} + ε du (thrust, drag,
    muscles all on), the intermediate state interpolated from an old state with the scheme's kinematics."""
    model = shaped_model
    if (spine_force, spine_rule) != ("source", "rear"):
        scene = coarse_scene(shapes=SHAPES, fluid={"spine_force": spine_force, "spine_rule": spine_rule})
        model = FullOrderModel(scene, load_fish(scene), DESIGN)
    scheme = TimeScheme.from_solver(coarse_scene(solver={"integrator": integrator}).solver)
    model.set_time_step(scheme)
    rng = np.random.default_rng(1)
    free = free_dofs_mask(model)
    old = [scale * rng.standard_normal(model.n_owned_dofs) * free for scale in (1e-3, 1e-2, 1e-1)]
    u_predicted, v_predicted = scheme.predict(*old)
    u = u_predicted + 1e-4 * rng.standard_normal(model.n_owned_dofs) * free
    time = 0.3

    def point(displacement):
        return scheme.evaluation_point(time, old, (displacement, *scheme.correct(displacement, u_predicted,
                                                                                  v_predicted)))

    for seed in range(3):
        direction = np.random.default_rng(10 + seed).standard_normal(model.n_owned_dofs) * free
        step = 1e-7
        finite_difference = (model.residual(*point(u + step * direction))[0]
                             - model.residual(*point(u - step * direction))[0]) / (2 * step)
        assert relative_error(model.newton_matrix.exact_product(*point(u), direction), finite_difference) < 1e-6


@pytest.mark.parametrize("stations", [40, "nodes"])
def test_the_stations_coupling_stays_out_of_the_matrix(stations):
    """With stations the assembled S lacks the slab coupling Bᵀ J B (its product differs from the exact
    derivative by more than the FD error) and holds the lumped added mass; the nodal model's is exact."""
    scene = coarse_scene(fluid={"stations": stations})
    model = FullOrderModel(scene, load_fish(scene))
    free = free_dofs_mask(model)
    rng = np.random.default_rng(3)
    u, v, a = (scale * rng.standard_normal(model.n_owned_dofs) * free for scale in (1e-3, 1e-1, 1.0))
    direction = rng.standard_normal(model.n_owned_dofs) * free
    exact = model.newton_matrix.exact_product(0.3, u, v, a, direction)
    assembled = model.matvec(model.newton_matrix.assemble(0.3, u, v, a), direction)
    if stations == "nodes":
        assert model.newton_matrix.correction(0.3, u, v, a) is None and np.array_equal(exact, assembled)
    else:
        assert relative_error(assembled, exact) > 1e-6


@pytest.mark.parametrize("stations, spine_rule", [(40, "rear"), (40, "trapezoid"), ("nodes", "rear")])
def test_the_symmetric_newton_matrix_is_factorised_by_ldlt(stations, spine_rule):
    """With stations S is symmetric at any state (K_t, M, C and the lumped added mass, for a shaped
    design and the muscles on; with either spine rule), so the model factorises its upper triangle with
    LDLᵀ and solves as LU does; the nodal model's S (thrust and drag Jacobians) is not symmetric and
    keeps LU."""
    from petsc4py import PETSc
    from aquarom_fenics.fem.linear_solver import mumps_solver

    scene = coarse_scene(fluid={"stations": stations, "spine_rule": spine_rule}, shapes=SHAPES)
    model = FullOrderModel(scene, load_fish(scene), DESIGN)
    free = free_dofs_mask(model)
    rng = np.random.default_rng(4)
    u, v, a = (scale * rng.standard_normal(model.n_owned_dofs) * free for scale in (1e-3, 1e-1, 1.0))
    matrix = model.newton_matrix.assemble(0.3, u, v, a)
    scalar_rows = matrix.convert("aij", PETSc.Mat())
    assert scalar_rows.isSymmetric(1e-10) == (stations != "nodes") == model.newton_matrix.is_symmetric
    rhs = rng.standard_normal(model.n_owned_dofs)
    model.factorize(0.3, u, v, a)
    lu = mumps_solver(model.comm)
    lu.setOperators(model.newton_matrix.assemble(0.3, u, v, a))
    assert model.newton_solver.ksp.getPC().getType() == ("cholesky" if stations != "nodes" else "lu")
    assert relative_error(model.solve(rhs), model.solve_with(lu, rhs)) < 1e-9
    lu.destroy()
    scalar_rows.destroy()
    model.destroy()



def test_the_nodal_model_is_the_sources_rear_rule_whatever_the_spine_rule():
    forces = []
    for rule in ("trapezoid", "rear"):
        scene = coarse_scene(fluid={"stations": "nodes", "spine_rule": rule})
        model = FullOrderModel(scene, load_fish(scene))
        state = [scale * np.random.default_rng(8).standard_normal(model.n_owned_dofs) for scale in (1e-3, 1e-1, 1.0)]
        forces.append(model.thrust_force(*state))
        assert not model.thrust.spine.trapezoid
    np.testing.assert_array_equal(*forces)


def test_a_new_time_step_frees_the_matrices_of_the_previous_one(shaped_model):
    """Step cuts and the tangent extraction change h many times per run: the Newton blocks of the old
    step are destroyed (petsc4py would keep them: tens of MB per change at degree 2, level 2)."""
    model = shaped_model
    model.newton_matrix.assemble(0.0, *(np.zeros(model.n_owned_dofs),) * 3)
    previous = (model.newton_matrix._inertia_damping, model.newton_matrix._on_newton_pattern["inertia_damping"])
    model.set_time_step(TimeScheme.from_solver(coarse_scene(solver={"time_step": 0.01}).solver))
    assert [matrix.handle for matrix in previous] == [0, 0]
    model.set_time_step(TimeScheme.from_solver(coarse_scene().solver))

def test_destroy_releases_every_petsc_object_of_the_model():
    """After a factorisation with the exact coupling (GMRES operator, LDLᵀ copy), a solve and the
    tangents, ``destroy`` leaves no live PETSc object on the model, its Newton system or its terms."""
    from petsc4py import PETSc

    scene = coarse_scene(solver={"newton_coupling": "krylov"}, shapes=SHAPES)
    model = FullOrderModel(scene, load_fish(scene), DESIGN)
    zero = np.zeros(model.n_owned_dofs)
    model.factorize(0.0, zero, zero, zero)
    model.solve(np.ones(model.n_owned_dofs))
    list(model.tangents(0.0, zero, zero, zero))
    owners = [model, model.newton_matrix, model.newton_solver, model.elastic, model.muscle, model.inertia,
              model.drag, model.thrust]

    def petsc_objects():
        for owner in owners:
            for value in vars(owner).values():
                for item in value.values() if isinstance(value, dict) else (value,):
                    if isinstance(item, PETSc.Object):
                        yield item

    kept = list(petsc_objects())
    assert len(kept) >= 12 and any(isinstance(item, PETSc.KSP) for item in kept)
    model.destroy()
    assert [type(item).__name__ for item in kept if item.handle != 0] == []


@pytest.mark.parametrize("degree", [1, 2])
def test_design_pulled_back_equals_design_meshed_directly(degree):
    scene = coarse_scene(shapes=SHAPES, solver={"duration": 0.2}, mesh={"degree": degree})
    fish = load_fish(scene)
    pulled_back = simulate_fom(scene, LINEAR_DESIGN, fish=fish, progress=False).trajectory.arrays()
    moved = simulate_fom(scene, LINEAR_DESIGN, fish=fish, moved_mesh=True, progress=False).trajectory.arrays()
    for name in ("head_x", "tail_y", "com_x"):
        assert relative_error(moved[name], pulled_back[name]) < 1e-8, name


def smooth_lateral_velocity(fish, speed):
    """v_y = speed ((x + 0.35 L) / (0.65 L))² behind the head, zero on it [m/s]."""
    relative, length = fish.tags.box.relative(fish.mesh.points), fish.tags.box.length
    velocity = np.zeros_like(relative)
    velocity[:, 1] = speed * np.clip(-(relative[:, 0] + 0.35 * length) / (0.65 * length), 0.0, None) ** 2
    return velocity


def test_energy_is_conserved_without_damping_and_forces():
    """Trapezoidal Newmark (α_N = 0) conserves ½ u̇ᵀMu̇ + Π(u) in the linear regime."""
    scene = coarse_scene(actuation={"amplitude": 0.0}, fluid={"thrust": False, "drag": False},
                         material={"rayleigh_alpha": 0.0, "rayleigh_beta": 0.0},
                         solver={"integrator": "newmark", "newmark_alpha": 0.0, "tolerance": 1e-7})
    fish = load_fish(scene)
    result = simulate_fom(scene, fish=fish, progress=False, keep_states=True,
                          initial_velocity=smooth_lateral_velocity(fish, 1e-4))
    assert result.completed and len(result.states) == 101
    energy = np.array([result.model.kinetic_energy(v) + result.model.elastic_energy(u) for u, v, _ in result.states])
    assert np.abs(energy - energy[0]).max() < 1e-6 * energy[0]


def test_reference_fish_swims_forward_with_a_plausible_tail_beat():
    scene = coarse_scene()
    result = simulate_fom(scene, progress=False)
    assert result.completed
    assert result.distance > 0
    assert 0.005 < result.tail_amplitude < 0.04


def test_left_and_right_muscles_bend_the_tail_to_opposite_sides():
    scene = coarse_scene()
    model = FullOrderModel(scene, load_fish(scene))
    left_tail = model.spine_values(model.static_response(0.2, 0.0))[0]
    right_tail = model.spine_values(model.static_response(0.0, 0.2))[0]
    assert left_tail[1] > 1e-3 and right_tail[1] < -1e-3
    assert abs(left_tail[1] + right_tail[1]) < 1e-8 * abs(left_tail[1])
    assert abs(left_tail[0] - right_tail[0]) < 1e-8 * abs(left_tail[0])


@pytest.mark.parametrize("scheme", [{}, {"integrator": "newmark", "newmark_alpha": 0.0}])
def test_halving_the_time_step_converges_at_second_order(scheme):
    """Successive differences of head x for h = 0.02, 0.01, 0.005, 0.0025 shrink about 4×: the default
    generalized-α and Newmark with α_N = 0 (γ = ½).

    With α_N > 0 (SPEC 0.005, Newmark's default 0.02; γ = ½ + α_N) Newmark keeps an O(α_N h) first-order
    term, so its ratios fall towards 2 as h → 0.
    """
    head_x = {}
    for time_step in (0.02, 0.01, 0.005, 0.0025):
        scene = coarse_scene(solver={"duration": 1.0, "time_step": time_step, "tolerance": 1e-9, **scheme})
        samples = simulate_fom(scene, progress=False).trajectory.arrays()["head_x"]
        head_x[time_step] = samples[:: int(round(0.02 / time_step))]
    steps = sorted(head_x, reverse=True)
    differences = [np.abs(head_x[coarse] - head_x[fine]).max() for coarse, fine in zip(steps, steps[1:])]
    ratios = [differences[0] / differences[1], differences[1] / differences[2]]
    assert all(3.0 < ratio < 5.0 for ratio in ratios), ratios


def test_steps_that_fail_are_cut_and_counted_in_the_summary(tmp_path):
    """k = 6e5 Pa (10× the reference), the nodal thrust: whole steps stall from t ≈ 0.36 s (the tail node's
    indentation); cut steps carry the run to 0.5 s. (Through the stations the same run needs no cut.)"""
    strong = coarse_scene(actuation={"stiffness": 6e5}, solver={"duration": 0.5}, output={"plots": False},
                          fluid={"stations": "nodes"})
    result = simulate_fom(strong, out_dir=tmp_path, progress=False)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert result.completed and summary["completed"]
    assert summary["cut_steps"] == result.cut_steps > 0
    assert len(result.trajectory) == 26        # the samples stay on the grid of h
    uncut = simulate_fom(strong.replace("solver", min_time_step=strong.solver.time_step), progress=False)
    assert not uncut.completed and uncut.cut_steps == 0


def test_tangents_combine_to_the_newton_matrix(shaped_model):
    """k_u K_t + k_v C_t + k_a M_t = S on the free rows at a moving state, and S is intact after the tangents."""
    model = shaped_model
    rng = np.random.default_rng(1)
    u, v, a = (scale * rng.normal(size=model.n_owned_dofs) for scale in (1e-4, 1e-3, 1e-2))
    u[model.fixed_dofs] = v[model.fixed_dofs] = a[model.fixed_dofs] = 0.0
    direction = rng.normal(size=model.n_owned_dofs)
    direction[model.fixed_dofs] = 0.0
    newton_product = model.matvec(model.newton_matrix.assemble(0.3, u, v, a), direction)
    scheme = model.scheme
    factors = (scheme.stiffness_factor, scheme.velocity_factor, scheme.acceleration_factor)
    combined = sum(factor * model.matvec(matrix, direction)
                   for factor, matrix in zip(factors, model.tangents(0.3, u, v, a)))
    free = free_dofs_mask(model)
    assert relative_error(combined[free], newton_product[free]) < 1e-12
    assert relative_error(model.matvec(model.newton_matrix.assemble(0.3, u, v, a), direction), newton_product) < 1e-14


def test_a_smooth_start_converges_from_its_first_tiny_step():
    """With a(t) ~ t³ the first step's strains are about 1e-11: written as ½(F_2ᵀF_2 - I) the strain
    lost all but 1e-5 of its digits there and Newton stalled at t = 0.0025 s; ½(H + Hᵀ + HᵀH) keeps them."""
    scene = coarse_scene(actuation={"start_ramp": 0.5}, solver={"duration": 0.1, "time_step": 0.0025})
    result = simulate_fom(scene, progress=False)
    assert result.completed and result.cut_steps == 0, result.error
