"""Shape variations (SPEC §4) on a small structured tetrahedral block."""

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.design_check import check_design, determinant_3x3
from aquarom_fenics.geometry.shapes import CATALOG, design_points, shape_displacement, shape_matrix, shape_names

L, W, H = 0.20, 0.04, 0.10


@dataclass(frozen=True)
class Box:
    length: float = L
    width: float = W
    height: float = H


BOX = Box()


def block_mesh(nx=20, ny=4, nz=4):
    """x ∈ [-L, 0], y ∈ [-W/2, W/2], z ∈ [-H/2, H/2]; hexahedra split into 6 positive tets each.

    Even ny, nz put nodes on the axis y = z = 0; nx = 20 puts nodes on every region bound of
    SPEC §4 (multiples of 0.05 L).
    """
    xs, ys, zs = np.linspace(-L, 0, nx + 1), np.linspace(-W / 2, W / 2, ny + 1), np.linspace(-H / 2, H / 2, nz + 1)
    points = np.array([(x, y, z) for x in xs for y in ys for z in zs])

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    cells = []
    for i, j, k in itertools.product(range(nx), range(ny), range(nz)):
        for axes in itertools.permutations(range(3)):
            corner = [i, j, k]
            path = [node(*corner)]
            for axis in axes:
                corner[axis] += 1
                path.append(node(*corner))
            cells.append(path)
    cells = np.array(cells)
    corners = points[cells]
    negative = np.linalg.det(corners[:, 1:] - corners[:, :1]) < 0
    cells[negative] = cells[negative][:, [0, 2, 1, 3]]
    return points, cells


@pytest.fixture(scope="module")
def mesh():
    return block_mesh()


def random_points(count=400, seed=0):
    """Points in the box, plus points on every region bound."""
    rng = np.random.default_rng(seed)
    inner = rng.uniform([-L, -W / 2, -H / 2], [0, W / 2, H / 2], size=(count, 3))
    bounds = np.array([-0.9, -0.8, -0.7, -0.55, -0.45, -0.3]) * L
    on_bounds = np.column_stack([bounds, np.full(6, W / 4), np.full(6, -H / 3)])
    return np.vstack([inner, on_bounds])


# The formulas of SPEC §4, one point at a time: (region(x), displacement(x, y, z)).

def rounded(s):
    return math.sqrt(max(0.0, 1 - s * s)) - 1


def notch(x):
    if x >= -0.7 * L:
        return (-0.3 * L - x) / (0.4 * L)
    return (x + 0.9 * L) / (0.2 * L)


def hat(x):
    return 1 - abs(x + 0.8 * L) / (0.1 * L)


def step(x):
    return 1.0 if x <= -0.55 * L else (-0.45 * L - x) / (0.1 * L)


SPEC = {
    "z_tail": (lambda x: x <= -0.7 * L,
               lambda x, y, z: (0, 0, z * rounded((x + 0.7 * L) / (0.3 * L)))),
    "z_head": (lambda x: x >= -0.3 * L,
               lambda x, y, z: (0, 0, z * rounded((x + 0.3 * L) / (0.3 * L)))),
    "y_thin": (lambda x: True, lambda x, y, z: (0, -y, 0)),
    "y_lin_long_tail": (lambda x: x <= -0.3 * L,
                        lambda x, y, z: (0, -y * (-x - 0.3 * L) / (0.7 * L), 0)),
    "y_head": (lambda x: x >= -0.3 * L,
               lambda x, y, z: (0, y * rounded((x + 0.3 * L) / (0.3 * L)), 0)),
    "y_ellipse": (lambda x: True, lambda x, y, z: (0, y * rounded(2 * z / H), 0)),
    "z_small": (lambda x: True, lambda x, y, z: (0, 0, -z)),
    "z_notch": (lambda x: -0.9 * L <= x <= -0.3 * L, lambda x, y, z: (0, 0, -z * notch(x))),
    "xz_concave_tail": (lambda x: x <= -0.9 * L,
                        lambda x, y, z: (-abs(z) * (-0.9 * L - x) / (0.1 * L), 0,
                                         0.4 * z * (-0.9 * L - x) / (0.1 * L))),
    "y_fin": (lambda x: -0.9 * L <= x <= -0.7 * L, lambda x, y, z: (0, y * hat(x), 0)),
    "y_notch": (lambda x: -0.9 * L <= x <= -0.3 * L, lambda x, y, z: (0, -y * notch(x), 0)),
    "z_tail_step": (lambda x: x <= -0.45 * L, lambda x, y, z: (0, 0, -z * step(x))),
    "z_tail_lin": (lambda x: x <= -0.3 * L, lambda x, y, z: (0, 0, -z * (-x - 0.3 * L) / (0.7 * L))),
    "y_tail": (lambda x: x <= -0.7 * L,
               lambda x, y, z: (0, y * rounded((x + 0.7 * L) / (0.3 * L)), 0)),
}

