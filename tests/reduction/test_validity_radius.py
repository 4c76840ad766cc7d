"""The PROM's validity radius where the tensors change fast in ξ (``[reduction] validity_change``,
docs/theory/basis.md "The validity radius at thin designs")."""
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.taylor import Taylor
from aquarom_fenics.reduction.reductor import build_prom, validity_radii

CENTER = np.array([-0.499, 0.499, 0.3992, 0.499, 0.499])
"""A PROM centre of the budget front near the CO corner (z_tail, z_head, y_lin_long_tail, y_head, y_ellipse),
where det F_1 falls to 0.10 at the tail's edges."""
STOPPED = np.array([-0.48730220127652124, 0.45887696375304754, 0.36456039012092584, 0.46226804386570963,
                    0.4221432086048888])
"""The design at which that PROM's simulation stopped in Newton's line search (A = 0.3, t = 0.12 s) with the
radius of validity_fraction alone: 0.62 of that radius from the centre."""


def taylor(rates, scale=2.0):
    """A tensor of norm ``scale`` whose k-th ξ-derivative has norm rates[k] × scale."""
    constant = np.zeros((2, 2))
    constant[0, 0] = scale
    first = np.zeros((len(rates), 2, 2))
    first[:, 1, 0] = np.asarray(rates) * scale
    return Taylor(constant, first)


def test_the_radius_is_the_scenes_capped_at_the_change_over_the_largest_relative_derivative():
    scene = Scene.load("co").replace("reduction", validity_change=0.05)
    elastic = SimpleNamespace(linear=taylor([0.5, 0.0, 1.0, 0.0, 0.1]), quadratic=taylor([2.0, 0.0, 0.2, 0.0, 0.1]),
                              cubic=taylor([0.1, 0.0, 0.2, 0.0, 0.1], scale=7.0))
    inertia = SimpleNamespace(mass=taylor([0.0, 0.25, 0.0, 0.0, 0.1]))
    # scene radii 0.125 (0.1 for y_lin_long_tail); largest rates 2.0, 0.25, 1.0, 0 (none), 0.1
    np.testing.assert_allclose(validity_radii(scene, elastic, inertia, 5), [0.025, 0.125, 0.05, 0.125, 0.125])
    off = scene.replace("reduction", validity_change=0.0)
    np.testing.assert_allclose(validity_radii(off, elastic, inertia, 5), off.validity_radii())


def test_validity_change_enters_the_scene_hash_only_when_set():
    scene = Scene.load("nominal")
    assert scene.replace("reduction", validity_change=0.0).hash == scene.hash
    assert scene.replace("reduction", validity_change=0.035).hash != scene.hash


@pytest.fixture(scope="module")
def corner_prom():
    scene = Scene.load("co").replace("solver", duration=1.0)
    return scene, build_prom(scene, dict(zip(scene.shape_names, CENTER)))


def test_near_the_co_corner_the_radius_keeps_the_prom_where_its_taylor_in_xi_holds(corner_prom):
    """Measured (level 1, A = 0.3, 1 s; with or without the stroke vectors): at STOPPED the PROM with the
    radius of validity_fraction stops (the tensors projected there swim 11.1 cm); with the radius capped,
    at its corner towards STOPPED the PROM is within 1 % of the projection there."""
    scene, prom = corner_prom
    assert scene.reduction.validity_change > 0
    wide = np.array(scene.validity_radii())
    assert np.all(prom.validity_radius <= wide) and prom.validity_radius[-1] < 0.1 * wide[-1]
    with pytest.raises(InputError, match="outside the PROM's validity radius"):
        prom.delta(STOPPED)
    edge = CENTER + np.sign(STOPPED - CENTER) * prom.validity_radius
    projected = build_prom(scene, dict(zip(scene.shape_names, edge)), basis_from=prom)
    taylor_run = simulate_reduced(prom, scene, edge, amplitude=0.3)
    exact_run = simulate_reduced(projected, scene, edge, amplitude=0.3)
    assert taylor_run.completed and exact_run.completed
    assert taylor_run.distance == pytest.approx(exact_run.distance, rel=0.02)
