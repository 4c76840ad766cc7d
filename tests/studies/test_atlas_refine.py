"""The atlas refined where a capped radius is smaller than its cell (``reduction/atlas_refine.py``), on a fake
PROM whose capped radius R is a known function of its centre: the cells split only where s R < h, in the shapes
where it is, into as many halvings at once as the node's own R asks for (one build on the way, not one per
halving), every design's leaf holds it within s R of its centre whatever the order of the queries (the cells are
a tree), the depth bound holds and is reported, and a scene without capped radii keeps the regular cells without
a build."""
from types import SimpleNamespace

import numpy as np
import pytest

from aquarom_fenics.reduction.atlas_cover import Cover, center_id
from aquarom_fenics.reduction.atlas_refine import MAX_DEPTH, Refiner, halvings, holds, node_of

S = 0.7
GRID = Cover(("a", "b"), np.zeros(2), np.ones(2), np.array([0.25, 0.25]), np.array([2, 2]),
             np.array([0.25, 0.25]) / S, S)
"""2 × 2 cells of half-width 0.25 over [0, 1]², cut from r = 0.25 / s."""


def capped(change=0.03):
    return SimpleNamespace(reduction=SimpleNamespace(validity_change=change, atlas_change=0.0))


def fake_prom_at(radius, calls):
    """prom_at(centre) → (a PROM whose validity radius is radius(ξ_c), built), counting the calls by centre."""
    def prom_at(center):
        xi = np.array([center["a"], center["b"]])
        calls.append(tuple(xi))
        return SimpleNamespace(validity_radius=np.asarray(radius(xi), dtype=float), xi_center=xi), True
    return prom_at


def thin_near_a1(xi):
    """R_a falls towards a = 1 (a thin design); R_b = r_b everywhere (never below the cell)."""
    return [0.25 / S * (1.0 - 0.6 * xi[0]) ** 2, 0.25 / S]


def test_a_cell_splits_only_in_the_shape_where_the_capped_radius_is_below_it():
    calls = []
    refiner = Refiner(capped(), GRID, prom_at=fake_prom_at(thin_near_a1, calls))
    near = refiner.leaf(np.array([0.1, 0.6]))               # centre a = 0.25: s R_a = 0.25 (1 - 0.15)² < 0.25
    assert near.node.levels == (1, 0) and not near.at_limit and [n.id for n in near.path] == ["0_1"]
    assert near.node.id == "0_1@1_0" and near.node.center(GRID) == pytest.approx([0.125, 0.75])
    far = refiner.leaf(np.array([0.95, 0.1]))
    assert far.node.levels[1] == 0 and far.node.levels[0] >= 3         # thinner: more bisections, in a only
    assert refiner.met[far.path[0]]["split"] == ["a"]
    for leaf in (near, far):
        assert np.all(leaf.node.half_width(GRID) <= S * leaf.radius * (1 + 1e-12))
    assert len(calls) == len(set(calls)) == len(refiner.met)          # each node's PROM built once


def test_every_design_is_held_by_its_leaf_within_s_times_its_capped_radius():
    rng = np.random.default_rng(3)
    refiner = Refiner(capped(), GRID, prom_at=fake_prom_at(thin_near_a1, []))
    for xi in rng.uniform(0, 1, size=(200, 2)):
        leaf = refiner.leaf(xi)
        center, h = leaf.node.center(GRID), leaf.node.half_width(GRID)
        assert holds(GRID, leaf.node, xi) and np.all(np.abs(xi - center) <= h * (1 + 1e-12))
        assert not leaf.at_limit and np.all(h <= S * leaf.radius * (1 + 1e-12))
        assert np.all(np.abs(xi - center) <= leaf.radius)         # so its PROM's own radius holds it
        assert node_of(leaf.node.id, GRID) == leaf.node
        for parent in leaf.path:                                      # every node on the way was too wide
            assert np.any(parent.half_width(GRID) > S * refiner.radii[parent])


def test_the_depth_bound_holds_and_a_leaf_at_it_is_reported():
    calls = []
    refiner = Refiner(capped(), GRID, prom_at=fake_prom_at(lambda xi: [1e-6, 1e-6], calls), max_depth=3)
    leaf = refiner.leaf(np.array([0.3, 0.9]))
    assert leaf.at_limit and leaf.node.levels == (3, 3) and len(leaf.path) == 1 and len(calls) == 2  # one jump
    assert holds(GRID, leaf.node, np.array([0.3, 0.9]))
    assert MAX_DEPTH == Refiner(capped(), GRID, prom_at=fake_prom_at(thin_near_a1, [])).max_depth


def test_without_capped_radii_the_cells_are_the_regular_covers_and_need_no_build():
    calls = []
    refiner = Refiner(capped(0.0), GRID, prom_at=fake_prom_at(lambda xi: [1e-6, 1e-6], calls))
    for xi, cell in (([0.1, 0.6], (0, 1)), ([0.75, 0.2], (1, 0)), ([1.0, 1.0], (1, 1))):
        leaf = refiner.leaf(np.array(xi))
        assert leaf.node.id == center_id(cell) and leaf.node.levels == (0, 0) and not leaf.path
        assert holds(GRID, leaf.node, np.array(xi)) and not holds(GRID, leaf.node, np.array([0.5, 0.5]) + 0.26 *
                                                                  (np.array(cell) * 2 - 1) * -1)
    assert calls == []                                                  # radii from the scene: nothing built


