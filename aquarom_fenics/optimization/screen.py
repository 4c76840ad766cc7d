"""The multi-start screen (``[optimizer] screen = N``): the starts chosen by the optimiser's cost among N
designs, each answered by the PROM atlas.

The N screened designs are the space's start and N - 1 seeded Latin-hypercube designs that satisfy the
linear constraints and the design check (:func:`~aquarom_fenics.optimization.optimize.start_points`). At
each the cost the optimisers minimise,

    L(z) = -w_1 d(z) + w_2 α E(z)      (:func:`~aquarom_fenics.optimization.cost.weighted_cost`; E = A², or
                                        the muscles' mean positive power P̄ with effort "power"),

with d (and P̄) from the PROM of the atlas centre whose cell holds the shapes of z
(:mod:`~aquarom_fenics.reduction.atlas_cover`: cells of half-width h ≤ s r, inside which the PROM stayed
within 3 % of the FOM in distance; bisected where a capped radius needs it, ``atlas_refine``). The designs of
one centre are integrated together (one ``simulate_batch`` without sensitivities; one run per design with
effort "power", whose P̄ needs the single run's trajectory), one task per regular cell on the multi-start's
pool; the centres' PROMs come from the PROM cache, shared with ``sweep --model prom`` on the same scene. The
``starts`` designs of least L (on a tie the one drawn first) start the optimisations. A design whose reduced
run stops, or whose centre has no PROM (its mesh refused there), or which a cell at the depth limit holds
beyond its PROM's radius, ranks last (L = +∞). The constraints need no penalty: a design outside them is
never drawn. The stability a PROM build judges (Floquet) is not screened: a start found unstable is
refused by its first build as an unscreened start would be.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from aquarom_fenics.dynamics.batched import reduced_distances, simulate_batch
from aquarom_fenics.errors import SolverError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import (CostWeights, DesignSpace, cost_value, counts_power, scene_at,
                                              weighted_cost)
from aquarom_fenics.optimization.optimize import start_points
from aquarom_fenics.reduction.atlas_cover import assign, center_prom, cover
from aquarom_fenics.reduction.atlas_refine import Refiner, RefusedNode, met_status

log = logging.getLogger("aquarom")


@dataclass(frozen=True)
class ScreenTask:
    """The screened designs of one atlas cell: their positions among the screened and their z (K, n)."""

    cell: tuple
    positions: tuple
    designs: np.ndarray
    scene: Scene
    space: DesignSpace
    weights: CostWeights


@dataclass
class Screen:
    """The screen's outcome: the screened designs (N, n), their cost L (N,), the chosen positions (least L
    first) and a record per centre (build or cache, times)."""

    designs: np.ndarray
    costs: np.ndarray
    chosen: np.ndarray
    centres: list
    time_s: float

    @property
    def starts(self) -> list[np.ndarray]:
        return [self.designs[k].copy() for k in self.chosen]

    def report(self, space: DesignSpace) -> dict:
        """summary.json's ``multistart.screen``: sizes, the atlas's builds and times, the chosen designs."""
        built = [record for record in self.centres if record["status"] == "built"]
        return {"designs": len(self.costs), "finite_costs": int(np.isfinite(self.costs).sum()),
                "centres": len(self.centres), "built": len(built),
                "from_the_cache": sum(record["status"] == "from the cache" for record in self.centres),
                "build_time_s": sum(record["build_time_s"] for record in built),
                "solve_time_s": sum(record["solve_time_s"] for record in self.centres), "time_s": self.time_s,
                "chosen": [{"screened": int(k) + 1, "design": space.as_dict(self.designs[k]),
                            "cost": float(self.costs[k])} for k in self.chosen]}


def screen_tasks(scene: Scene, space: DesignSpace, weights: CostWeights, designs: np.ndarray) -> list[ScreenTask]:
    """One task per atlas cell holding screened designs (cells in the order first met)."""
    grid = cover(scene)
    shapes = [dict(zip(grid.names, z[: space.n_shapes].tolist())) for z in designs]
    return [ScreenTask(cell, tuple(members), designs[members], scene, space, weights)
            for cell, members in assign(grid, shapes).items()]


def screen_center(task: ScreenTask) -> dict:
    """The costs of a cell's designs from the PROMs of the atlas leaves holding them (the cell itself unless a
    capped radius splits it: ``atlas_refine``), and a record per node met (a worker's task). A design at a leaf
    of the depth limit beyond its PROM's radius, or whose way meets a node without a PROM, costs +∞."""
    grid = cover(task.scene)
    refiner = Refiner(task.scene, grid, prom_at=lambda center: center_prom(task.scene, center),
                      distances=reduced_distances)
    costs, leaves = np.full(len(task.positions), np.inf), {}
    for k, z in enumerate(task.designs):
        try:
            leaf = refiner.leaf(z[: task.space.n_shapes], task.cell)
        except RefusedNode:
            continue
        if leaf.answers(grid, z[: task.space.n_shapes]):
            leaves.setdefault(leaf.node, []).append(k)
    solved = {}
    for node, members in leaves.items():
        try:
            prom = refiner.prom(node)
        except RefusedNode:
            continue
        started = time.perf_counter()
        costs[members] = batch_costs(prom, task.scene, task.space, task.designs[members], task.weights)
        solved[node] = {"designs": len(members), "solve_time_s": time.perf_counter() - started}
    records = {node: {"id": node.id, "center": refiner.center_dict(node), "designs": 0,
                      "status": met_status(met), "build_time_s": met["time_s"],
                      "solve_time_s": 0.0} | solved.get(node, {}) for node, met in refiner.met.items()}
    return {"costs": costs.tolist(), "records": list(records.values())}


def batch_costs(prom, scene: Scene, space: DesignSpace, designs: np.ndarray, weights: CostWeights) -> np.ndarray:
    """L at every row z of ``designs`` (K, n) from the PROM, without gradients; +∞ where its run stops or L
    is not finite. One ``simulate_batch`` (each design's amplitude and gait), or with effort "power" one
    :func:`~aquarom_fenics.optimization.cost.cost_value` per design."""
    designs = np.atleast_2d(np.asarray(designs, dtype=float))
    if counts_power(scene, space):
        return np.array([_single_cost(prom, scene, space, z, weights) for z in designs])
    amplitudes = designs[:, space.amplitude_index] if space.with_amplitude else None
    scenes = [scene_at(scene, space, z) for z in designs] if space.n_gait else None
    batch = simulate_batch(prom, scene, designs[:, : space.n_shapes], amplitudes=amplitudes, scenes=scenes)
    costs = np.array([weighted_cost(space, weights, z, float(batch.distance[b]))[0] if batch.completed[b] else np.inf
                      for b, z in enumerate(designs)])
    return np.where(np.isfinite(costs), costs, np.inf)


def _single_cost(prom, scene: Scene, space: DesignSpace, z: np.ndarray, weights: CostWeights) -> float:
    try:
        return cost_value(prom, scene, space, z, weights)
    except SolverError:
        return np.inf


def screen(scene: Scene, space: DesignSpace, weights: CostWeights, meshes, pool=None) -> Screen:
    """Screen ``[optimizer] screen`` designs (``meshes(z)``: the design check) and choose the ``starts`` of
    least cost; the cells' tasks on ``pool`` (a backend of :mod:`aquarom_fenics.parallel`), or here with one
    BLAS thread (as on a worker) when None."""
    from aquarom_fenics.parallel import run_all, worker_threads

    settings = scene.optimizer
    started = time.perf_counter()
    designs = np.array(start_points(space, settings.screen, settings.seed, meshes))
    tasks = screen_tasks(scene, space, weights, designs)
    costs, centres = np.full(len(designs), np.inf), []
    if pool is None:
        with worker_threads():
            answers = [(task, screen_center(task), None) for task in tasks]
    else:
        answers = run_all(pool, screen_center, tasks, key=lambda task: task.cell)
    for task, answer, error in answers:
        if error is not None:
            raise error
        costs[list(task.positions)] = answer["costs"]
        centres.extend(answer["records"])
    chosen = np.argsort(costs, kind="stable")[: settings.starts]
    outcome = Screen(designs, costs, chosen, centres, time.perf_counter() - started)
    report = outcome.report(space)
    log.info("multi-start screen: %d designs at %d atlas centre(s) (%d built, %d from the cache), %.1f s; the %d "
             "start(s) of least cost %s", report["designs"], report["centres"], report["built"],
             report["from_the_cache"], outcome.time_s, settings.starts,
             ", ".join(f"{costs[k]:.4g}" for k in chosen))
    if not np.isfinite(costs[chosen]).all():
        log.warning("multi-start screen: only %d of %d screened designs have a finite cost; the others start "
                    "anyway", report["finite_costs"], report["designs"])
    return outcome


def multistart_starts(scene: Scene, space: DesignSpace, weights: CostWeights, meshes,
                      pool=None) -> tuple[list[np.ndarray], dict | None]:
    """The multi-start's starts and the screen's report: without a screen :func:`start_points` (the start and
    ``starts`` - 1 Latin-hypercube designs) and None; with one the :func:`screen`'s choice."""
    settings = scene.optimizer
    if not settings.screen:
        return start_points(space, settings.starts, settings.seed, meshes), None
    chosen = screen(scene, space, weights, meshes, pool)
    return chosen.starts, chosen.report(space)
