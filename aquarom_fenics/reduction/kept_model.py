"""The FOM of the last PROM build in this process, moved to the next build's design.

A build's FOM set-up (the mesh, its function spaces, every compiled form and expression, what the
reduction compiles on the model) depends on the scene and the nominal mesh, not on the design: the
design enters only through the shape coefficients' values and what is assembled at it. Builds of one
scene and fish (an optimisation's, an atlas's) share one model, moved to each centre
(``FullOrderModel.move_to``): the same compiled kernels on the same values, so the same tensors.
"""
from __future__ import annotations

import threading
from contextlib import contextmanager

from mpi4py import MPI
from petsc4py import PETSc

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.scene import Scene


class KeptModel:
    """One pulled-back FOM kept with its scene hash, fish and communicator; ``lock`` serialises the
    builds of threads that share the process (they share the model)."""

    def __init__(self):
        self.lock = threading.RLock()
        self.key: tuple | None = None
        self.model: FullOrderModel | None = None

    def _matches(self, scene: Scene, fish: Fish, comm: MPI.Comm) -> bool:
        if self.key is None:
            return False
        scene_hash, kept_fish, kept_comm = self.key
        return scene_hash == scene.hash and kept_fish is fish and MPI.Comm.Compare(kept_comm, comm) == MPI.IDENT

    @contextmanager
    def model_at(self, scene: Scene, fish: Fish, xi, comm: MPI.Comm):
        """The kept model of (scene, fish, comm) moved to ξ, or a new one (then kept), held for the block."""
        with self.lock:
            same = comm.allreduce(self._matches(scene, fish, comm), op=MPI.LAND)
            if same:
                self.model.move_to(xi)
            else:
                model = FullOrderModel(scene, fish, xi, comm=comm)    # a refused design keeps the old model
                self.release()
                self.key, self.model = (scene.hash, fish, comm), model
            yield self.model

    def release(self) -> None:
        """Free the kept model (when the builds are done: an optimisation's end)."""
        with self.lock:
            if self.model is not None:
                release_kept(self.model)
                self.model.destroy()
            self.key = self.model = None


def release_kept(model: FullOrderModel) -> None:
    """Destroy the PETSc objects the reductions keep on the model (``FullOrderModel.keep``: storages of
    projected forms, a work vector), in a kept tuple or as attributes of a kept object."""
    for value in model.kept.values():
        items = value if isinstance(value, (tuple, list)) else tuple(getattr(value, "__dict__", {}).values())
        for item in items:
            if isinstance(item, PETSc.Object):
                item.destroy()
    model.kept.clear()


KEPT_MODEL = KeptModel()
