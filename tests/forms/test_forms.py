"""The UFL forms of forms/ on one tetrahedron, against closed forms of homogeneous fields (SPEC §5).

The cell is the unit corner tetrahedron (volume 1/6); the design's shape gradient ∇u_ξ is a constant
tensor (F_1 = I + ∇u_ξ), the displacement the linear field u = G x, so that every integrand is constant.
"""
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.drag import drag_direction_form
from aquarom_fenics.forms.elasticity import lame_parameters, strain_energy
from aquarom_fenics.forms.inertia import mass_form, mass_moment_x, total_mass
from aquarom_fenics.forms.kinematics import green_lagrange_strain, relative_gradient, volume_ratio
from aquarom_fenics.forms.muscle import muscle_energy

CORNER = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
VOLUME = 1.0 / 6.0
SHAPE_GRADIENT = np.array([[0.1, 0.02, 0.0], [0.0, -0.05, 0.03], [0.01, 0.0, 0.08]])      # ∇u_ξ
DISPLACEMENT_GRADIENT = np.array([[0.03, -0.01, 0.02], [0.04, 0.01, 0.0], [0.0, 0.02, -0.03]])  # ∇u = G
YOUNG, POISSON, DENSITY = 2.6e5, 0.45, 1080.0


@pytest.fixture(scope="module")
def cell():
    """(mesh, space, u = G x, the constant ∇u_ξ)."""
    mesh = fx.create_tet_mesh(MPI.COMM_WORLD, CORNER, np.array([[0, 1, 2, 3]]))
    space = fx.vector_space(mesh, 1)
    displacement = fx.new_function(space, "u")
    displacement.interpolate(lambda x: DISPLACEMENT_GRADIENT @ x)
    shape_gradient = fx.tensor_constant(mesh, (3, 3))
    shape_gradient.value = SHAPE_GRADIENT
    return mesh, space, displacement, shape_gradient


def integral(form) -> float:
    return fx.assemble_scalar(fx.compile_form(form), MPI.COMM_WORLD)


def strain_closed_form(shape_gradient=SHAPE_GRADIENT, displacement_gradient=DISPLACEMENT_GRADIENT):
    """E = ½ (F_2ᵀ F_2 - I), F_2 = (I + ∇u_ξ + ∇u)(I + ∇u_ξ)⁻¹, and det F_1."""
    shape = np.eye(3) + shape_gradient
    relative = (shape + displacement_gradient) @ np.linalg.inv(shape)
    return 0.5 * (relative.T @ relative - np.eye(3)), relative, np.linalg.det(shape)


def test_kinematics_of_a_homogeneous_deformation(cell):
    mesh, _, u, shape_gradient = cell
    strain, relative, det_shape = strain_closed_form()
    dx = ufl.dx(domain=mesh)
    assert integral(volume_ratio(shape_gradient) * dx) == pytest.approx(det_shape * VOLUME, rel=1e-12)
    for i, j in ((0, 0), (0, 1), (2, 1)):
        assert integral(green_lagrange_strain(u, shape_gradient)[i, j] * dx) == pytest.approx(
            strain[i, j] * VOLUME, rel=1e-10)
        assert integral(relative_gradient(u, shape_gradient)[i, j] * dx) == pytest.approx(
            relative[i, j] * VOLUME, rel=1e-10)


def test_strain_energy_of_a_homogeneous_deformation(cell):
    mesh, _, u, shape_gradient = cell
    strain, _, det_shape = strain_closed_form()
    lam = YOUNG * POISSON / ((1 + POISSON) * (1 - 2 * POISSON))
    mu = YOUNG / (2 * (1 + POISSON))
    assert lame_parameters(YOUNG, POISSON) == pytest.approx((lam, mu), rel=1e-14)
    expected = (0.5 * lam * np.trace(strain) ** 2 + mu * np.sum(strain * strain)) * det_shape * VOLUME
    energy = strain_energy(u, shape_gradient, fx.constant(mesh, YOUNG), fx.constant(mesh, POISSON))
    assert integral(energy) == pytest.approx(expected, rel=1e-10)


def test_strain_energy_vanishes_for_a_rigid_rotation_of_the_shape_varied_body(cell):
    mesh, space, _, shape_gradient = cell
    angle = 0.4
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0, 0, 1]])
    rotated = fx.new_function(space, "rotated")
    # u = (R - I) F_1 X: x_deformed = R x_ξ
    rotated.interpolate(lambda x: (rotation - np.eye(3)) @ (np.eye(3) + SHAPE_GRADIENT) @ x)
    energy = strain_energy(rotated, shape_gradient, fx.constant(mesh, YOUNG), fx.constant(mesh, POISSON))
    assert abs(integral(energy)) < 1e-20 * YOUNG


