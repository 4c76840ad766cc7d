"""Station averages B of SPEC §5 on the nominal mesh: hats, weights, the head average."""
import numpy as np
import pytest

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.physics.stations import hat_functions, lagrange_basis, station_averages, station_positions
from conftest import coarse_scene


def test_hats_are_a_partition_of_unity_and_interpolate_the_grid():
    stations = station_positions(0.2, -0.2, 8)
    x = np.linspace(-0.2, 0.0, 1001)
    hats = hat_functions(x, stations)
    np.testing.assert_allclose(hats.sum(axis=0), 1.0, atol=1e-14)
    np.testing.assert_allclose(hat_functions(stations, stations), np.eye(9), atol=1e-14)
    assert hats.min() >= 0.0


@pytest.mark.parametrize("degree", [1, 2])
def test_lagrange_basis_sums_to_one_and_is_nodal(degree):
    rng = np.random.default_rng(0)
    points = rng.dirichlet(np.ones(4), size=20)[:, 1:]
    np.testing.assert_allclose(lagrange_basis(points, degree).sum(axis=1), 1.0, atol=1e-13)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    np.testing.assert_allclose(lagrange_basis(vertices, degree)[:, :4], np.eye(4), atol=1e-13)


@pytest.fixture(scope="module", params=[1, 2])
def averages(request):
    scene = coarse_scene(mesh={"degree": request.param})
    fish = load_fish(scene)
    return fish, station_averages(fish.mesh.points, fish.mesh.cells, fish.nodes, fish.tags.box, 10,
                                  fish.tags.head_cells)


def test_station_weights_average_rigid_motions_and_the_nominal_positions(averages):
    """Σ_j b_ij = 1 (a rigid motion moves every station with it); B(X) is X_i inside, and the end
    stations' half-hats put their kinematics Δ/3 inside the faces (uniform cross-section), up to the
    quadrature of the hats' kinks inside cells (measured 2.4e-4 Δ on level 1)."""
    fish, stations = averages
    np.testing.assert_allclose(np.asarray(stations.weights.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    positions = stations.average(fish.nodes.points)
    spacing = 0.2 / 10
    expected = stations.stations.copy()
    expected[0] += spacing / 3
    expected[-1] -= spacing / 3
    np.testing.assert_allclose(positions[:, 0], expected, atol=1e-3 * spacing)
    np.testing.assert_allclose(positions[:, 1:], 0.0, atol=1e-9)


def test_the_head_average_weighs_head_nodes_only(averages):
    fish, stations = averages
    assert stations.head_weights.sum() == pytest.approx(1.0)
    outside = np.setdiff1d(np.arange(fish.nodes.points.shape[0]), fish.tags.head_nodes)
    assert np.all(stations.head_weights[outside] == 0.0)
    centroid = stations.head_weights @ fish.nodes.points
    assert centroid[0] == pytest.approx(-0.35 * 0.2 / 2, rel=0.05)


@pytest.mark.parametrize("degree", [1, 2])
def test_the_face_tail_station_averages_the_end_face(degree):
    """[fluid] tail_station = "face": station 0 is the average over the end face x = -L (its x is -L,
    its y and z the face's centre)."""
    from aquarom_fenics.fem.fom import averages_of

    fish = load_fish(coarse_scene(mesh={"degree": degree}))
    face = averages_of(fish, 10, "face")
    assert face.weights[0].sum() == pytest.approx(1.0)
    np.testing.assert_allclose(face.average(fish.nodes.points)[0], [-0.2, 0.0, 0.0], atol=1e-12)
    slab = averages_of(fish, 10, "slab")
    assert (face.weights[1:] != slab.weights[1:]).nnz == 0


def test_the_same_mesh_read_again_shares_its_read_only_maps_and_another_station_count_does_not(averages):
    fish, stations = averages
    again = load_fish(coarse_scene(mesh={"degree": fish.nodes.degree}))
    assert again is not fish
    mesh, tags = again.mesh, again.tags
    shared = station_averages(mesh.points, mesh.cells, again.nodes, tags.box, 10, tags.head_cells)
    assert shared is stations
    with pytest.raises(ValueError):
        shared.head_weights[0] = 1.0
    with pytest.raises(ValueError):
        shared.weights.data[0] = 1.0
    coarser = station_averages(mesh.points, mesh.cells, again.nodes, tags.box, 5, tags.head_cells)
    assert coarser.n_stations == 6 and coarser is not stations
