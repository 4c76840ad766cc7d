"""Shape (and actuation) optimisation with PROM sensitivities (SPEC §10).

Two algorithms over the same cost and design space (``cost.py``):

* ``paper``: the source's gradient descent with a log-barrier, z ← z - γ W ∇L_b with a diagonal
  W that starts at 1/‖∇L_b(z_0)‖_∞ (so the first step changes the leading parameter by γ) and is
  halved along a direction whose gradient component changes sign or whose bound becomes active,
  the linearised trajectory η ≈ η_c + S (ξ - ξ_c) between PROM builds (so d ≈ d_c + ∇d_c·(z - z_c)),
  and a new PROM when any |z - z_c|_i exceeds ``rebuild_threshold`` or every ``n_rebuild``
  iterations (by the count alone, inside the last PROM's validity radius, that PROM simulated at
  z re-linearises instead). A PROM within half the validity radius of the last PROM whose basis
  was built reuses that basis (``PromBuilder``).
* ``trust-region``: the PROM built at the centre is a nonlinear surrogate (simulated at any z in
  the radius, with its own sensitivities); SciPy's SLSQP solves the surrogate problem with bounds
  and linear constraints inside the radius; a PROM built at the candidate gives the actual
  reduction, ρ = actual / predicted accepts or rejects the step and resizes the radius (by ρ
  only). A candidate the design check refuses is pulled back along its step to the last design
  that meshes (bisection); a direction refused right at the centre becomes a cut of the surrogate
  problem, the radius unchanged.

Both stop by first-order optimality (``cost.first_order``: KKT residual over the active set,
relative to |L|, below ``optimality_tolerance``) at a design where a PROM was built; step size and
``max_iterations`` are safeguards. ``starts`` > 1 repeats the run from Latin-hypercube feasible
starts (:func:`start_points`), all sharing the PROM cache; with ``screen`` the starts are the designs of
least cost among that many, each answered by the PROM atlas (:mod:`~aquarom_fenics.optimization.screen`). With
``atlas`` (paper method) every PROM is the atlas's at the centre of the cell holding the iterate (``PromBuilder``).

The state after every iteration goes to an atomic checkpoint; a resumed run continues from it to
the same result (PROM builds are deterministic).
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.reduction.basis import KEPT_FACTORS
from aquarom_fenics.reduction.kept_model import KEPT_MODEL
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import (CostWeights, DesignSpace, Evaluation, FirstOrder, design_space,
                                              first_order_at, meshable_space)
from aquarom_fenics.optimization.history import Checkpoint, Safeguard
from aquarom_fenics.optimization.paper_method import paper_method
from aquarom_fenics.optimization.prom_builder import PromBuilder, stability_plan
from aquarom_fenics.optimization.trust_region import trust_region

log = logging.getLogger("aquarom")
DEFAULT_MAX_TIME = 24 * 3600.0     # s, wall-time safeguard of one optimisation


@dataclass
class OptimizationResult:
    optimum: np.ndarray
    evaluation: Evaluation                    # PROM prediction at the optimum (from a PROM built there)
    history: list[dict]
    prom_builds: int                          # PROMs built (or taken from the cache) over the run
    stop_reason: str
    space: DesignSpace
    prom_size: int = 0                        # reduced dofs of the last PROM built
    timings: dict = field(default_factory=dict)
    reused: int = 0                           # of the builds, PROMs taken from the cache
    optimality: FirstOrder | None = None      # at the optimum, from the PROM's exact gradient
    converged: bool = False                   # optimality.measure ≤ optimality_tolerance
    basis_reuses: int = 0                     # of the builds, PROMs on the basis of an earlier one
    build_records: list[dict] = field(default_factory=list)   # per build: PromBuilder.records

    @property
    def iterations(self) -> int:
        return int(self.history[-1]["iteration"])

    @property
    def prom_builds_reused_from_cache(self) -> int:
        """``reused`` under its summary.json name."""
        return self.reused

    @property
    def prom_builds_on_an_earlier_basis(self) -> int:
        """``basis_reuses`` under its summary.json name."""
        return self.basis_reuses

    @property
    def optimum_dict(self) -> dict[str, float]:
        """The optimum by name, as summary.json's ``optimum``: {shape name: ξ, ["amplitude": A]}."""
        return self.space.as_dict(self.optimum)


def optimization_space(scene: Scene, fish: Fish) -> DesignSpace:
    """The scene's design space with its bounds pulled in to where the design meshes."""
    space, notes = meshable_space(design_space(scene), fish)
    for note in notes:
        log.warning("design space: %s", note)
    return space


