"""The two material laws of forms/elasticity.py: Taylor tests of the Neo-Hookean force and tangent
against its energy, and its agreement with SVK to first order in the strain (same λ, μ)."""
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.elasticity import (ENERGY_DENSITIES, neo_hookean_energy_density, small_strain_energy_density,
                                             strain_energy, svk_energy_density)

POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
CELLS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
SHAPE_GRADIENT = np.array([[0.1, 0.02, 0.0], [0.0, -0.05, 0.03], [0.01, 0.0, 0.08]])
YOUNG, POISSON = 2.6e5, 0.4


@pytest.fixture(scope="module")
def neo_hookean():
    """(u, energy, force, tangent) of the Neo-Hookean law on two cells with a constant ∇u_ξ."""
    mesh = fx.create_tet_mesh(MPI.COMM_WORLD, POINTS, CELLS)
    space = fx.vector_space(mesh, 1)
    u = fx.new_function(space, "u")
    shape_gradient = fx.tensor_constant(mesh, (3, 3))
    shape_gradient.value = SHAPE_GRADIENT
    energy = strain_energy(u, shape_gradient, fx.constant(mesh, YOUNG), fx.constant(mesh, POISSON), "neo-hookean")
    force = ufl.derivative(energy, u, ufl.TestFunction(space))
    tangent = ufl.derivative(force, u, ufl.TrialFunction(space))
    return u, fx.compile_form(energy), fx.compile_form(force), fx.compile_form(tangent)


def evaluate(model, values):
    u, energy, force, tangent = model
    fx.set_owned_values(u, values)
    vector = fx.assemble_vector_into(fx.create_vector(force), force).copy()
    matrix = fx.assemble_matrix_into(fx.create_matrix(tangent), tangent)
    dense = matrix.convert("dense").getDenseArray().copy()
    return fx.assemble_scalar(energy, MPI.COMM_WORLD), vector, dense


def test_neo_hookean_force_and_tangent_pass_taylor_tests(neo_hookean):
    rng = np.random.default_rng(3)
    u0, direction = 0.05 * rng.standard_normal(15), 0.05 * rng.standard_normal(15)
    energy, force, tangent = evaluate(neo_hookean, u0)
    energy_remainders, force_remainders = [], []
    for step in (1e-2, 5e-3, 2.5e-3):
        energy_h, force_h, _ = evaluate(neo_hookean, u0 + step * direction)
        energy_remainders.append(abs(energy_h - energy - step * force @ direction))
        force_remainders.append(np.linalg.norm(force_h - force - step * tangent @ direction))
    for remainders in (energy_remainders, force_remainders):
        rates = np.log2(np.array(remainders[:-1]) / np.array(remainders[1:]))
        assert rates == pytest.approx([2.0, 2.0], abs=0.1), remainders


def densities(strain):
    """(ψ_NH, ψ_SVK, ψ₂ of Neo-Hookean) of a constant strain tensor [J/m³] on one cell."""
    mesh = fx.create_tet_mesh(MPI.COMM_WORLD, POINTS[:4], CELLS[:1])
    tensor = fx.tensor_constant(mesh, (3, 3))
    tensor.value = strain
    dx = ufl.dx(domain=mesh)
    young, poisson = fx.constant(mesh, YOUNG), fx.constant(mesh, POISSON)
    return [6.0 * fx.assemble_scalar(fx.compile_form(density * dx), MPI.COMM_WORLD) for density in
            (neo_hookean_energy_density(tensor, young, poisson), svk_energy_density(tensor, young, poisson),
             small_strain_energy_density("neo-hookean", tensor, young, poisson))]


def test_neo_hookean_matches_svk_to_first_order_in_the_strain():
    """ψ_NH(εE) - ψ_SVK(εE) = O(ε³) while ψ = O(ε²): the stresses agree to first order."""
    direction = np.array([[0.3, 0.1, -0.2], [0.1, -0.4, 0.05], [-0.2, 0.05, 0.5]])
    differences = []
    for scale in (0.04, 0.02, 0.01):
        neo_hookean, svk, expansion = densities(scale * direction)
        assert expansion == pytest.approx(svk, rel=1e-12)
        differences.append(abs(neo_hookean - svk))
        assert differences[-1] < 0.1 * svk
    rates = np.log2(np.array(differences[:-1]) / np.array(differences[1:]))
    assert rates == pytest.approx([3.0, 3.0], abs=0.15), differences


def test_both_laws_are_zero_at_rest_and_the_law_is_checked():
    assert densities(np.zeros((3, 3)))[:2] == [pytest.approx(0.0, abs=1e-9)] * 2
    assert set(ENERGY_DENSITIES) == {"svk", "neo-hookean"}
    with pytest.raises(ValueError, match="material law"):
        small_strain_energy_density("mooney", None, YOUNG, POISSON)
