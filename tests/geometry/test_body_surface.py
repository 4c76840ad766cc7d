"""Boundary surfaces of tetrahedral meshes and their checks (closed, manifold, outward, no
self-intersection, volume), on the block and on small meshes built to fail each check."""
import numpy as np
import pytest

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.geometry.export import checked_surface, design_body, read_stl, stl_bytes
from aquarom_fenics.geometry.surface import (Surface, boundary_surface, manifold_problem, open_edges,
                                             self_intersections, surface_problem, tetrahedra_volume)

UNIT_TETRAHEDRON = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def test_one_tetrahedron_in_either_vertex_order_faces_outward():
    for cells in ([[0, 1, 2, 3]], [[0, 2, 1, 3]]):
        surface = boundary_surface(UNIT_TETRAHEDRON, np.array(cells))
        assert len(surface.triangles) == 4
        assert surface.volume == pytest.approx(1.0 / 6.0, rel=1e-14)
        centre = surface.points.mean(axis=0)
        x = surface.points[surface.triangles]
        assert (np.einsum("ij,ij->i", surface.normals, x.mean(axis=1) - centre) > 0).all()
        assert surface_problem(surface, 1.0 / 6.0) is None


@pytest.fixture(scope="module")
def block_body():
    from aquarom_fenics.geometry.fish import load_fish
    from tests.conftest import coarse_scene

    scene = coarse_scene()
    return scene, design_body(scene, load_fish(scene), {})


def test_the_nominal_block_is_closed_outward_and_holds_8e_4_cubic_metres(block_body):
    _, body = block_body
    surface = checked_surface(body.points, body.cells, "body")
    assert open_edges(surface) == 0 and manifold_problem(surface) is None and self_intersections(surface) == 0
    assert surface.volume == pytest.approx(8.0e-4, rel=1e-9)
    assert body.volume == pytest.approx(8.0e-4, rel=1e-9)


def test_the_regions_are_closed_and_their_volumes_add_up_to_the_body(block_body):
    _, body = block_body
    assert list(body.regions) == ["head", "left_muscle", "right_muscle", "passive"]
    covered = np.sort(np.concatenate(list(body.regions.values())))
    assert np.array_equal(covered, np.arange(len(body.cells)))          # disjoint and complete
    volumes = {name: checked_surface(body.points, body.cells[cells], name).volume
               for name, cells in body.regions.items()}
    assert sum(volumes.values()) == pytest.approx(body.volume, rel=1e-12)
    assert volumes["head"] == pytest.approx(0.35 * 8.0e-4, rel=1e-9)     # head_fraction 0.35 of the block


def test_a_surface_with_a_triangle_missing_is_not_closed(block_body):
    _, body = block_body
    surface = boundary_surface(body.points, body.cells)
    holed = Surface(surface.points, surface.triangles[1:])
    kind, why = surface_problem(holed, body.volume)
    assert kind == "input" and why.startswith("not closed: 3 edge(s)")


def test_a_flipped_triangle_and_an_inside_out_surface_are_refused(block_body):
    _, body = block_body
    surface = boundary_surface(body.points, body.cells)
    one = surface.triangles.copy()
    one[0] = one[0, [0, 2, 1]]
    assert surface_problem(Surface(surface.points, one), body.volume)[1].startswith("not manifold: 3 edge(s) run twice")
    inside_out = Surface(surface.points, surface.triangles[:, [0, 2, 1]])
    assert surface_problem(inside_out, body.volume)[1].startswith("not outward")


def test_two_tetrahedra_touching_at_one_vertex_are_no_manifold():
    points = np.vstack([UNIT_TETRAHEDRON, -UNIT_TETRAHEDRON[1:]])
    cells = np.array([[0, 1, 2, 3], [0, 4, 5, 6]])
    surface = boundary_surface(points, cells)
    assert open_edges(surface) == 0
    assert manifold_problem(surface) == "1 vertex/vertices where separate parts of the surface touch"


def test_two_overlapping_tetrahedra_intersect_themselves():
    shifted = UNIT_TETRAHEDRON + np.array([0.2, 0.2, 0.2])
    points = np.vstack([UNIT_TETRAHEDRON, shifted])
    cells = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    surface = boundary_surface(points, cells)
    assert open_edges(surface) == 0 and manifold_problem(surface) is None
    assert self_intersections(surface) > 0
    kind, why = surface_problem(surface, tetrahedra_volume(points, cells))
    assert kind == "input" and why.startswith("self-intersecting")
    apart = np.vstack([UNIT_TETRAHEDRON, UNIT_TETRAHEDRON + 2.0])        # the same two, apart: no crossing
    assert self_intersections(boundary_surface(apart, cells)) == 0


def test_a_volume_off_by_more_than_1e_9_is_a_computation_failure(block_body):
    _, body = block_body
    surface = boundary_surface(body.points, body.cells)
    assert surface_problem(surface, body.volume * (1 + 5e-10)) is None
    kind, why = surface_problem(surface, body.volume * (1 + 2e-9))
    assert kind == "volume" and "relative" in why


def test_checked_surface_raises_input_or_solver_errors():
    shifted = UNIT_TETRAHEDRON + 0.2
    with pytest.raises(InputError, match="^body: surface self-intersecting.*nothing written$"):
        checked_surface(np.vstack([UNIT_TETRAHEDRON, shifted]), np.array([[0, 1, 2, 3], [4, 5, 6, 7]]), "body")
    assert issubclass(SolverError, Exception) and SolverError.exit_code == 3


def test_binary_stl_reads_back_in_millimetres_and_metres(block_body):
    _, body = block_body
    surface = boundary_surface(body.points, body.cells)
    header, normals, vertices = read_stl(stl_bytes(surface, "mm"))
    _, _, metres = read_stl(stl_bytes(surface, "m"))
    assert header.startswith("aquarom export") and vertices.shape == (len(surface.triangles), 3, 3)
    assert np.allclose(vertices, 1000.0 * metres, rtol=1e-6, atol=0)
    assert np.allclose(metres, surface.points[surface.triangles], rtol=0, atol=1e-8)
    assert np.allclose(normals, surface.normals, atol=1e-6)
