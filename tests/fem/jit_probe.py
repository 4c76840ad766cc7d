"""A small run that compiles what a FOM run compiles first: an element, then a form on it.

Run as a script by tests/fem/test_jit_cache.py with ``AQUAROM_JIT_CACHE`` set: it prints
``compiled`` when both are compiled (or loaded); SIGTERM is handled as the command line does, and
the toolkit's log lines (the waits for another process's compile) go to stderr.
"""
import sys

import numpy as np
import ufl
from mpi4py import MPI

from aquarom_fenics import set_log_level
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.io.stop_signals import sigterm_as_interrupt

POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
CELLS = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])


def probe_mesh(comm=MPI.COMM_WORLD):
    return fx.create_tet_mesh(comm, POINTS, CELLS)


def stiffness_form(space):
    """∫ ∇u : ∇v dx, with a weight so that its module is the probe's own."""
    u, v = ufl.TrialFunction(space), ufl.TestFunction(space)
    return 1.2345 * ufl.inner(ufl.grad(u), ufl.grad(v)) * ufl.dx


def main() -> int:
    set_log_level("info")
    with sigterm_as_interrupt():
        space = fx.vector_space(probe_mesh(), 2)
        fx.compile_form(stiffness_form(space))
    if MPI.COMM_WORLD.rank == 0:
        print("compiled", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