def test_a_radius_asking_for_three_halvings_gets_one_build_on_the_way_not_three():
    calls = []
    eighth = [0.25 / 8 / S, 0.25 / S]                                  # s R_a = h / 8: three halvings in a
    refiner = Refiner(capped(), GRID, prom_at=fake_prom_at(lambda xi: eighth, calls))
    leaf = refiner.leaf(np.array([0.3, 0.9]))
    assert leaf.node.levels == (3, 0) and [n.id for n in leaf.path] == ["0_1"] and len(calls) == 2
    assert leaf.node.id == "4_1@3_0" and holds(GRID, leaf.node, np.array([0.3, 0.9]))
    assert leaf.node.center(GRID) == pytest.approx([0.28125, 0.75]) and not leaf.at_limit
    assert refiner.met[leaf.path[0]]["halvings"] == {"a": 3} and refiner.met[leaf.path[0]]["split"] == ["a"]
    h, most = np.array([0.25, 0.25]), np.array([6, 6])
    assert list(halvings([0.25 / 8 / S * (1 - 1e-9), 1.0], h, S, most)) == [4, 0]   # just below h / 8: four
    assert list(halvings([0.25 / 8 / S * (1 + 1e-9), 0.25 / S], h, S, most)) == [3, 0]
    assert list(halvings([0.0, 0.25 / 2 / S], h, S, np.array([6, 1]))) == [6, 1]      # bounded by the depth left


def thinner_and_thinner(xi):
    """R_a falls steeply towards a = 1, R_b towards b = 0: a part may ask for more halvings than its parent."""
    return [0.25 / S * (1.2 - xi[0]) ** 2, 0.25 / S * (0.2 + xi[1])]


def test_a_designs_leaf_does_not_depend_on_the_order_of_the_queries():
    designs = np.random.default_rng(5).uniform(0, 1, size=(150, 2))
    first = Refiner(capped(), GRID, prom_at=fake_prom_at(thinner_and_thinner, []))
    leaves = [first.leaf(xi) for xi in designs]
    assert any(len(leaf.path) >= 2 for leaf in leaves)                 # a part that asked for more
    assert max(leaf.node.levels[0] for leaf in leaves) >= 4
    for order in (designs[::-1], np.random.default_rng(6).permutation(designs)):
        other = Refiner(capped(), GRID, prom_at=fake_prom_at(thinner_and_thinner, []))
        found = {tuple(xi): other.leaf(xi).node for xi in order}
        assert [found[tuple(xi)] for xi in designs] == [leaf.node for leaf in leaves]
    nodes = {leaf.node for leaf in leaves}
    for xi, leaf in zip(designs, leaves):                              # the leaves do not overlap: one holds ξ
        assert [node for node in nodes if holds(GRID, node, xi)] == [leaf.node]
        assert np.all(leaf.node.half_width(GRID) <= S * leaf.radius * (1 + 1e-12)) and not leaf.at_limit
        assert node_of(leaf.node.id, GRID) == leaf.node
        for parent, below in zip(leaf.path, leaf.path[1:] + [leaf.node]):  # each jump the parent's own R asked
            down = np.asarray(below.levels) - np.asarray(parent.levels)
            assert list(down) == list(halvings(first.radii[parent], parent.half_width(GRID), S,
                                               MAX_DEPTH - np.asarray(parent.levels)))


def tensor(constant, first):
    """A Taylor tensor T(ξ) = T0 + Σ_k ξ_k T1[k] (constant T0, first T1 (p, ...))."""
    return SimpleNamespace(constant=np.asarray(constant, dtype=float), first=np.asarray(first, dtype=float))


def test_atlas_change_caps_the_atlas_radius_by_the_tensors_rate_and_leaves_the_proms_own():
    """R = min(r, c_a / s_k), s_k = max_T ‖∂T/∂ξ_k‖ / ‖T‖ over the internal-force and mass tensors: a PROM whose
    stiffness changes at the relative rate 2 in shape a and 0.1 in b, and whose mass changes at 4 in b, gets
    R_a = 0.05 / 2, R_b = min(0.3, 0.05 / 4) with c_a = 0.05; its own validity radius (the optimisers') is not
    touched, and c_a = 0 leaves R at that radius, without a refinement."""
    from aquarom_fenics.io.scene import scene_from_dict
    from aquarom_fenics.reduction.atlas_refine import atlas_radius, divides

    eye = np.eye(2)
    elastic = SimpleNamespace(linear=tensor(eye, [2.0 * eye, 0.1 * eye]), quadratic=tensor(np.zeros((2, 2, 2)), np.zeros((2, 2, 2, 2))),
                              cubic=tensor(np.zeros((2, 2, 2, 2)), np.zeros((2, 2, 2, 2, 2))))
    inertia = SimpleNamespace(mass=tensor(eye, [0.0 * eye, 4.0 * eye]))
    own = np.array([0.2, 0.3])
    prom = SimpleNamespace(validity_radius=own.copy(), elastic=elastic, inertia=inertia)
    data = {"mesh": {"level": 1}, "reduction": {"atlas_change": 0.05},
            "shapes": {"z_tail": {"bounds": [-0.5, 0.5]}, "y_thin": {"bounds": [-0.15, 0.15]}}}
    scene = scene_from_dict(data, source="<test>")
    assert divides(scene) and scene.reduction.validity_change == 0
    assert atlas_radius(scene, prom) == pytest.approx([0.05 / 2.0, 0.05 / 4.0])
    assert np.array_equal(prom.validity_radius, own)
    off = scene.replace("reduction", atlas_change=0.0)
    assert not divides(off) and np.array_equal(atlas_radius(off, prom), own)
    assert off.prom_hash == scene.prom_hash and off.hash != scene.hash
