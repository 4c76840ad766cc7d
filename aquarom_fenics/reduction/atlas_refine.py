"""The atlas's cells refined where a PROM's capped radius is smaller than its cell.

With ``[reduction] validity_change`` = c > 0 a PROM's radius is capped at its centre, R_k ≤ c / s_k
(``reductor.validity_radii``), known only once the PROM is built. A cell of the regular cover
(:mod:`~aquarom_fenics.reduction.atlas_cover`, half-width h_k ≤ s r_k) whose PROM has

    s R_k < h_k   in some shapes k   (s = the atlas's radius scale, the rule of the regular cells)

is divided at once into the 2^{D_k} parts per shape its own PROM asks for, D_k the smallest number of halvings
with h_k / 2^{D_k} ≤ s R_k (0 where s R_k ≥ h_k), and the part holding the design is built and judged the same
way (it may ask for more). The division of a node is a function of its own PROM only, so the cells form a tree:
a design's leaf does not depend on the order of the queries. A node is the base cell's grid halved L_k times in
shape k: its indices j_k on the grid of half-width h_k / 2^{L_k},

    c_k = lower_k + (2 j_k + 1) h_k / 2^{L_k},   part: L_k + D_k,   j_k ← ⌊(ξ_k - lower_k) 2^{L_k + D_k} / (2 h_k)⌋

(clipped to the node's parts j_k 2^{D_k} … (j_k + 1) 2^{D_k} - 1). A node that needs no division is a leaf:
every design in it is within h ≤ s R ≤ R of its centre, so its PROM answers every design of the cell, as a
regular cell's does. A shape is halved at most :data:`MAX_DEPTH` times (D_k is cut to reach it at most): a node
that would divide only shapes at that depth is a leaf *at the depth limit*; its PROM answers a design only
within its own radius R (``ReducedModel.refuse_outside_radius``), and callers report such leaves. On a scene
whose radii are not capped (R = r ≥ h / s) every base cell is a leaf: the regular atlas, its cells, names and
cache entries, unchanged.

With ``[reduction] atlas_check`` = τ > 0 a node that its radius leaves whole is also checked
(:mod:`~aquarom_fenics.reduction.atlas_check`): its PROM against the PROMs at two of its corners; where the gap
exceeds τ the node is halved once in every shape with a width (D_k = 1, cut at :data:`MAX_DEPTH`) and the part
holding the design is judged again. A node that fails the check with every shape at the depth limit is a leaf
whose check failed (``Leaf.check``, ``met[node]["check"]``): its PROM still answers its cell (h ≤ s R), and
callers report it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from aquarom_fenics.errors import InputError
from aquarom_fenics.reduction.atlas_check import CellCheck, check_cell, vertex
from aquarom_fenics.reduction.atlas_cover import BUILT_HERE, Cover, cell_of, center_id, center_prom

MAX_DEPTH = 6
"""Most bisections of a base cell per shape (a half-width of h / 64): on the CO scene the capped radius falls to
R = 0.0045 in y_ellipse at the corner (validity_change 0.035), s R = 0.0032 ≥ h / 32 = 0.0026: five bisections
(docs/devlog.md, "the atlas for capped radii")."""


@dataclass(frozen=True)
class Node:
    """A cell of the refined atlas: per shape its halvings L_k of the base cell and index j_k on that level's grid."""

    index: tuple
    levels: tuple

    @property
    def id(self) -> str:
        """The base cell's name for an unrefined cell (``atlas_cover.center_id``), else "j_0_j_1…@L_0_L_1…"."""
        if not any(self.levels):
            return center_id(self.index)
        return center_id(self.index) + "@" + "_".join(str(int(level)) for level in self.levels)

    def half_width(self, grid: Cover) -> np.ndarray:
        return grid.half_width / 2.0 ** np.asarray(self.levels)

    def center(self, grid: Cover) -> np.ndarray:
        return grid.lower + (2 * np.asarray(self.index) + 1) * self.half_width(grid)

    def base_cell(self) -> tuple:
        """The regular cover's cell holding this node: j_k // 2^{L_k}."""
        return tuple(int(j) >> int(level) for j, level in zip(self.index, self.levels))


def node_of(name: str, grid: Cover) -> Node:
    """The node of a name (:attr:`Node.id`) on ``grid``."""
    cell, _, levels = name.partition("@")
    index = tuple(cell_of(cell, grid))
    return Node(index, tuple(int(level) for level in levels.split("_")) if levels else (0,) * len(index))