# x where a field's definition changes (region bounds and kinks), away from the box faces.
BREAKPOINTS = {
    "z_tail": [-0.7], "z_head": [-0.3], "y_thin": [], "y_lin_long_tail": [-0.3], "y_head": [-0.3],
    "y_ellipse": [], "z_small": [], "z_notch": [-0.9, -0.7, -0.3], "xz_concave_tail": [-0.9],
    "y_fin": [-0.9, -0.8, -0.7], "y_notch": [-0.9, -0.7, -0.3], "z_tail_step": [-0.55, -0.45],
    "z_tail_lin": [-0.3], "y_tail": [-0.7],
}

# Collapse fields: (component, nodes of the extreme where ξ = 1 brings that coordinate to 0).
COLLAPSE = {
    "z_tail": (2, lambda p: np.isclose(p[:, 0], -L)),
    "z_head": (2, lambda p: np.isclose(p[:, 0], 0)),
    "y_thin": (1, lambda p: np.ones(len(p), bool)),
    "y_lin_long_tail": (1, lambda p: np.isclose(p[:, 0], -L)),
    "y_head": (1, lambda p: np.isclose(p[:, 0], 0)),
    "y_ellipse": (1, lambda p: np.isclose(np.abs(p[:, 2]), H / 2)),
    "z_small": (2, lambda p: np.ones(len(p), bool)),
    "z_notch": (2, lambda p: np.isclose(p[:, 0], -0.7 * L)),
    "y_notch": (1, lambda p: np.isclose(p[:, 0], -0.7 * L)),
    "z_tail_step": (2, lambda p: p[:, 0] <= -0.55 * L + 1e-12),
    "z_tail_lin": (2, lambda p: np.isclose(p[:, 0], -L)),
    "y_tail": (1, lambda p: np.isclose(p[:, 0], -L)),
}


def test_catalog_is_spec_table_plus_y_tail():
    assert shape_names() == list(SPEC)
    assert len(shape_names()) == 14


@pytest.mark.parametrize("name", list(SPEC))
def test_field_matches_spec_formula_inside_and_vanishes_outside(name, mesh):
    region, formula = SPEC[name]
    points = np.vstack([random_points(), mesh[0]])
    inside = np.array([region(x) for x in points[:, 0]])
    assert inside.any()
    expected = np.array([formula(*p) if region(p[0]) else (0, 0, 0) for p in points], dtype=float)
    actual = shape_displacement(name, points, BOX)
    np.testing.assert_allclose(actual, expected, rtol=1e-12, atol=1e-14)
    assert np.all(actual[~inside] == 0.0)


@pytest.mark.parametrize("name", [name for name, bounds in BREAKPOINTS.items() if bounds])
def test_field_is_continuous_at_its_breakpoints(name):
    for fraction in BREAKPOINTS[name]:
        x = fraction * L
        side = np.array([[x - 1e-9, W / 2, H / 2], [x, W / 2, H / 2], [x + 1e-9, W / 2, H / 2]])
        values = shape_displacement(name, side, BOX)
        np.testing.assert_allclose(values, values[[1, 1, 1]], atol=1e-8)


@pytest.mark.parametrize("name", [name for name, bounds in BREAKPOINTS.items() if bounds])
def test_field_is_near_zero_just_inside_its_region_bounds(name):
    region, _ = SPEC[name]
    outer_bounds = [b * L for b in BREAKPOINTS[name] if not (region(b * L - 1e-6) and region(b * L + 1e-6))]
    assert outer_bounds
    for x in outer_bounds:
        just_inside = x + (1e-6 if region(x + 1e-6) else -1e-6)
        value = shape_displacement(name, np.array([[just_inside, W / 2, H / 2]]), BOX)
        assert np.abs(value).max() < 1e-4 * H


@pytest.mark.parametrize("name", list(SPEC))
def test_field_is_finite_just_outside_the_box(name):
    eps = 1e-12
    corners = np.array([[-L - eps, W / 2 + eps, H / 2 + eps], [eps, -W / 2 - eps, -H / 2 - eps]])
    assert np.all(np.isfinite(shape_displacement(name, corners, BOX)))


