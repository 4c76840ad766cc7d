"""What a PROM sweep on a scene with capped radii will build, told before it runs (``sweep --dry-run``).

Where ``[reduction] validity_change`` caps the PROMs' radii, a design's cell is found by descending from its
regular cell, each node divided as its own PROM's radius asks (:mod:`~aquarom_fenics.reduction.atlas_refine`),
so the builds are known only as the PROMs are. The plan descends through the PROMs the PROM cache holds
already (read, never built) and stops each design's way at the first node not in the cache. Then

    builds ≥ N_stop                                (every node a way stops at is built),
    builds ≤ Σ_stop (1 + n_stop Σ_k (D - L_k))      (below a stop node each node of a design's way has at least
                                                     one more halving, at most D = MAX_DEPTH per shape),

N_stop the distinct stop nodes, n_stop the designs whose ways stop at one, L_k its halvings in shape k. Designs
whose way ends at a leaf of the cache need no build.

With ``[reduction] atlas_check`` > 0 (:mod:`~aquarom_fenics.reduction.atlas_check`) the plan cannot know the gaps
without the corners' reduced solves, which it does not make: a way stops at the first node not in the cache, or
at a cached node its radius leaves whole (its check unknown). Each node checked costs up to 3 builds (its own PROM
and two corners', fewer where the cache holds them or cells share a corner), and a check that fails halves every
shape, so

    builds ≥ N_stop,    builds ≤ 3 Σ_stop (1 + n_stop Σ_k (D - L_k)) + Σ_unchecked (2 + 3 n Σ_k (D - L_k)).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aquarom_fenics.reduction.atlas_cover import cover
from aquarom_fenics.reduction.atlas_refine import (MAX_DEPTH, Refiner, RefusedNode, base_node, check_tolerance,
                                                   halvings, part)


@dataclass
class DivisionPlan:
    """The capped atlas's builds for a sweep's designs as far as the PROM cache tells them."""

    designs: int
    answered_from_cache: int     # designs whose leaf's PROM (and every node's on the way) is in the cache
    leaves_in_cache: int         # distinct such leaves
    read: int                    # nodes whose PROM the cache holds, met on the ways down
    refused: int                 # designs whose way meets a node the cache records as refused
    to_build: int                # distinct nodes not in the cache where ways stop: builds at least
    at_most: int                 # builds at most (module docstring)
    unchecked: int = 0           # with the atlas check: designs whose way reaches a cached node whose check is not known


class _NotStored(Exception):
    """A node's PROM is not in the cache (the plan's look-up builds nothing)."""


def division_plan(scene, designs: list[dict], stored=None, max_depth: int = MAX_DEPTH) -> DivisionPlan:
    """The plan of ``designs`` (dicts by shape name) on ``scene``'s capped atlas; ``stored(ξ_c)`` → the cached
    PROM at centre ξ_c or None (``reduction.cache.stored_prom`` by default)."""
    grid = cover(scene)
    if stored is None:
        from aquarom_fenics.reduction.cache import stored_prom

        stored = lambda xi: stored_prom(scene, xi)                          # noqa: E731

    def prom_at(center: dict):
        prom = stored(np.array([center[name] for name in grid.names], dtype=float))
        if prom is None:
            raise _NotStored
        return prom, False

    refiner = Refiner(scene, grid, prom_at=prom_at, max_depth=max_depth)
    checking = check_tolerance(scene) > 0
    stops: dict = {}
    unchecked: dict = {}
    leaves, answered, refused = set(), 0, 0
    for design in designs:
        xi = np.array([design[name] for name in grid.names], dtype=float)
        node = base_node(grid.cells(xi[None, :])[0])
        while True:
            if node in stops:
                stops[node] += 1
                break
            try:
                if checking:
                    refiner.prom(node)                      # the node's own PROM, cached or a stop
                radius = refiner.radius(node)
            except _NotStored:
                stops[node] = 1
                break
            except RefusedNode:
                refused += 1
                break
            down = halvings(radius, node.half_width(grid), grid.scale, max_depth - np.asarray(node.levels))
            if not down.any() and checking:
                unchecked[node] = unchecked.get(node, 0) + 1
                break
            if not down.any():
                leaves.add(node)
                answered += 1
                break
            node = part(grid, node, down, xi)
    below = lambda node, count: count * int(np.sum(max_depth - np.asarray(node.levels)))     # noqa: E731
    bound = sum(1 + below(node, count) for node, count in stops.items())
    if checking:
        bound = 3 * bound + sum(2 + 3 * below(node, count) for node, count in unchecked.items())
    read = len(refiner.radii) if not checking else len({node for node in refiner.met if "refused" not in refiner.met[node]})
    return DivisionPlan(len(designs), answered, len(leaves), read, refused, len(stops), bound,
                        sum(unchecked.values()))
