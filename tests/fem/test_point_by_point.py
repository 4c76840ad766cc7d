"""An expression of quadrature fields evaluated point by point (fem/dolfinx_adapter.py): the values at the
rule's points, bit for bit."""
import numpy as np
import pytest
import ufl
from dolfinx.mesh import create_unit_cube
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.inertia import mass_density


def test_point_by_point_values_are_the_rules_bit_for_bit():
    """ρ |det J| det(I + G) and its derivative along D (G, D random tensors at the points of the degree-6
    rule): the same numbers from the rule's evaluation and from the one-point fields set point by point."""
    mesh = create_unit_cube(MPI.COMM_WORLD, 2, 2, 3)
    degree, cells = 6, fx.owned_cells(mesh)
    n_points = fx.quadrature_rule(degree)[1].size
    rng = np.random.default_rng(7)
    values = [0.2 * rng.standard_normal((fx.local_cells(mesh).size, n_points, 3, 3)) for _ in range(2)]
    density = fx.constant(mesh, 1000.0)

    def expression(gradient, direction):
        weighted = abs(ufl.JacobianDeterminant(mesh)) * mass_density(gradient, density)
        return ufl.as_vector([weighted, ufl.derivative(weighted, gradient, direction)])

    at_rule = [fx.new_function(fx.quadrature_tensor_space(mesh, degree), name) for name in ("G", "D")]
    for field, array in zip(at_rule, values):
        fx.set_quadrature_values(field, array)
    expected = fx.evaluate_expression(fx.compile_quadrature_expression(expression(*at_rule), degree), cells)
    at_a_point = [fx.new_function(fx.point_tensor_space(mesh), name) for name in ("g", "d")]
    by_point = fx.evaluate_point_by_point(fx.compile_point_expression(expression(*at_a_point), at_a_point),
                                          at_a_point, values, cells)
    assert by_point.shape == (cells.size, n_points, 2)
    assert np.array_equal(by_point, expected.reshape(cells.size, n_points, 2))
    assert np.abs(by_point[..., 1]).max() > 0
    assert np.array_equal(fx.quadrature_values(at_rule[0]), values[0])


def test_an_expression_of_other_fields_or_of_x_is_refused():
    """A field that varies in the cell (or x) would be taken at the one point: refused before compiling."""
    mesh = create_unit_cube(MPI.COMM_WORLD, 1, 1, 1)
    point_field = fx.new_function(fx.point_tensor_space(mesh), "g")
    displacement = fx.new_function(fx.vector_space(mesh, 2), "u")
    with pytest.raises(ValueError, match="u"):
        fx.compile_point_expression(ufl.det(point_field) + ufl.div(displacement), [point_field])
    with pytest.raises(ValueError, match="position"):
        fx.compile_point_expression(ufl.det(point_field) * ufl.SpatialCoordinate(mesh)[0], [point_field])
