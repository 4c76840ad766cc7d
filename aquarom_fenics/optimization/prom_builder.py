"""PROMs centred on designs for the optimisers: built or taken from the cache, checked for a stable gait."""
from __future__ import annotations

import time

import numpy as np

from aquarom_fenics.dynamics.reduced_dynamics import reduced_stability
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import DesignSpace, Evaluation, evaluate
from aquarom_fenics.reduction.cache import cached_prom
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.reduction.reductor import build_prom


STABILITY_STROKES = 2
"""Strokes the horizon must hold before the gait's stability is judged."""


class PromBuilder:
    """Builds PROMs centred on designs, counting builds, cache reuses and their time."""

    def __init__(self, scene: Scene, fish: Fish, space: DesignSpace):
        self.scene, self.fish, self.space = scene, fish, space
        self.builds = 0
        self.reused = 0
        self.last_size = 0
        self.build_time = 0.0
        self.solve_time = 0.0

    def build(self, z: np.ndarray) -> ReducedModel:
        started = time.perf_counter()
        center = z[: self.space.n_shapes]
        built = []

        def build_here():
            built.append(build_prom(self.scene, xi_center=center, fish=self.fish))
            return built[0]

        prom = cached_prom(self.scene, center, build_here)
        self.build_time += time.perf_counter() - started
        self.builds += 1
        self.reused += not built
        self.last_size = prom.size
        self._refuse_unstable(prom, z)
        return prom

    def _refuse_unstable(self, prom: ReducedModel, z: np.ndarray) -> None:
        """A design whose PROM gait is unstable (Floquet multiplier |μ| > 1.01 over the last stroke,
        ``reduced_stability``) is refused like one the mesh check refuses: the optimisers step back.
        Judged only on horizons of two strokes or more (a start-up from rest is no periodic gait)."""
        actuation = self.scene.actuation
        if self.scene.solver.duration * actuation.frequency < STABILITY_STROKES:
            return
        amplitude = float(z[-1]) if self.space.with_amplitude else None
        stable, reason = reduced_stability(prom, self.scene, z[: self.space.n_shapes], amplitude)
        if not stable:
            raise InputError(f"design {self.space.as_dict(z)} is infeasible: its PROM is unstable ({reason})")

    def evaluate(self, prom, z, weights) -> Evaluation:
        started = time.perf_counter()
        try:
            return evaluate(prom, self.scene, self.space, z, weights)
        finally:
            self.solve_time += time.perf_counter() - started

    def meshes(self, z: np.ndarray) -> bool:
        """The design check of SPEC §4 (det F_1 > 0.1 everywhere) at the shapes of z."""
        try:
            self.fish.design(z[: self.space.n_shapes])
            return True
        except InputError:
            return False