@pytest.mark.parametrize("name", list(SPEC))
def test_field_takes_coordinate_rows_as_dolfinx_interpolation_does(name, mesh):
    coordinates = mesh[0].T.copy()
    rows = CATALOG[name](coordinates[0], coordinates[1], coordinates[2], BOX)
    np.testing.assert_array_equal(np.array(rows), shape_displacement(name, mesh[0], BOX).T)


@pytest.mark.parametrize("name", list(COLLAPSE))
def test_collapse_at_xi_one_and_enlarge_at_negative_xi(name, mesh):
    points = mesh[0]
    component, extreme = COLLAPSE[name]
    field = shape_displacement(name, points, BOX)
    at_extreme = extreme(points) & (np.abs(points[:, component]) > 0)
    assert at_extreme.any()
    np.testing.assert_allclose((points + field)[at_extreme, component], 0.0, atol=1e-15)
    enlarged = np.abs((points - field)[:, component])
    assert np.all(enlarged >= np.abs(points[:, component]) - 1e-15)
    assert np.all(enlarged[at_extreme] > np.abs(points[at_extreme, component]))


def test_y_thin_at_one_collapses_y_and_keeps_x_z(mesh):
    points = mesh[0]
    moved = design_points(points, shape_matrix(["y_thin"], points, BOX), np.array([1.0]))
    np.testing.assert_allclose(moved[:, 1], 0.0, atol=1e-15)
    np.testing.assert_array_equal(moved[:, [0, 2]], points[:, [0, 2]])


def test_shape_matrix_is_node_major_with_one_column_per_name(mesh):
    points = mesh[0]
    names = ["z_tail", "y_thin", "xz_concave_tail"]
    U = shape_matrix(names, points, BOX)
    assert U.shape == (3 * len(points), 3)
    for k, name in enumerate(names):
        field = shape_displacement(name, points, BOX)
        for i in (0, 7, len(points) - 1):
            for c in range(3):
                assert U[3 * i + c, k] == field[i, c]
    assert shape_matrix([], points, BOX).shape == (3 * len(points), 0)


def test_design_points_is_nominal_plus_weighted_fields(mesh):
    points = mesh[0]
    names = ["z_tail", "z_head", "y_thin"]
    U = shape_matrix(names, points, BOX)
    np.testing.assert_array_equal(design_points(points, U, np.zeros(3)), points)
    xi = np.array([0.5, -0.3, 0.15])
    expected = points + sum(x * shape_displacement(n, points, BOX) for x, n in zip(xi, names))
    np.testing.assert_allclose(design_points(points, U, xi), expected, rtol=0, atol=1e-15)


def moved_mesh(mesh, xi_by_name):
    points = mesh[0]
    U = shape_matrix(list(xi_by_name), points, BOX)
    return design_points(points, U, np.array(list(xi_by_name.values())))


@pytest.mark.parametrize("xi_by_name", [
    {"z_tail": 0.5, "z_head": -0.5, "y_thin": 0.15},
    {"z_tail": 0.5, "z_head": -0.5, "y_lin_long_tail": 0.3, "y_head": -0.4, "y_ellipse": 0.4,
     "z_small": 0.25, "z_notch": 0.25, "xz_concave_tail": 0.2},
    {"y_thin": 0.85},
    {"y_fin": 0.3, "y_notch": -0.3, "z_tail_step": 0.5, "z_tail_lin": -0.5, "y_tail": 0.5},
])
def test_designs_within_study_bounds_pass(mesh, xi_by_name):
    check_design(*mesh, moved_mesh(mesh, xi_by_name), xi_by_name)


@pytest.mark.parametrize("xi_by_name", [{"y_thin": 1.0}, {"y_thin": 1.5},
                                        {"z_tail": 0.2, "y_thin": 1.2},
                                        # fields add: y vanishes at the head's top and bottom edges
                                        {"y_head": 0.5, "y_ellipse": 0.5}])
def test_inverted_or_flat_cells_raise_naming_the_parameters(mesh, xi_by_name):
    with pytest.raises(InputError) as error:
        check_design(*mesh, moved_mesh(mesh, xi_by_name), xi_by_name, label="start design")
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith("start design ")
    for name, value in xi_by_name.items():
        assert f"{name}={value:g}" in message
    assert "reduce the parameters" in message