def optimize(scene: Scene, fish: Fish | None = None, weights: CostWeights | None = None,
             checkpoint_path: Path | None = None, resume: bool = False,
             on_iteration=None, write_checkpoint: bool = True, max_time: float = DEFAULT_MAX_TIME,
             start: np.ndarray | None = None, builder: PromBuilder | None = None) -> OptimizationResult:
    """Run the scene's optimiser from ``start`` (the scene's start point by default);
    ``on_iteration(row)`` sees every history row as it is made.

    Every rank reads a checkpoint to resume from; only ranks with ``write_checkpoint`` write one.
    The run stops at first-order optimality, or after ``scene.optimizer.max_iterations``
    iterations or ``max_time`` seconds. ``builder`` gives PROMs and their evaluations (a
    :class:`PromBuilder` of this scene by default).
    """
    fish = fish or load_fish(scene)
    space = builder.space if builder is not None else optimization_space(scene, fish)
    if start is not None:
        space = dataclasses.replace(space, start=np.asarray(start, dtype=float))
    weights = weights or CostWeights()
    method = scene.optimizer.method
    builder = builder or PromBuilder(scene, fish, space)
    checkpoint = Checkpoint(checkpoint_path, scene, method, write=write_checkpoint)
    saved = checkpoint.load() if resume else None
    history = list(saved["history"]) if saved else []
    if saved:
        builder.builds, builder.build_time, builder.solve_time = saved["builds"], saved["build_time"], saved["solve_time"]
        builder.reused, builder.basis_reuses = saved.get("reused", 0), saved.get("basis_reuses", 0)
        builder.records = list(saved.get("build_records", []))
        if saved.get("basis_center") is not None:
            builder.basis_center = np.array(saved["basis_center"])
    started = time.perf_counter() - (history[-1]["wall_time"] if history else 0.0)
    algorithm = {"paper": paper_method, "trust-region": trust_region}[method]
    log.info("stability of the designs: %s", stability_plan(scene))
    safeguard = Safeguard(started, max_time)
    finished = saved["state"].get("finished") if saved else None
    try:
        if finished is not None:      # stopped before (interrupted in the FOM check): the same optimum, no new rows
            evaluation = Evaluation(np.array(finished["optimum"]), finished["cost"], np.array(finished["gradient"]),
                                    finished["distance"], np.array(finished["distance_gradient"]))
            optimum, reason, builder.last_size = evaluation.z, finished["reason"], finished["prom_size"]
        else:
            optimum, evaluation, reason = algorithm(scene, space, builder, weights, history, checkpoint,
                                                    saved["state"] if saved else None, safeguard,
                                                    on_iteration or (lambda row: None))
            checkpoint.finish(optimum, evaluation, reason, history, builder)
    finally:
        KEPT_FACTORS.release()      # the builds' K_0 factorisation and model: not needed by the FOM check that follows
        KEPT_MODEL.release()
    timings = {"prom_builds": builder.build_time, "prom_solves": builder.solve_time,
               "tail_screens": builder.screen_time, "total": time.perf_counter() - started}
    optimality = first_order_at(scene, space, evaluation)
    log.info("optimisation (%s) stopped: %s; first-order measure %.2e; %d PROM builds (%d reused from the cache, "
             "%d on an earlier basis), %.1f s", method, reason, optimality.measure, builder.builds, builder.reused,
             builder.basis_reuses, timings["total"])
    return OptimizationResult(optimum, evaluation, history, builder.builds, reason, space, builder.last_size, timings,
                              builder.reused, optimality, optimality.measure <= scene.optimizer.optimality_tolerance,
                              builder.basis_reuses, builder.records)


def start_points(space: DesignSpace, count: int, seed: int, meshes) -> list[np.ndarray]:
    """The space's start, then ``count - 1`` Latin-hypercube points of the box (scrambled, seeded)
    that satisfy the linear constraints and the design check ``meshes(z)``.

    Draws at most 20 batches of ``count`` points; raises InputError if too few qualify.
    """
    points = [space.start.copy()]
    sampler = qmc.LatinHypercube(d=len(space.names), seed=seed)
    for _ in range(20):
        if len(points) == count:
            break
        for unit in sampler.random(count):
            z = space.lower + unit * (space.upper - space.lower)
            if len(points) < count and space.is_feasible(z) and meshes(z):
                points.append(z)
    if len(points) < count:
        raise InputError(f"only {len(points)} of [optimizer] starts = {count} feasible, meshable start points found "
                         f"in 20 batches of Latin-hypercube samples; lower starts")
    return points
