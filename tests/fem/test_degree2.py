"""Quadratic tetrahedra (SPEC §3) and the exact design geometry (SPEC §4), coarsest mesh."""
import re

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.io.scene import scene_from_dict
from conftest import coarse_scene


def peak_muscle_tail_deflection(level: int, degree: int) -> float:
    """Tail y of the static, head-clamped fish with the muscles at their peak (k = 6e4, a = ±0.2) [m]."""
    scene = scene_from_dict({"mesh": {"level": level, "degree": degree}}, source="<test>")
    model = FullOrderModel(scene, load_fish(scene))
    return float(model.spine_values(model.static_response(0.2, -0.2))[0, 1])


@pytest.mark.parametrize("degree", [0, 3])
def test_other_degrees_are_refused_naming_the_valid_values(degree):
    with pytest.raises(InputError, match=r"degree.*must be one of 1, 2"):
        coarse_scene(mesh={"degree": degree})


def test_quadratic_nodes_are_vertices_then_edge_midpoints_and_the_spine_halves():
    linear, quadratic = (load_fish(coarse_scene(mesh={"degree": d})) for d in (1, 2))
    nodes = quadratic.nodes
    assert nodes.n_vertices == linear.mesh.points.shape[0]
    np.testing.assert_array_equal(nodes.points[:nodes.n_vertices], linear.mesh.points)
    midpoints = 0.5 * (nodes.points[nodes.edges[:, 0]] + nodes.points[nodes.edges[:, 1]])
    np.testing.assert_array_equal(nodes.points[nodes.n_vertices:], midpoints)
    assert quadratic.tags.spine_nodes.size == 2 * linear.tags.spine_nodes.size - 1
    spine_x = nodes.points[quadratic.tags.spine_nodes, 0]
    assert np.all(np.diff(spine_x) > 0)
    np.testing.assert_allclose(spine_x[::2], linear.mesh.points[linear.tags.spine_nodes, 0])
    assert quadratic.tags.dorsal_nodes.size == quadratic.tags.spine_nodes.size - 1
    assert quadratic.shape_matrix.shape[0] == 3 * nodes.points.shape[0]


def test_degree_two_on_the_coarsest_mesh_is_closer_than_degree_one_to_a_finer_reference():
    """Bending locks linear tetrahedra: on level 1, P2 is nearer the level-2 P2 deflection than P1."""
    reference = peak_muscle_tail_deflection(2, 2)
    linear, quadratic = peak_muscle_tail_deflection(1, 1), peak_muscle_tail_deflection(1, 2)
    assert abs(quadratic - reference) < 0.25 * abs(linear - reference)
    assert abs(linear) < abs(quadratic)          # the linear mesh is too stiff


def test_degree_two_dof_layout_matches_the_nodes():
    """Every dof block sits at the coordinates of the node it is mapped to."""
    scene = coarse_scene(mesh={"degree": 2})
    fish = load_fish(scene)
    model = FullOrderModel(scene, fish)
    coordinates = model.space.tabulate_dof_coordinates()[:model.layout.n_owned_blocks]
    np.testing.assert_allclose(coordinates, fish.nodes.points[model.layout.owned_nodes], atol=1e-12)


@pytest.fixture(scope="module")
def quadratic_so1():
    from prom_checks import SO1_SHAPES

    from aquarom_fenics.reduction.reductor import build_prom

    scene = coarse_scene(mesh={"degree": 2}, shapes=SO1_SHAPES)
    fish = load_fish(scene)
    return scene, fish, build_prom(scene, fish=fish)


def test_degree_two_prom_reproduces_the_projected_fom_forces(quadratic_so1):
    """The strains sampled at the quadrature points of the FOM's forms give Vᵀ r exactly (SPEC §8)."""
    from prom_checks import assert_prom_reproduces_the_projected_fom_forces

    assert_prom_reproduces_the_projected_fom_forces(*quadratic_so1, samples=5)


def test_degree_two_first_xi_derivative_matches_central_difference_of_the_fom(quadratic_so1):
    from prom_checks import assert_first_xi_derivative_matches_the_fom

    assert_first_xi_derivative_matches_the_fom(*quadratic_so1)