def test_inversion_reports_counts_and_a_squeezed_design_is_valid_with_a_warning(mesh):
    """Only what the continuum inverts is refused; cells squeezed below 0.1 of their volume are named in
    a one-line warning and the design runs."""
    points, cells = mesh
    with pytest.raises(InputError, match=rf"inverts or flattens {len(cells)} of {len(cells)} cells"):
        check_design(points, cells, moved_mesh(mesh, {"y_thin": 1.5}), {"y_thin": 1.5})
    warning = check_design(points, cells, moved_mesh(mesh, {"y_thin": 0.95}), {"y_thin": 0.95})
    assert warning.startswith(f"design y_thin=0.95 shrinks {len(cells)} of {len(cells)} cells below 0.1")
    assert "\n" not in warning and "volume ratio 0.05" in warning
    assert check_design(points, cells, moved_mesh(mesh, {"y_thin": 0.85}), {"y_thin": 0.85}) is None


def test_check_design_does_not_depend_on_nominal_cell_orientation(mesh):
    points, cells = mesh
    reversed_cells = cells[:, [0, 2, 1, 3]]
    check_design(points, reversed_cells, moved_mesh(mesh, {"y_thin": 0.5}), {"y_thin": 0.5})
    with pytest.raises(InputError, match="y_thin=1.5"):
        check_design(points, reversed_cells, moved_mesh(mesh, {"y_thin": 1.5}), {"y_thin": 1.5})


def test_unknown_name_raises_listing_the_valid_names(mesh):
    with pytest.raises(InputError) as error:
        shape_displacement("z_tial", mesh[0], BOX)
    message = str(error.value)
    assert "'z_tial'" in message
    for name in SPEC:
        assert name in message
    with pytest.raises(InputError, match="z_tial"):
        shape_matrix(["z_tail", "z_tial"], mesh[0], BOX)


def test_fields_interpolate_into_a_dolfinx_vector_space():
    dolfinx = pytest.importorskip("dolfinx")
    from mpi4py import MPI

    domain = dolfinx.mesh.create_box(
        MPI.COMM_SELF, [np.array([-L, -W / 2, -H / 2]), np.array([0.0, W / 2, H / 2])], [10, 2, 2],
        dolfinx.mesh.CellType.tetrahedron)
    from aquarom_fenics.fem import dolfinx_adapter

    space = dolfinx_adapter.vector_space(domain, 1)        # compiled through the toolkit's guarded cache
    nodes = space.tabulate_dof_coordinates()
    for name, field in CATALOG.items():
        displacement = dolfinx.fem.Function(space)
        displacement.interpolate(lambda X: np.stack(field(X[0], X[1], X[2], BOX)))
        np.testing.assert_allclose(displacement.x.array.reshape(-1, 3), shape_displacement(name, nodes, BOX),
                                   rtol=1e-12, atol=1e-15)


def test_the_design_check_determinant_equals_numpy_s():
    matrices = np.eye(3) + 0.4 * np.random.default_rng(3).standard_normal((500, 3, 3))
    np.testing.assert_allclose(determinant_3x3(matrices), np.linalg.det(matrices), rtol=1e-12, atol=1e-14)


def test_a_fish_keeps_its_last_design_checks(monkeypatch):
    """An optimiser checks a design and then builds there: the second check is the kept verdict, a
    refusal included; beyond CHECKED_DESIGNS other designs the first is checked again."""
    from aquarom_fenics.geometry import fish as fish_module
    from aquarom_fenics.geometry.fish import CHECKED_DESIGNS, load_fish
    from aquarom_fenics.io.scene import Scene

    fish = load_fish(Scene.load("so1"))
    checks = []
    original = fish_module.check_exact_design
    monkeypatch.setattr(fish_module, "check_exact_design", lambda *args, **kwargs: checks.append(1) or original(*args, **kwargs))
    design = np.array([-0.21, 0.33, 0.05])
    first = fish.design(design)
    np.testing.assert_array_equal(fish.design(design.copy()), first)
    assert len(checks) == 1
    inverting = np.array([0.0, 0.0, 1.2])          # y_thin beyond 1 flattens the body
    messages = []
    for _ in range(2):
        with pytest.raises(InputError) as refused:
            fish.design(inverting)
        messages.append(str(refused.value))
    assert len(checks) == 2 and messages[0] == messages[1] and "inverts or flattens" in messages[0]
    for k in range(CHECKED_DESIGNS):
        fish.design(np.array([0.0, 0.0, 0.001 * (k + 1)]))
    fish.design(design)
    assert len(checks) == 3 + CHECKED_DESIGNS
