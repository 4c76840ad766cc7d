"""The atlas's check of its own cells (``[reduction] atlas_check``, ``reduction/atlas_check.py``), on fake PROMs:
a PROM built at c answers d_c(ξ) = f(c) + ∇f(c)·(ξ - c), the first-order Taylor model of a known distance f, so
the gap between a cell's PROM and its corners' grows as h². A cell is halved where the gap at the two corners
along its gradient's signs exceeds τ, until it holds; the corners are vertices shared by the cells that meet there;
the depth limit bounds it; τ = 0 builds nothing (the regular cells)."""
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.errors import InputError
from aquarom_fenics.reduction.atlas_check import CellCheck, gradient_signs, relative_gaps, vertex
from aquarom_fenics.reduction.atlas_cover import Cover
from aquarom_fenics.reduction.atlas_refine import Node, Refiner, divides

S = 0.7
GRID = Cover(("a", "b"), np.zeros(2), np.ones(2), np.array([0.25, 0.25]), np.array([2, 2]),
             np.array([0.25, 0.25]) / S, S)
"""2 × 2 cells of half-width 0.25 over [0, 1]², cut from r = 0.25 / s (uncapped: R = r)."""


def checked(tolerance):
    return SimpleNamespace(reduction=SimpleNamespace(validity_change=0.0, atlas_change=0.0, atlas_check=tolerance))


def f(xi):
    """The 'true' distance: curved in a, more so towards a = 1, falling linearly in b."""
    xi = np.atleast_2d(xi)
    return 1.0 + 2 * xi[:, 0] ** 3 - 0.5 * xi[:, 1]


def grad_f(xi):
    return np.array([6 * xi[0] ** 2, -0.5])


def taylor_prom_at(calls, refuse=lambda xi: False):
    """prom_at(centre) → (a fake PROM at ξ_c, built: False when asked before, as from the PROM cache), every call
    kept by centre; ``refuse(ξ_c)``: an InputError."""
    store = {}

    def prom_at(center):
        xi = np.array([center["a"], center["b"]])
        calls.append(tuple(xi))
        if refuse(xi):
            raise InputError(f"no PROM at {xi}")
        built = tuple(xi) not in store
        store.setdefault(tuple(xi), SimpleNamespace(validity_radius=GRID.radius.copy(), xi_center=xi))
        return store[tuple(xi)], built
    return prom_at


def taylor_distances(prom, scene, xis, gradient=False):
    """d_c(ξ) = f(c) + ∇f(c)·(ξ - c) and its gradient ∇f(c)."""
    xis = np.atleast_2d(xis)
    g = grad_f(prom.xi_center)
    d = f(prom.xi_center)[0] + (xis - prom.xi_center) @ g
    return d, (np.tile(g, (len(xis), 1)) if gradient else None)


def refiner(tolerance, calls, **kwargs):
    return Refiner(checked(tolerance), GRID, prom_at=kwargs.pop("prom_at", taylor_prom_at(calls)),
                   distances=taylor_distances, **kwargs)


def true_corner_errors(grid, node):
    """|d_c(v) - f(v)| / |f(v)| of the node's PROM at all four corners of its cell."""
    center, half = node.center(grid), node.half_width(grid)
    corners = np.array([center + np.array(signs) * half for signs in ((1, 1), (1, -1), (-1, 1), (-1, -1))])
    prom = SimpleNamespace(xi_center=center)
    return np.abs(taylor_distances(prom, None, corners)[0] - f(corners)) / np.abs(f(corners))


def test_the_corners_follow_the_signs_of_the_centre_proms_gradient_and_sit_on_shared_vertices():
    assert gradient_signs(np.array([2.0, -1e-9, 0.0, np.nan])).tolist() == [1, -1, 1, 1]
    calls = []
    check = refiner(0.9, calls).check(Node((1, 0), (0, 0)))         # centre (0.75, 0.25), g = (+, -)
    assert check.corners.tolist() == [[1.0, 0.0], [0.5, 0.5]]        # c ± (h_a, -h_b)
    assert check.passed and check.built == 2 and len(calls) == 3
    parent = vertex(GRID.lower, GRID.half_width, (0, 0), (0, 0), np.array([1, 1]), 6)
    child = vertex(GRID.lower, GRID.half_width, (1, 1), (1, 1), np.array([1, 1]), 6)
    assert parent.tolist() == child.tolist() == [0.5, 0.5]           # the same floats from two levels
    assert relative_gaps([1.0, np.nan, 2.0], [1.0, 1.0, 1.0]).tolist() == [0.0, np.inf, 1.0]


