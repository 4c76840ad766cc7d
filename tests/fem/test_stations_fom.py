"""The thrust through stations has a mesh limit; the nodal model's point force does not (SPEC §5)."""
import pytest

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.verification.convergence import tail_compliances
from conftest import coarse_scene


@pytest.fixture(scope="module")
def compliances():
    """Static x-compliance [m/N] of the tail station and of the tail node, degree 2, levels 2 and 3."""
    measured = {}
    for level in (2, 3):
        scene = coarse_scene(mesh={"level": level, "degree": 2})
        model = FullOrderModel(scene, load_fish(scene))
        measured[level] = tail_compliances(model)
        model.destroy()
    return measured


def test_the_tail_station_compliance_converges_between_levels_2_and_3(compliances):
    change = compliances[3]["station"] / compliances[2]["station"] - 1.0
    assert abs(change) < 0.03, change


def test_the_tail_node_compliance_grows_with_the_mesh(compliances):
    """A unit force on one node indents the continuum more on every finer mesh (no limit)."""
    assert compliances[3]["node"] / compliances[2]["node"] - 1.0 > 0.1
    assert compliances[3]["node"] > 2.0 * compliances[3]["station"]