def base_node(cell) -> Node:
    cell = tuple(int(i) for i in cell)
    return Node(cell, (0,) * len(cell))


def holds(grid: Cover, node: Node, xi: np.ndarray) -> bool:
    """Whether design ξ is in ``node``'s cell: its index on the node's grid (clipped to the base cell, as the
    regular cover clips to the box) equals the node's."""
    return descendant_index(grid, node.base_cell(), np.asarray(node.levels), np.atleast_1d(xi)) == node.index


def descendant_index(grid: Cover, cell: tuple, levels: np.ndarray, xi: np.ndarray) -> tuple:
    """Index of ξ on the grid of ``levels`` bisections: ⌊(ξ - lower) / (2 h / 2^L)⌋, within the base cell
    that holds ξ (``Cover.cells``) and equal to ``cell`` only if that cell is ``cell``."""
    own = grid.cells(xi[None, :])[0]
    if tuple(int(i) for i in own) != tuple(cell):
        return ()
    return index_within(grid, levels, xi, cell, levels)


def index_within(grid: Cover, levels: np.ndarray, xi: np.ndarray, index: tuple, down: np.ndarray) -> tuple:
    """Index of ξ on the grid of ``levels`` halvings, ⌊(ξ - lower) / (2 h / 2^L)⌋, clipped to the 2^D parts
    (D = ``down``) of the cell ``index`` of the grid D halvings coarser: j_k 2^{D_k} … (j_k + 1) 2^{D_k} - 1."""
    width = 2 * grid.half_width / 2.0 ** levels
    raw = np.floor(np.divide(xi - grid.lower, width, out=np.zeros_like(xi), where=width > 0)).astype(int)
    first = np.asarray(index) * 2 ** down
    return tuple(int(j) for j in np.clip(raw, first, first + 2 ** down - 1))


def splits(radius: np.ndarray, half_width: np.ndarray, scale: float) -> np.ndarray:
    """The shapes where the cell is wider than the atlas's radius s R of its PROM: h_k > s R_k."""
    radius = np.asarray(radius, dtype=float)
    return (half_width > 0) & (half_width > scale * radius * (1 + 1e-12))


def halvings(radius: np.ndarray, half_width: np.ndarray, scale: float, most: np.ndarray) -> np.ndarray:
    """Per shape the fewest halvings D_k of the cell with h_k / 2^{D_k} ≤ s R_k (0 where the cell is not wider
    than s R_k), at most ``most``_k: D_k = ⌈log₂(h_k / (s R_k))⌉, checked against :func:`splits`."""
    radius, half_width = np.asarray(radius, dtype=float), np.asarray(half_width, dtype=float)
    wide = splits(radius, half_width, scale)
    most = np.maximum(np.asarray(most, dtype=int), 0)
    with np.errstate(divide="ignore"):
        ratio = np.where(wide, half_width / np.maximum(scale * radius * (1 + 1e-12), 1e-300), 1.0)
    count = np.where(wide, np.ceil(np.log2(np.minimum(ratio, 2.0 ** 1000))), 0).astype(int)
    while np.any(fix := wide & (count < most) & splits(radius, half_width / 2.0 ** count, scale)):
        count = count + fix                                         # log₂ rounded below the boundary
    while np.any(fix := (count > 1) & ~splits(radius, half_width / 2.0 ** (count - 1), scale)):
        count = count - fix                                         # or above it
    return np.minimum(count, most)


def part(grid: Cover, node: Node, down: np.ndarray, xi: np.ndarray) -> Node:
    """The part of ``node`` holding ξ when shape k is halved ``down``_k more times: ξ's index on the grid of
    L_k + D_k halvings, clipped to the node's parts (:func:`index_within`)."""
    down = np.asarray(down, dtype=int)
    levels = np.asarray(node.levels) + down
    return Node(index_within(grid, levels, xi, node.index, down), tuple(int(level) for level in levels))


class RefusedNode(InputError):
    """No PROM at a node's centre (the design check refuses its mesh, for one): ``node`` names it."""

    def __init__(self, node: Node, message: str):
        super().__init__(message)
        self.node = node