def test_mass_forms_integrate_the_density_over_the_shape_varied_volume(cell):
    mesh, space, _, shape_gradient = cell
    density = fx.constant(mesh, DENSITY)
    det_shape = strain_closed_form()[2]
    expected = DENSITY * det_shape * VOLUME
    assert integral(total_mass(shape_gradient, density, mesh)) == pytest.approx(expected, rel=1e-12)
    moment = fx.compile_form(mass_moment_x(ufl.TestFunction(space), shape_gradient, density))
    weights = fx.assemble_vector_into(fx.create_vector(moment), moment).reshape(-1, 3)
    assert weights[:, 0].sum() == pytest.approx(expected, rel=1e-12)
    np.testing.assert_array_equal(weights[:, 1:], 0.0)
    mass = fx.compile_form(mass_form(ufl.TrialFunction(space), ufl.TestFunction(space), shape_gradient, density))
    matrix = fx.assemble_matrix_into(fx.create_matrix(mass), mass)
    translation = np.tile([1.0, 0.0, 0.0], 4)
    vector = matrix.createVecRight()
    vector.array[:] = translation
    product = matrix.createVecLeft()
    matrix.mult(vector, product)
    assert translation @ product.array == pytest.approx(expected, rel=1e-12)


def muscle_energy_of(cell, activation, nominal_volume=False, displacement=None):
    mesh, space, u, shape_gradient = cell
    activations = [fx.constant(mesh, activation), fx.constant(mesh, 0.5)]
    muscles = fx.cell_measure(mesh, {1: np.array([0]), 2: np.array([], dtype=np.int64)})   # the cell is muscle 1
    energy = muscle_energy(displacement if displacement is not None else u, shape_gradient,
                           fx.constant(mesh, 6e4), activations, [muscles(1), muscles(2)], nominal_volume)
    return integral(energy)


def test_muscle_energy_closed_form_zero_at_zero_activation_and_contracting(cell):
    _, relative, det_shape = strain_closed_form()
    stretch = relative @ np.array([1.0, 0.0, 0.0])
    assert muscle_energy_of(cell, 0.0) == 0.0
    assert muscle_energy_of(cell, 0.2) == pytest.approx(0.5 * 6e4 * 0.2 * stretch @ stretch * det_shape * VOLUME,
                                                        rel=1e-10)
    total = (np.eye(3) + SHAPE_GRADIENT + DISPLACEMENT_GRADIENT) @ np.array([1.0, 0.0, 0.0])
    assert muscle_energy_of(cell, 0.2, nominal_volume=True) == pytest.approx(
        0.5 * 6e4 * 0.2 * total @ total * VOLUME, rel=1e-10)
    # a > 0 contracts the fibres: the energy falls when the body shortens along x, rises when it stretches
    _, space, _, _ = cell
    energies = []
    for strain_x in (-0.01, 0.0, 0.01):
        stretched = fx.new_function(space, "stretched")
        stretched.interpolate(lambda x, s=strain_x: np.vstack([s * x[0], 0 * x[1], 0 * x[2]]))
        energies.append(muscle_energy_of(cell, 0.2, displacement=stretched))
    assert energies[0] < energies[1] < energies[2]


def test_drag_direction_of_one_cell_against_nanson_per_facet(cell):
    mesh, space, _, shape_gradient = cell
    drag = fx.compile_form(drag_direction_form(ufl.TestFunction(space), shape_gradient,
                                               fx.constant(mesh, 1000.0), mesh))
    direction = fx.assemble_vector_into(fx.create_vector(drag), drag).reshape(-1, 3)
    shape = np.eye(3) + SHAPE_GRADIENT
    expected = 0.0
    for face in ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2)):
        a, b, c = CORNER[list(face)]
        area_normal = 0.5 * np.cross(b - a, c - a)                       # N dA_0 (orientation irrelevant)
        nanson = np.linalg.det(shape) * np.linalg.inv(shape).T @ area_normal   # n_ξ dA_ξ
        expected += -1000.0 * nanson[0] ** 2 / np.linalg.norm(nanson)   # -ρ_w ½ C_d A_ξ, C_d = 2 (n_ξ·e_x)²
    assert direction[:, 0].sum() == pytest.approx(expected, rel=1e-12)
    np.testing.assert_array_equal(direction[:, 1:], 0.0)
    assert np.all(direction[:, 0] <= 0.0)
