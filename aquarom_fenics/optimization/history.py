"""What an optimiser leaves after every iteration: the history row, the checkpoint, its safeguards."""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.cost import DesignSpace
from aquarom_fenics.optimization.prom_builder import PromBuilder


def design_columns(space: DesignSpace) -> list[str]:
    """The columns of z in a history row: ``xi_<name>`` of the shapes (and ``xi_amplitude`` of the co-design's
    A), ``gait_<name>`` of the ``[gait]`` variables (``gait_frequency``, ``gait_phase_lag``, ``gait_amplitude_2``)."""
    first_gait = len(space.names) - space.n_gait
    return [f"{'gait' if k >= first_gait else 'xi'}_{name}" for k, name in enumerate(space.names)]


def relabelled(space: DesignSpace, row: dict) -> dict:
    """A history row of a checkpoint written before the gait's columns were named ``gait_<name>`` (they were
    ``xi_<name>``), in today's columns; other rows as they are."""
    renamed = {f"xi_{column[5:]}": column for column in design_columns(space) if column.startswith("gait_")}
    return {renamed.get(key, key): value for key, value in row.items()}


def history_columns(space: DesignSpace) -> list[str]:
    """The columns of a history row, in the order :func:`history_row` makes them."""
    return (["iteration", *design_columns(space), "cost", *(f"grad_{name}" for name in space.names)]
            + ["distance", "prom", "wall_time", "radius", "ratio", "optimality"])


def history_row(space: DesignSpace, iteration: int, z, cost, gradient, distance, kind: str, started: float,
                radius: float | None = None, ratio: float | None = None, optimality: float | None = None) -> dict:
    """One iteration: ξ, cost, gradient, distance [m], how the PROM was used, the first-order
    measure, and for the trust region its radius (fraction of the validity box) and
    actual/predicted reduction."""
    row = {"iteration": iteration}
    row.update({column: float(value) for column, value in zip(design_columns(space), z)})
    row["cost"] = float(cost)
    row.update({f"grad_{name}": float(value) for name, value in zip(space.names, gradient)})
    row.update({"distance": float(distance), "prom": kind, "wall_time": time.perf_counter() - started,
                "radius": radius, "ratio": ratio, "optimality": optimality})
    return row


def record(history: list[dict], row: dict, on_iteration) -> None:
    """Append a history row and show it to ``on_iteration``."""
    history.append(row)
    on_iteration(row)


class Checkpoint:
    """Optimiser state as JSON, written atomically after every iteration."""

    KEYS = ("scene_hash", "method", "state", "history", "builds", "build_time", "solve_time")

    def __init__(self, path: Path | None, scene: Scene, method: str, write: bool = True):
        self.path, self.scene_hash, self.method, self.write = path, scene.hash, method, write
        self.scene = scene
        self.state: dict | None = None          # the last state saved (or loaded)

    def finish(self, optimum, evaluation, reason: str, history: list[dict], builder: PromBuilder) -> None:
        """The last checkpoint of an optimisation that has stopped: its state with ``finished`` (the
        optimum's evaluation, the PROM size and the stop reason) and the whole history, so that a
        run interrupted after it (in the FOM check) resumes with the same optimum and history rows,
        none repeated."""
        if self.state is None:
            return
        finished = {"optimum": np.asarray(optimum, dtype=float).tolist(), "cost": float(evaluation.cost),
                    "gradient": np.asarray(evaluation.gradient, dtype=float).tolist(),
                    "distance": float(evaluation.distance),
                    "distance_gradient": np.asarray(evaluation.distance_gradient, dtype=float).tolist(),
                    "prom_size": int(builder.last_size), "reason": reason}
        self.save(dict(self.state) | {"finished": finished}, history, builder)

    def save(self, state: dict, history: list[dict], builder: PromBuilder) -> None:
        self.state = state
        if self.path is None or not self.write:
            return
        write_json_atomic(self.path, {"scene_hash": self.scene_hash, "method": self.method, "state": state,
                                      "history": history, "builds": builder.builds, "reused": builder.reused,
                                      "build_time": builder.build_time, "solve_time": builder.solve_time,
                                      "basis_reuses": builder.basis_reuses, "build_records": builder.records,
                                      "basis_center": None if builder.basis_center is None
                                      else builder.basis_center.tolist()})

    def load(self) -> dict | None:
        """The saved state, checked against the checkpoint schema (:mod:`aquarom_fenics.io.readback`)
        and against this scene and method; InputError before anything is written otherwise."""
        from aquarom_fenics.io.readback import load_checkpoint
        from aquarom_fenics.optimization.cost import design_space

        if self.path is None or not self.path.exists():
            return None
        space = design_space(self.scene)
        data = load_checkpoint(self.path, len(space.names), self.method, space.n_shapes)
        if data["scene_hash"] != self.scene_hash or data["method"] != self.method:
            raise InputError(f"checkpoint {self.path}: written for scene hash {data['scene_hash']} with "
                             f"method {data['method']}, not this scene ({self.scene_hash}, {self.method}); "
                             "start without --resume")
        self.state = data["state"]
        data["history"] = [relabelled(space, row) for row in data["history"]]
        return data


@dataclass
class Safeguard:
    """Stops a loop past its wall-time budget and refuses a non-finite design."""

    started: float
    max_time: float

    def out_of_time(self) -> bool:
        return time.perf_counter() - self.started > self.max_time

    @property
    def reason(self) -> str:
        return f"wall-time limit of {self.max_time:g} s reached"

    @staticmethod
    def finite(z: np.ndarray, iteration: int) -> np.ndarray:
        if not np.all(np.isfinite(z)):
            raise SolverError(f"the optimiser produced a non-finite design {z.tolist()} at iteration {iteration}")
        return z


def optimality_reason(measure: float, tolerance: float) -> str:
    return f"first-order optimality: measure {measure:.2e} ≤ tolerance {tolerance:g}"
