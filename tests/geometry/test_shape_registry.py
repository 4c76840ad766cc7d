"""Shape fields of one's own: registration, its one-line errors, use by name from the API, and the
Taylor test of a field's gradient against its value (SPEC §4)."""
import numpy as np
import pytest

from aquarom_fenics.api import (build_prom, check_shape_fields, load_fish, register_shape_field, simulate,
                                unregister_shape_field)
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.shape_registry import PROBE_BOX, probe_points, registered_fields
from aquarom_fenics.geometry.shapes import shape_displacement, shape_gradients, shape_names
from aquarom_fenics.verification.check import table_row
from conftest import coarse_scene


@pytest.fixture
def registry():
    """Registers through the API and forgets every field registered by the test afterwards."""
    yield register_shape_field
    for name in registered_fields():
        unregister_shape_field(name)


@pytest.fixture(scope="module")
def box():
    return load_fish(coarse_scene()).tags.box


def copy_of(name, box, gradient_factor=1.0):
    """(U, ∇U) of the catalogue's field ``name`` as functions of X alone (∇U scaled by the factor)."""
    return (lambda X: shape_displacement(name, X, box),
            lambda X: gradient_factor * shape_gradients([name], X, box)[0])


def one_shape_scene(name, duration=0.1):
    return coarse_scene(solver={"duration": duration}, shapes={name: {"bounds": [-0.5, 0.5]}})


# ---------------------------------------------------------------------------------------------
# Registration


def test_a_registered_field_is_a_shape_name_until_unregistered(registry, box):
    registry("my_tail", *copy_of("z_tail", box))
    assert shape_names()[-1] == "my_tail" and len(shape_names()) == 15
    unregister_shape_field("my_tail")
    assert "my_tail" not in shape_names() and len(shape_names()) == 14
    with pytest.raises(InputError, match="unknown shape variation 'my_tail'"):
        one_shape_scene("my_tail")


def test_the_probe_points_lie_inside_the_default_block():
    from aquarom_fenics.io.scene_sections import MeshSection

    block = MeshSection()
    assert PROBE_BOX == (block.length, block.width, block.height)
    points = probe_points()
    assert points.shape == (125, 3)
    assert np.all((points[:, 0] < 0) & (points[:, 0] > -block.length))
    assert np.all(np.abs(points[:, 1:]) < np.array([block.width, block.height]) / 2)


def flat(X):
    return np.zeros((len(X), 3))


def flat_gradient(X):
    return np.zeros((len(X), 3, 3))


@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")
@pytest.mark.parametrize("name, value, gradient, message", [
    ("y_thin", flat, flat_gradient, r"shape field 'y_thin': the name is the catalogue's field y_thin; choose another"),
    ("2nd", flat, flat_gradient, r"shape field name '2nd': use letters, digits and underscores"),
    ("my-field", flat, flat_gradient, r"shape field name 'my-field': use letters"),
    ("amplitude", flat, flat_gradient, r"shape field 'amplitude': the name is reserved"),
    ("bump", "flat", flat_gradient, r"shape field 'bump': its value must be a function of X .* got str$"),
    ("bump", lambda X: X[:, 0], flat_gradient,
     r"shape field 'bump': its value returned an array of shape \(125,\) for 125 points; expected \(125, 3\)$"),
    ("bump", flat, flat, r"shape field 'bump': its gradient returned an array of shape \(125, 3\) for 125 points; "
                         r"expected \(125, 3, 3\)$"),
    ("bump", lambda X: np.sqrt(X + 0.01), flat_gradient,
     r"shape field 'bump': its value is not finite at \d+ of 125 points, the first X = \(-0.02, -0.016, -0.04\) m"),
])
def test_a_bad_registration_is_one_line(registry, name, value, gradient, message):
    with pytest.raises(InputError, match=message):
        registry(name, value, gradient)
    assert name not in registered_fields()


def test_a_name_registered_twice_is_refused(registry):
    registry("bump", flat, flat_gradient)
    with pytest.raises(InputError, match=r"shape field 'bump': already registered in this process; "
                                         r"unregister_shape_field\('bump'\) first"):
        registry("bump", flat, flat_gradient)
    with pytest.raises(InputError, match=r"shape field 'lump': not registered in this process \(registered: bump\)"):
        unregister_shape_field("lump")


