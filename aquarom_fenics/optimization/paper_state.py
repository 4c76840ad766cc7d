"""The paper method's state (:mod:`aquarom_fenics.optimization.paper_method`): what a checkpoint
keeps to resume a run, as typed dataclasses, read from and written to checkpoint.json's ``state``
(its schema: :func:`aquarom_fenics.io.readback.checkpoint_schema`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Linearisation:
    """d(z) ≈ d_c + ∇d_c · (z - z_c) about the centre z_c (a build or a surrogate), and ``prom_z``
    the centre of the PROM it was evaluated on (z_c after a build; the last build's for a surrogate)."""

    z: np.ndarray
    distance: float                 # d_c [m]
    distance_gradient: np.ndarray   # ∇d_c [m per unit of z]
    prom_z: np.ndarray

    def at(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """The first-order trajectory approximation d(z) and its gradient between builds."""
        return self.distance + self.distance_gradient @ (z - self.z), self.distance_gradient

    def to_dict(self) -> dict:
        return {"z": self.z.tolist(), "distance": float(self.distance),
                "distance_gradient": self.distance_gradient.tolist(), "prom_z": self.prom_z.tolist()}

    @classmethod
    def from_dict(cls, data: dict) -> "Linearisation":
        """From a checkpoint's ``center`` (one written before ``prom_z`` existed: the PROM at z_c)."""
        return cls(np.array(data["z"], dtype=float), float(data["distance"]),
                   np.array(data["distance_gradient"], dtype=float),
                   np.array(data.get("prom_z", data["z"]), dtype=float))


@dataclass
class PaperState:
    """The paper method's state after an iteration: what a checkpoint keeps to resume from.

    ``scaling`` is the diagonal W; ``previous_gradient`` ∇L_b of the last step (None: W restarts
    at 1/‖∇L_b‖_∞); ``since_build`` iterations since the last exact evaluation; ``confirm``: the
    next iteration re-evaluates exactly (a build, never a surrogate); ``restarted``: W has been
    restarted once after a step below the step tolerance."""

    z: np.ndarray
    scaling: np.ndarray
    iteration: int = 0
    previous_gradient: np.ndarray | None = None
    since_build: int = 0
    center: Linearisation | None = None
    confirm: bool = False
    restarted: bool = False

    @classmethod
    def start(cls, z: np.ndarray) -> "PaperState":
        return cls(np.array(z, dtype=float), np.ones(z.size))

    def to_dict(self) -> dict:
        """checkpoint.json's ``state`` (schema: :func:`aquarom_fenics.io.readback.checkpoint_schema`)."""
        return {"z": self.z.tolist(), "iteration": int(self.iteration), "scaling": self.scaling.tolist(),
                "previous_gradient": None if self.previous_gradient is None else self.previous_gradient.tolist(),
                "since_build": int(self.since_build), "center": None if self.center is None else self.center.to_dict(),
                "confirm": bool(self.confirm), "restarted": bool(self.restarted)}

    @classmethod
    def from_dict(cls, data: dict) -> "PaperState":
        """From a checkpoint's ``state``, already checked against its schema (a ``finished`` entry is
        read by :func:`aquarom_fenics.optimization.optimize.optimize`, not here)."""
        previous = data.get("previous_gradient")
        return cls(np.array(data["z"], dtype=float), np.array(data["scaling"], dtype=float), int(data["iteration"]),
                   None if previous is None else np.array(previous, dtype=float), int(data["since_build"]),
                   None if data.get("center") is None else Linearisation.from_dict(data["center"]),
                   bool(data.get("confirm", False)), bool(data.get("restarted", False)))