@dataclass
class Leaf:
    """The node answering a design, its PROM's radius R, the nodes split on the way and whether the depth
    limit stopped its refinement (``at_limit``: its PROM answers only within R)."""

    node: Node
    radius: np.ndarray
    path: list
    at_limit: bool
    check: CellCheck | None = None      # the atlas check of the leaf (None: not checked); failed only at the depth limit

    def answers(self, grid: Cover, xi: np.ndarray) -> bool:
        """Whether the leaf's PROM answers ξ of its cell: always (h ≤ s R), unless the leaf is at the depth limit;
        then only within its radius, |ξ_k - c_k| ≤ R_k."""
        if not self.at_limit:
            return True
        gap = np.abs(np.asarray(xi, dtype=float) - self.node.center(grid))
        return bool(np.all(gap <= self.radius * (1 + 1e-12)))


def met_status(met: dict) -> str:
    """A node's status from its ``Refiner.met`` record: "refused: …", "built" or "from the cache"."""
    return f"refused: {met['refused']}" if "refused" in met else "built" if met["built"] else "from the cache"


class Refiner:
    """Finds the leaf of designs, building (or reading from the PROM cache) the PROM of every node on the way.

    ``prom_at(center_dict)`` → (PROM, built): :func:`~aquarom_fenics.reduction.atlas_cover.center_prom` by
    default; the radius of every node met is kept (``radii``, by node), and ``met`` records each node's first
    visit: its id, whether it was built, its split, its time. Without capped radii no PROM is needed to find a
    leaf (the base cell). ``distances(prom, scene, xis, gradient)`` → (d, ∂d/∂ξ): the reduced solves of the atlas
    check (``dynamics.batched.reduced_distances``, handed down from the layers above; needed only with
    ``[reduction] atlas_check`` > 0)."""

    def __init__(self, scene, grid: Cover, fish=None, prom_at=None, max_depth: int = MAX_DEPTH, distances=None):
        self.scene, self.grid, self.fish, self.max_depth = scene, grid, fish, max_depth
        self.prom_at = prom_at or (lambda center: center_prom(scene, center, fish))
        self.distances = distances      # the atlas check's reduced solves (dynamics.batched.reduced_distances)
        self.tolerance = check_tolerance(scene)
        self.checks: dict[Node, CellCheck] = {}
        self.radii: dict[Node, np.ndarray] = {}
        self.refused: dict[Node, str] = {}
        self.met: dict[Node, dict] = {}
        self.last = None            # (node, PROM) of the last node built or read

    def center_dict(self, node: Node) -> dict:
        return dict(zip(self.grid.names, node.center(self.grid).tolist()))

    @property
    def capped(self) -> bool:
        """Whether PROM radii are capped at their centres (``[reduction] validity_change`` or ``atlas_change``
        > 0); if not, R = r."""
        return capped(self.scene)

    def radius(self, node: Node) -> np.ndarray:
        """R of the PROM at the node's centre: the scene's r when radii are not capped (no build: every base cell
        is a leaf, h ≤ s r), else the built (or cached) PROM's, kept once met."""
        if not self.capped:
            return self.grid.radius
        if node not in self.radii:
            self.radii[node] = atlas_radius(self.scene, self.prom(node))
        return self.radii[node]

    def prom(self, node: Node):
        """The PROM at the node's centre: the one met last, or built or read from the PROM cache (its first
        visit recorded in ``met``: built or not, wall and thread CPU time [s], the worker's atlas builds by then);
        :class:`RefusedNode` where it cannot be built."""
        if node in self.refused:
            raise RefusedNode(node, self.refused[node])
        if self.last is not None and self.last[0] == node:
            return self.last[1]
        started, cpu = time.perf_counter(), time.thread_time()
        try:
            prom, built = self.prom_at(self.center_dict(node))
        except InputError as refused:
            self.refused[node] = str(refused)
            self.met.setdefault(node, {"id": node.id, "built": False, "refused": str(refused),
                                       "time_s": time.perf_counter() - started, "cpu_s": time.thread_time() - cpu})
            raise RefusedNode(node, str(refused)) from None
        self.last = (node, prom)
        self.met.setdefault(node, {"id": node.id, "built": bool(built), "time_s": time.perf_counter() - started,
                                   "cpu_s": time.thread_time() - cpu, "builds_in_worker": BUILT_HERE[0]})
        return prom

    def leaf(self, xi: np.ndarray, cell=None) -> Leaf:
        """Descend from ξ's base cell (or ``cell``) to the leaf holding ξ, each node divided at once as its own
        PROM asks (:func:`halvings`; ``met``'s ``split`` and ``halvings`` record it); :class:`RefusedNode` where a
        node's PROM cannot be built."""
        xi = np.asarray(xi, dtype=float)
        node = base_node(self.grid.cells(xi[None, :])[0] if cell is None else cell)
        path = []
        while True:
            radius = self.radius(node)
            need = splits(radius, node.half_width(self.grid), self.grid.scale)
            down = halvings(radius, node.half_width(self.grid), self.grid.scale,
                            self.max_depth - np.asarray(node.levels))
            check = None
            if not down.any() and self.tolerance > 0:
                check = self.check(node)
                if not check.passed:
                    down = self.check_halvings(node)
            if not down.any():
                return Leaf(node, radius, path, bool(need.any()), check)
            self.met[node]["split"] = [name for name, d in zip(self.grid.names, down) if d]
            self.met[node]["halvings"] = {name: int(d) for name, d in zip(self.grid.names, down) if d}
            path.append(node)
            node = part(self.grid, node, down, xi)


    def check(self, node: Node) -> CellCheck:
        """The atlas check of a node (:func:`~aquarom_fenics.reduction.atlas_check.check_cell`), made once: its PROM
        against the PROMs at its two corners along its distance gradient's signs, those read from the PROM cache
        or built (``met[node]["check"]`` records it)."""
        if node not in self.checks:
            if self.distances is None:
                raise ValueError("the atlas check needs the reduced solves: Refiner(..., distances="
                                 "dynamics.batched.reduced_distances)")
            prom = self.prom(node)
            depth = max(MAX_DEPTH, self.max_depth)       # one grid of vertices for every node

            def corners_of(signs):
                return np.array([vertex(self.grid.lower, self.grid.half_width, node.index, node.levels, sign * signs,
                                        depth) for sign in (1, -1)])

            def corner_prom(corner):
                return self.prom_at(dict(zip(self.grid.names, corner.tolist())))

            started = time.perf_counter()
            self.checks[node] = check_cell(prom, self.scene, node.center(self.grid), corners_of, corner_prom,
                                           self.tolerance, self.distances)
            self.met[node]["check"] = self.checks[node].record(self.grid.names) | {
                "time_s": time.perf_counter() - started}
        return self.checks[node]

    def check_halvings(self, node: Node) -> np.ndarray:
        """D_k = 1 in every shape with a width below the depth limit: a node that failed its check is halved
        once everywhere it can be (0 everywhere at the limit: a leaf whose check failed)."""
        room = (self.grid.half_width > 0) & (np.asarray(node.levels) < self.max_depth)
        return room.astype(int)