@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")
def test_a_field_wrong_on_the_mesh_is_one_line_when_used(registry):
    """Finite on the probe box, not on a longer body: the mesh's points name the problem."""
    registry("short_bump", lambda X: np.stack([0 * X[:, 0], 0 * X[:, 0], np.sqrt(0.2 + X[:, 0])], axis=1), flat_gradient)
    scene = one_shape_scene("short_bump").replace("mesh", length=0.3)
    with pytest.raises(InputError, match=r"shape field 'short_bump': its value is not finite at \d+ of \d+ points"):
        load_fish(scene)


def test_the_scene_hash_follows_the_registered_definition(registry, box):
    """The hashes (and so the PROM and FOM cache entries) are those of the definition registered now."""
    scene = one_shape_scene("z_tail")
    catalogue = scene.hash
    registry("bump", *copy_of("z_tail", box))
    scene = one_shape_scene("bump")
    first = scene.hash, scene.fom_hash
    unregister_shape_field("bump")
    registry("bump", *copy_of("z_head", box))
    second = scene.hash, scene.fom_hash
    assert first[0] != second[0] and first[1] != second[1]
    unregister_shape_field("bump")
    registry("bump", *copy_of("z_tail", box))
    assert (scene.hash, scene.fom_hash) == first and catalogue not in (first[0], second[0])


# ---------------------------------------------------------------------------------------------
# Used by name from the API: the same results as the catalogue's field it copies


def test_a_registered_copy_of_z_tail_swims_as_z_tail(registry, box):
    registry("my_tail", *copy_of("z_tail", box))
    catalogue = simulate(one_shape_scene("z_tail"), {"z_tail": 0.4})
    registered = simulate(one_shape_scene("my_tail"), {"my_tail": 0.4})
    nominal = simulate(one_shape_scene("z_tail"), {"z_tail": 0.0})
    assert catalogue.completed and registered.completed
    assert abs(catalogue.distance - nominal.distance) > 1e-9          # the shape changes the swim
    assert registered.distance == pytest.approx(catalogue.distance, rel=0, abs=1e-12)


