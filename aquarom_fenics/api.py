"""The Python API for scripted studies: scenes in, plain dataclasses and numpy arrays out.

    from aquarom_fenics.api import Scene, simulate, build_prom, optimize

    scene = Scene.load("so1").replace("mesh", level=1)
    fom = simulate(scene, {"y_thin": 0.1})                   # SimulationResult (FOM)
    prom = build_prom(scene)                                  # ReducedModel at the start values
    reduced = simulate(scene, {"y_thin": 0.02}, model="prom", prom=prom, sensitivities=True)
    result, check = optimize(scene, "results/my-so1")       # OptimizationResult, FomCheck
    result.optimum_dict, check.start_distance, check.optimal_distance   # names as in summary.json

Every model runs the scene's start values for a shape not given in ``xi`` (as the CLI does).
A shape field of one's own: :func:`register_shape_field` (a name, U(X) and ∇U(X)), then name it in
the scene's ``[shapes]``; :func:`check_shape_fields` runs the Taylor test of its gradient.
Messages: :func:`aquarom_fenics.set_log_level` ("info" for details; warnings only by default).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.optimization.cost import CostWeights
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.dynamics.reduced_dynamics import ReducedResult, attach_strains, simulate_reduced
from aquarom_fenics.reduction.reductor import build_prom as _build_prom
from aquarom_fenics.io.scene import Scene, scene_from_dict
from aquarom_fenics.dynamics.simulate import SimulationResult, simulate_fom
from aquarom_fenics.optimization.optimize import DEFAULT_MAX_TIME, OptimizationResult
from aquarom_fenics.studies.study import FomCheck, run_optimization
from aquarom_fenics.errors import InputError, Interrupted, SolverError
from aquarom_fenics.geometry.shape_registry import RegisteredField, register_shape_field, unregister_shape_field
from aquarom_fenics.verification.check import CheckResult

__all__ = ["Scene", "Fish", "load_fish", "simulate", "build_prom", "optimize", "start_design", "CostWeights",
           "ReducedModel", "SimulationResult", "ReducedResult", "OptimizationResult", "FomCheck", "scene_from_dict",
           "register_shape_field", "unregister_shape_field", "RegisteredField", "check_shape_fields", "CheckResult"]


def check_shape_fields(scene: Scene, names: list[str] | None = None, fish: Fish | None = None) -> list[CheckResult]:
    """The Taylor test of each shape field's gradient against its value (the rows ``0`` of
    ``aquarom check``) at the quadrature points of the scene's mesh: the fields ``names``, registered
    or of the catalogue (default: the scene's shapes). ``result.passed``, ``result.note`` say how it went."""
    from aquarom_fenics.verification.shape_fields import check_shape_gradients

    return list(check_shape_gradients(fish or load_fish(scene), names))


def start_design(scene: Scene, xi: dict[str, float] | None = None) -> dict[str, float]:
    """The design a call runs: the scene's start value of every shape, overridden by ``xi``."""
    return {shape.name: shape.start for shape in scene.shapes} | (xi or {})


def build_prom(scene: Scene, xi: dict[str, float] | None = None, fish: Fish | None = None) -> ReducedModel:
    """The scene's PROM centred on ``xi`` (default: the scene's start values)."""
    center = {s.name: s.start for s in scene.shapes} | (xi or {})
    return _build_prom(scene, xi_center=center, fish=fish)


def simulate(scene: Scene, xi: dict[str, float] | None = None, model: str = "fom", prom: ReducedModel | None = None,
             sensitivities: bool = False, fish: Fish | None = None) -> SimulationResult | ReducedResult:
    """Simulate a design (:func:`start_design` of ``xi``) with the FOM, a ROM built at the design, or a
    PROM (built at the start values if not given)."""
    xi = start_design(scene, xi)
    if model == "fom":
        return simulate_fom(scene, xi, fish=fish, progress=False)
    if model == "rom":
        rom = _build_prom(scene, xi_center=xi, fish=fish, parametric=False)
        return attach_strains(simulate_reduced(rom, scene), rom, scene, None, fish)
    if model != "prom":
        raise ValueError(f"model must be 'fom', 'rom' or 'prom', got {model!r}")
    prom = prom or build_prom(scene, fish=fish)
    vector = np.array([xi.get(name, prom.design_point.get(name, 0.0)) for name in prom.shape_names])
    return attach_strains(simulate_reduced(prom, scene, vector, sensitivities=sensitivities), prom, scene, vector, fish)


def optimize(scene: Scene, out_dir: str | Path, weights: CostWeights | None = None, fish: Fish | None = None,
             render: bool = False, resume: bool = False, force: bool = False,
             max_time: float = DEFAULT_MAX_TIME) -> tuple[OptimizationResult, FomCheck]:
    """Optimise the scene with its method, check with the FOM, write the report to ``out_dir``.

    The folder is handled as ``aquarom optimize --out`` does: an existing one is refused unless
    ``force`` (and then only an earlier run's folder is replaced, once this run has finished) or
    ``resume``; the folder gets its manifest.json. A run that stops keeps its partial outputs.
    """
    from aquarom_fenics.io.outputs import claim_folder, discard, list_outputs, on_rank_zero, publish, write_manifest

    comm = MPI.COMM_WORLD
    location = on_rank_zero(comm, lambda: claim_folder(Path(out_dir), force, resume))
    started = time.perf_counter()
    arguments = {"out_dir": out_dir, "resume": resume, "force": force, "max_time": max_time,
                 "weights": weights or CostWeights(), "render": render}

    def settle(finished: bool, keep: bool, timings: dict) -> None:
        if comm.rank != 0:
            return
        if not keep:
            discard(location)
            return
        write_manifest(location.working, "aquarom_fenics.api.optimize", arguments, scene,
                       {"total": time.perf_counter() - started} | timings)
        list_outputs(location.working)
        if finished:
            publish(location)

    try:
        result, check = run_optimization(scene, location.working, resume=resume, weights=weights, fish=fish,
                                         render=render, max_time=max_time)
    except (SolverError, Interrupted, KeyboardInterrupt):
        settle(False, location.working.is_dir(), {})
        raise
    except BaseException:
        settle(False, False, {})
        raise
    settle(True, True, result.timings | {"fom_check": check.time})
    return result, check


