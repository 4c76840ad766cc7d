"""The Python API for scripted studies: scenes in, plain dataclasses and numpy arrays out.

    from aquarom_fenics.api import Scene, simulate, build_prom, optimize

    scene = Scene.load("so1").replace("mesh", level=1)
    fom = simulate(scene, {"y_thin": 0.1})                   # SimulationResult (FOM)
    prom = build_prom(scene)                                  # ReducedModel at the start values
    reduced = simulate(scene, {"y_thin": 0.03}, model="prom", prom=prom, sensitivities=True)
    result, check = optimize(scene, "results/my-so1")       # OptimizationResult, FomCheck
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from aquarom_fenics.optimization.cost import CostWeights
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.dynamics.reduced_dynamics import ReducedResult, simulate_reduced
from aquarom_fenics.reduction.reductor import build_prom as _build_prom
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.dynamics.simulate import SimulationResult, simulate_fom
from aquarom_fenics.optimization.study import FomCheck, run_optimization

__all__ = ["Scene", "Fish", "load_fish", "simulate", "build_prom", "optimize", "CostWeights", "ReducedModel",
           "SimulationResult", "ReducedResult"]


def build_prom(scene: Scene, xi: dict[str, float] | None = None, fish: Fish | None = None) -> ReducedModel:
    """The scene's PROM centred on ``xi`` (default: the scene's start values)."""
    center = {s.name: s.start for s in scene.shapes} | (xi or {})
    return _build_prom(scene, xi_center=center, fish=fish)


def simulate(scene: Scene, xi: dict[str, float] | None = None, model: str = "fom", prom: ReducedModel | None = None,
             sensitivities: bool = False, fish: Fish | None = None) -> SimulationResult | ReducedResult:
    """Simulate a design with the FOM, a ROM built at the design, or a PROM (built if not given)."""
    xi = xi or {}
    if model == "fom":
        return simulate_fom(scene, xi, fish=fish, progress=False)
    if model == "rom":
        return simulate_reduced(_build_prom(scene, xi_center=xi, fish=fish, parametric=False), scene)
    if model != "prom":
        raise ValueError(f"model must be 'fom', 'rom' or 'prom', got {model!r}")
    prom = prom or build_prom(scene, fish=fish)
    vector = np.array([xi.get(name, prom.design_point.get(name, 0.0)) for name in prom.shape_names])
    return simulate_reduced(prom, scene, vector, sensitivities=sensitivities)


def optimize(scene: Scene, out_dir: str | Path, weights: CostWeights | None = None, fish: Fish | None = None,
             render: bool = False, resume: bool = False):
    """Optimise the scene with its method, check with the FOM, write the report to ``out_dir``."""
    return run_optimization(scene, Path(out_dir), resume=resume, weights=weights, fish=fish, render=render)