def test_a_registered_field_builds_a_prom_as_the_catalogue(registry, box):
    registry("my_tail", *copy_of("z_tail", box))
    prom = build_prom(one_shape_scene("my_tail", duration=0.2))
    reference = build_prom(one_shape_scene("z_tail", duration=0.2))
    assert prom.shape_names == ["my_tail"]
    np.testing.assert_allclose(simulate(one_shape_scene("my_tail", 0.2), {"my_tail": 0.1}, model="prom",
                                        prom=prom).trajectory.arrays()["com_x"],
                               simulate(one_shape_scene("z_tail", 0.2), {"z_tail": 0.1}, model="prom",
                                        prom=reference).trajectory.arrays()["com_x"], rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# The Taylor test


def test_the_taylor_test_passes_every_catalogue_field():
    scene = coarse_scene(shapes={name: {"bounds": [-0.1, 0.1]} for name in shape_names()})
    results = check_shape_fields(scene)
    assert [result.check for result in results] == [f"0 ∇U {name}" for name in shape_names()]
    assert all(result.passed for result in results), [table_row(result) for result in results]
    assert results[0].order == "2.00"


def test_the_taylor_test_passes_a_correct_registered_field_and_fails_a_wrong_gradient(registry, box):
    registry("good_tail", *copy_of("z_tail", box))
    registry("bad_tail", *copy_of("z_tail", box, gradient_factor=1.05))
    good, bad = check_shape_fields(one_shape_scene("good_tail"), ["good_tail", "bad_tail"])
    assert good.passed and good.order == "2.00"
    assert bad.passed is False and bad.order == "1.00"
    assert "the remainder falls like h^1.00 (median), not h²: the gradient is not that of the value" in bad.note


def test_no_fresh_worker_process_runs_a_scene_with_a_registered_field(registry, box):
    """A worker started afresh does not know the field: the FOM check runs the start design here."""
    from aquarom_fenics.studies.background_fom import start_if_useful

    registry("my_tail", *copy_of("z_tail", box))
    assert start_if_useful(one_shape_scene("my_tail"), {"my_tail": 0.0}, None, cached=False) is None


# ---------------------------------------------------------------------------------------------
# The fingerprint is taken at the scene's mesh, the Taylor test at every quadrature point


def tail_tip(scale):
    """(U, ∇U) of Δz = scale z ((x + 0.19) / 0.01)² behind x = -0.19 m, 0 elsewhere: the tail's
    last 5 %, which the probe box (x ≥ -0.18 m) never reaches."""
    def value(X):
        U = np.zeros_like(X)
        U[:, 2] = scale * X[:, 2] * np.where(X[:, 0] < -0.19, (X[:, 0] + 0.19) / 0.01, 0.0) ** 2
        return U

    def gradient(X):
        s = np.where(X[:, 0] < -0.19, (X[:, 0] + 0.19) / 0.01, 0.0)
        G = np.zeros((len(X), 3, 3))
        G[:, 2, 0] = scale * X[:, 2] * 2 * s / 0.01
        G[:, 2, 2] = scale * s ** 2
        return G
    return value, gradient


@pytest.mark.parametrize("degree", [1, 2])
def test_fields_equal_on_the_probe_box_but_not_on_the_mesh_hash_apart(registry, degree):
    """Three times larger behind the probe box: another hash, FOM hash and fish (so no cache entry
    of the first definition answers for the second)."""
    from aquarom_fenics.geometry.fish_cache import fish_key

    small, large = tail_tip(1.0), tail_tip(3.0)
    np.testing.assert_array_equal(small[0](probe_points()), large[0](probe_points()))
    np.testing.assert_array_equal(small[1](probe_points()), large[1](probe_points()))
    hashes = []
    for value, gradient in (small, large, small):
        registry("tip", value, gradient)
        scene = one_shape_scene("tip").replace("mesh", degree=degree)
        hashes.append((scene.hash, scene.fom_hash, fish_key(scene)))
        unregister_shape_field("tip")
    assert all(a != b for a, b in zip(hashes[0], hashes[1]))
    assert hashes[2][:2] == hashes[0][:2]                     # the same definition: the same hashes again


def test_the_fingerprint_of_a_quadratic_scene_sees_its_edge_midpoints(registry, box):
    """A field zero at every vertex but not at the edge midpoints: what a linear scene reads of it
    (U at the vertices, ∇U at the quadrature points) is the zero field's, a quadratic one's is not."""
    vertices = {tuple(point) for point in np.round(box.relative(load_fish(coarse_scene()).mesh.points), 12)}

    def between(X):
        U = np.zeros_like(X)
        U[:, 2] = [0.0 if tuple(point) in vertices else 1e-3 for point in np.round(X, 12)]
        return U

    hashes = []
    for value in (flat, between):
        registry("bump", value, flat_gradient)
        hashes.append([one_shape_scene("bump").replace("mesh", degree=degree).fom_hash for degree in (1, 2)])
        unregister_shape_field("bump")
    assert hashes[0][0] == hashes[1][0] and hashes[0][1] != hashes[1][1]


def wrong_at_the_tail_end(L, share=0.012):
    """(U, ∇U) of Δz = z (x/L)² over the whole body, with ∂U_z/∂x 10 % too large on its last 1.2 %
    (x < -0.988 L), on the quarter y > 0, z > 0 of the cross-section: 66 of the 6860 quadrature
    points of level 1, under the 1 % a share-based test lets pass."""
    def value(X):
        U = np.zeros_like(X)
        U[:, 2] = X[:, 2] * (X[:, 0] / L) ** 2
        return U

    def gradient(X):
        wrong = (X[:, 0] < -(1 - share) * L) & (X[:, 1] > 0) & (X[:, 2] > 0)
        G = np.zeros((len(X), 3, 3))
        G[:, 2, 0] = 2 * X[:, 2] * X[:, 0] / L ** 2 * np.where(wrong, 1.1, 1.0)
        G[:, 2, 2] = (X[:, 0] / L) ** 2
        return G
    return value, gradient


def test_a_gradient_wrong_on_the_last_cells_of_the_tail_fails_the_taylor_test(registry, box):
    registry("right", *wrong_at_the_tail_end(box.length, share=0.0))
    registry("wrong", *wrong_at_the_tail_end(box.length))
    right, wrong = check_shape_fields(one_shape_scene("right"), ["right", "wrong"])
    assert right.passed and right.order == "2.00", table_row(right)
    assert wrong.passed is False, table_row(wrong)
    assert wrong.measured.startswith("66 of 6860") and "not h²: the gradient is not that of the value" in wrong.note
    x = float(wrong.note.split("at X = (")[1].split(",")[0])
    assert x < -0.988 * box.length