def test_a_cell_whose_gap_exceeds_the_tolerance_is_halved_until_its_check_holds():
    calls = []
    atlas = refiner(0.03, calls)
    leaf = atlas.leaf(np.array([0.9, 0.1]))                           # f'' = 12 a: large towards a = 1
    assert leaf.path and leaf.check is not None and leaf.check.passed and leaf.check.largest <= 0.03
    assert all(not atlas.checks[node].passed for node in leaf.path)
    assert all(atlas.met[node]["split"] == ["a", "b"] for node in leaf.path)    # halved in every shape
    assert leaf.node.levels == (len(leaf.path),) * 2
    assert np.all(true_corner_errors(GRID, leaf.node) <= 0.03 * 1.01)          # the proxy is exact here
    for node in leaf.path:
        assert np.max(true_corner_errors(GRID, node)) > 0.03
    assert len(calls) == 3 * (len(leaf.path) + 1)                     # centre and two corners per level asked,
    assert len(set(calls)) == 3 + len(leaf.path)                      # but a half's corners along its parent's
    assert atlas.checks[leaf.node].built == 0                         # signs are its parent's centre and corner
    gentle = atlas.leaf(np.array([0.1, 0.9]))                         # less curved: fewer halvings
    assert gentle.check.passed and gentle.node.levels[0] < leaf.node.levels[0]


def test_every_design_s_leaf_holds_its_check_and_the_leaves_do_not_depend_on_the_order():
    rng = np.random.default_rng(5)
    designs = rng.uniform(0, 1, size=(80, 2))
    leaves = []
    for order in (designs, designs[::-1]):
        calls = []
        atlas = refiner(0.03, calls)
        leaves.append({tuple(xi): atlas.leaf(xi).node for xi in order})
        assert len(set(calls)) < len(calls)                           # corners shared by cells, read again
        assert sum(check.built for check in atlas.checks.values()) + len(atlas.checks) >= len(set(calls))
        for xi in order:
            leaf = atlas.leaf(xi)
            assert leaf.check.passed and np.all(np.abs(xi - leaf.node.center(GRID)) <= leaf.node.half_width(GRID))
    assert leaves[0] == leaves[1]
    assert len(set(leaves[0].values())) > 4                           # some cells were halved


def test_the_depth_limit_bounds_the_check_and_the_leaf_says_it_failed():
    calls = []
    leaf = refiner(1e-9, calls, max_depth=2).leaf(np.array([0.9, 0.1]))
    assert leaf.node.levels == (2, 2) and not leaf.check.passed and not leaf.at_limit
    assert len(calls) == 3 * 3 and len(set(calls)) == 3 + 2          # three levels, each checked once


def test_a_corner_without_a_prom_is_left_out_and_the_other_decides():
    calls = []
    atlas = refiner(0.9, calls, prom_at=taylor_prom_at(calls, refuse=lambda xi: xi.tolist() == [1.0, 0.0]))
    check = atlas.check(Node((1, 0), (0, 0)))
    assert np.isnan(check.gaps[0]) and np.isfinite(check.gaps[1]) and check.passed and check.built == 1
    assert check.record(GRID.names)["gaps"][0] is None and check.record(GRID.names)["refused"]
    assert not CellCheck(np.zeros((2, 2)), np.array([np.nan, np.inf]), 0, 0.03).passed   # a stopped solve halves


def test_off_the_atlas_is_the_regular_one_without_a_build():
    calls = []
    atlas = refiner(0.0, calls)
    leaf = atlas.leaf(np.array([0.9, 0.1]))
    assert leaf.node == Node((1, 0), (0, 0)) and leaf.check is None and calls == []
    assert not divides(checked(0.0)) and divides(checked(0.03))


@pytest.mark.parametrize("value", [-0.01, 1.0, 2.5])
def test_the_key_refuses_values_outside_zero_to_one(value):
    from aquarom_fenics.io.scene import Scene

    with pytest.raises(InputError, match=r"atlas_check = .* must be in \[0, 1\)"):
        Scene.load("so1").replace("reduction", atlas_check=value)


def test_the_key_is_out_of_the_prom_hash_and_out_of_the_scene_hash_when_off():
    from aquarom_fenics.io.scene import Scene

    scene = Scene.load("so1")
    on = scene.replace("reduction", atlas_check=0.03)
    assert scene.reduction.atlas_check == 0.0 and on.prom_hash == scene.prom_hash and on.hash != scene.hash
    assert scene.replace("reduction", atlas_check=0.0).hash == scene.hash
