"""A FOM moved to another design (``FullOrderModel.move_to``) is the FOM made at that design."""
import numpy as np

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from conftest import coarse_scene
from prom_checks import SO1_SHAPES


def test_a_moved_model_has_the_residual_and_matrices_of_a_new_one():
    scene = coarse_scene(shapes=SO1_SHAPES)
    fish = load_fish(scene)
    target = np.array([-0.3, 0.2, 0.1])
    moved = FullOrderModel(scene, fish, np.zeros(3))
    before = moved.drag.direction.copy()
    moved.move_to(target)
    fresh = FullOrderModel(scene, fish, target)
    assert not np.allclose(before, fresh.drag.direction)
    np.testing.assert_array_equal(moved.drag.direction, fresh.drag.direction)
    np.testing.assert_array_equal(moved.rest_points, fresh.rest_points)
    assert moved.inertia.total_mass == fresh.inertia.total_mass
    np.testing.assert_array_equal(moved.inertia.mass_moment_x, fresh.inertia.mass_moment_x)
    random = np.random.default_rng(3)
    u, v, a = (1e-3 * random.standard_normal(fresh.n_owned_dofs) for _ in range(3))
    for model in (moved, fresh):
        model.factorize(0.1, u, v, a)
    residual, scale = moved.residual(0.1, u, v, a)
    expected, expected_scale = fresh.residual(0.1, u, v, a)
    np.testing.assert_array_equal(residual, expected)
    assert scale == expected_scale
    np.testing.assert_array_equal(moved.solve(residual), fresh.solve(residual))
    for matrix in ("mass_matrix", "damping_matrix", "rest_stiffness"):
        values = [getattr(model, matrix).getValuesCSR()[2] for model in (moved, fresh)]
        np.testing.assert_array_equal(*values, err_msg=matrix)
    assert moved.observables(u) == fresh.observables(u)
    for family, points in fresh.quadrature_points.items():   # ∇u_ξ from the kept ∇U_k: the fish's own, exactly
        expected = fish.shape_gradient(target, points.reshape(-1, 3)).reshape(points.shape[:2] + (3, 3))
        for model in (moved, fresh):
            np.testing.assert_array_equal(fx.quadrature_values(model.shape_gradients[family]), expected, err_msg=family)


def test_the_mass_moments_follow_a_move():
    """The moments and the total mass, assembled at first use, are the new design's after a move."""
    scene = coarse_scene(shapes=SO1_SHAPES)
    fish = load_fish(scene)
    moved = FullOrderModel(scene, fish, np.zeros(3))
    nominal = (moved.inertia.total_mass, moved.inertia.mass_moment_x.copy(), moved.inertia.mass_moment_y.copy())
    moved.move_to(np.array([0.0, 0.0, 0.15]))        # y_thin: a thinner body, less mass
    fresh = FullOrderModel(scene, fish, np.array([0.0, 0.0, 0.15]))
    assert moved.inertia.total_mass == fresh.inertia.total_mass < 0.9 * nominal[0]
    for name, before in zip(("mass_moment_x", "mass_moment_y"), nominal[1:]):
        after = getattr(moved.inertia, name)
        np.testing.assert_array_equal(after, getattr(fresh.inertia, name))
        assert not np.array_equal(after, before), name