def check_tolerance(scene) -> float:
    """τ of ``[reduction] atlas_check`` (0: off; a scene object without the key: off)."""
    return float(getattr(scene.reduction, "atlas_check", 0.0))


def capped(scene) -> bool:
    """Whether PROM radii are capped for the atlas: ``[reduction] validity_change`` or ``atlas_change`` > 0."""
    return scene.reduction.validity_change > 0 or scene.reduction.atlas_change > 0


def divides(scene) -> bool:
    """Whether the atlas's cells may be divided: where their PROMs' radii are capped (:func:`capped`) or where the
    atlas check finds a cell's PROM too far from its corners' (``[reduction] atlas_check`` > 0)."""
    return capped(scene) or check_tolerance(scene) > 0


def atlas_radius(scene, prom) -> np.ndarray:
    """R of a PROM in the atlas: its validity radius (capped by ``[reduction] validity_change``), and with
    ``[reduction] atlas_change`` = c_a > 0 also R_k ≤ c_a / s_k, s_k its tensors' largest relative ξ_k-derivative
    (``reductor.validity_radii``'s rule): the atlas's cells divided where the tensors change fast, the PROM's own
    radius, which the optimisers use, unchanged."""
    from aquarom_fenics.reduction.reductor import validity_radii

    radius = np.asarray(prom.validity_radius, dtype=float)
    change = scene.reduction.atlas_change
    if change <= 0:
        return radius
    return np.minimum(radius, validity_radii(scene, prom.elastic, prom.inertia, radius.size, change=change))


def leaf_record(grid: Cover, leaf: Leaf) -> dict:
    """What atlas.json and the optimiser's build records say of a leaf: its levels, half-width, its PROM's
    radius R and s R, and the depth limit."""
    return {"levels": list(leaf.node.levels), "half_width": dict(zip(grid.names, leaf.node.half_width(grid).tolist())),
            "prom_radius": dict(zip(grid.names, leaf.radius.tolist())), "at_depth_limit": leaf.at_limit,
            "split_on_the_way": [node.id for node in leaf.path]}