SO2_CORNER_DESIGN = {"z_tail": -0.49, "z_head": 0.32, "y_lin_long_tail": 0.39, "y_head": 0.49, "y_ellipse": 0.49}
"""Refused on level 3 by a check of the linearly interpolated design (head corner cells invert),
although the exact map has det F_1 = (1 + ∂Δy/∂y)(1 + ∂Δz/∂z) > 0 for |ξ| < 1."""


def test_design_check_judges_the_exact_geometry_not_its_nodal_interpolation():
    from aquarom_fenics.io.scene import Scene
    from aquarom_fenics.geometry.design_check import check_design

    fish = load_fish(Scene.load("so2").replace("mesh", level=3, degree=1))
    xi = fish.parameter_vector(SO2_CORNER_DESIGN)
    interpolated = fish.mesh.points + fish.shape_displacement(xi)[:fish.nodes.n_vertices]
    with pytest.raises(InputError, match="inverts or flattens [1-9]"):
        check_design(fish.mesh.points, fish.mesh.cells, interpolated, SO2_CORNER_DESIGN)
    design = fish.design(SO2_CORNER_DESIGN)
    np.testing.assert_allclose(design, fish.nodes.points + fish.shape_displacement(xi))


@pytest.mark.parametrize("degree", [1, 2])
def test_a_design_that_inverts_in_the_continuum_is_refused(degree):
    fish = load_fish(coarse_scene(mesh={"degree": degree}, shapes={"z_head": {"bounds": [-4.0, 4.0]}}))
    fish.design({"z_head": 0.9})
    # det F_1 = 1 + ∂Δz/∂z = 1 + ξ (√(1 - s²) - 1) < 0 for s > 0.745 at ξ = 3 (x > -0.015 m).
    with pytest.raises(InputError, match=r"z_head=3 inverts or flattens [1-9]\d* .*reduce the parameters"):
        fish.design({"z_head": 3.0})


def test_so1_bounds_are_no_longer_pulled_in_on_the_reference_level():
    """With the nodal check, z_head's upper bound 0.5 was pulled in to 0.41 on level 3 (an artifact)."""
    from aquarom_fenics.optimization.cost import design_space, meshable_space
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load("so1")
    space, notes = meshable_space(design_space(scene), load_fish(scene))
    assert notes == []
    np.testing.assert_array_equal(space.upper, design_space(scene).upper)


def test_the_design_check_samples_the_points_where_the_fom_integrates():
    from aquarom_fenics.fem import dolfinx_adapter as fx

    scene = coarse_scene(mesh={"degree": 2})
    fish = load_fish(scene)
    model = FullOrderModel(scene, fish)
    fom_points = np.concatenate([model.quadrature_points[family] for family in ("stiffness", "mass")], axis=1)
    check_points = fish.integration_points()[fx.input_cell_indices(model.mesh)]
    assert fom_points.shape == check_points.shape

    def sorted_per_cell(points):        # rounded to 1e-12 m before the lexicographic order
        return np.stack([cell[np.lexsort(np.round(cell, 12).T)] for cell in points])

    np.testing.assert_allclose(sorted_per_cell(fom_points), sorted_per_cell(check_points), atol=1e-12)


SO2_PAPER_OPTIMUM = {"z_tail": -0.49, "z_head": 0.32, "y_lin_long_tail": 0.39, "y_head": 0.49, "y_ellipse": 0.49}
"""The SO2 optimum of the method's source: strongly squeezed at the head's corners, inverted nowhere."""


def test_the_paper_so2_optimum_is_valid_with_a_warning_naming_the_squeezed_head_cells(caplog):
    from aquarom_fenics.io.scene import Scene

    fish = load_fish(Scene.load("so2").replace("mesh", level=2))
    with caplog.at_level("WARNING", logger="aquarom"):
        fish.design(SO2_PAPER_OPTIMUM)
    warnings = [record.getMessage() for record in caplog.records if record.levelname == "WARNING"]
    squeezed = re.search(r"shrinks (\d+) of (\d+) cells below 0\.1 of their nominal volume", warnings[0])
    assert len(warnings) == 1 and squeezed and "(head)" in warnings[0]
    # 16 head cells on the conforming level-2 mesh (12 on the earlier centroid-region mesh)
    assert 0 < int(squeezed.group(1)) < 0.01 * len(fish.mesh.cells) and int(squeezed.group(2)) == len(fish.mesh.cells)
