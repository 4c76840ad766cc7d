"""Every dolfinx-version-specific call of the toolkit (written against dolfinx 0.5.2).

The rest of the package sees plain numpy arrays of *owned* degrees of freedom, PETSc objects and
compiled forms; a migration to a newer dolfinx touches this module only.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem, io
from dolfinx import mesh as dolfinx_mesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc


def create_tet_mesh(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray):
    """Distributed linear-tetrahedron mesh; rank 0's arrays are the input, other ranks pass none."""
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))
    if comm.rank != 0:
        points = np.empty((0, 3), dtype=np.float64)
        cells = np.empty((0, 4), dtype=np.int64)
    return dolfinx_mesh.create_mesh(comm, np.asarray(cells, dtype=np.int64), np.asarray(points, dtype=np.float64), domain)


def vector_p1_space(mesh):
    return fem.VectorFunctionSpace(mesh, ("Lagrange", 1))


def cellwise_constant_space(mesh):
    return fem.FunctionSpace(mesh, ("DG", 0))


def new_function(space, name: str = "f"):
    return fem.Function(space, name=name)


def constant(mesh, value: float):
    return fem.Constant(mesh, PETSc.ScalarType(value))


@dataclass(frozen=True)
class DofLayout:
    """Where the nodes of the input mesh live in a distributed P1 vector space (block size 3).

    ``node_of_block[b]`` is the input-mesh node index of local dof block b (owned first, then
    ghosts); ``global_block[b]`` its global PETSc block index; ``n_owned_blocks`` the owned count.
    """

    node_of_block: np.ndarray
    global_block: np.ndarray
    n_owned_blocks: int

    @property
    def owned_nodes(self) -> np.ndarray:
        return self.node_of_block[: self.n_owned_blocks]


def dof_layout(space) -> DofLayout:
    mesh = space.mesh
    geometry_nodes = mesh.geometry.dofmap.array.reshape(-1, 4)
    dof_blocks = space.dofmap.list.array.reshape(-1, 4)
    index_map = space.dofmap.index_map
    n_local = index_map.size_local + index_map.num_ghosts
    node_of_block = np.empty(n_local, dtype=np.int64)
    node_of_block[dof_blocks.ravel()] = np.asarray(mesh.geometry.input_global_indices)[geometry_nodes.ravel()]
    global_block = np.asarray(index_map.local_to_global(np.arange(n_local, dtype=np.int32)), dtype=np.int64)
    return DofLayout(node_of_block, global_block, index_map.size_local)


def input_cell_indices(mesh) -> np.ndarray:
    """Input-mesh index of every local cell (owned, then ghosts)."""
    n_local = mesh.topology.index_map(3).size_local + mesh.topology.index_map(3).num_ghosts
    return np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:n_local]


def set_nodal_values(function, layout: DofLayout, nodal_values: np.ndarray) -> None:
    """Fill a P1 vector function from an (n_input_nodes, 3) array (owned and ghost dofs)."""
    function.x.array[:] = nodal_values[layout.node_of_block].ravel()


def set_cell_values(function, cell_values: np.ndarray) -> None:
    """Fill a DG0 function from an array indexed by input-mesh cell."""
    function.x.array[:] = cell_values[input_cell_indices(function.function_space.mesh)]


def set_owned_values(function, owned: np.ndarray) -> None:
    """Set the owned dofs of a function from a numpy array and update its ghosts."""
    function.x.array[: owned.size] = owned
    function.x.scatter_forward()


def compile_form(form):
    """JIT-compile a UFL form (cached by FFCx); the C compiler's INFO log lines are silenced."""
    return _quietly(fem.form, form)


def compile_midpoint_expression(expression):
    """JIT-compile a UFL expression evaluated at the cell midpoint of a tetrahedron."""
    return _quietly(fem.Expression, expression, np.array([[0.25, 0.25, 0.25]]))


def evaluate_expression(compiled, cells: np.ndarray) -> np.ndarray:
    """(n_cells, value size) values of a compiled midpoint expression."""
    return compiled.eval(cells)


def owned_cells(mesh) -> np.ndarray:
    return np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)


def tensor_constant(mesh, shape) -> fem.Constant:
    """A constant tensor whose ``value`` can be set between evaluations."""
    return fem.Constant(mesh, np.zeros(shape))


def _quietly(compile_function, *args):
    logging.disable(logging.INFO)
    try:
        return compile_function(*args)
    finally:
        logging.disable(logging.NOTSET)


def create_vector(compiled_form) -> PETSc.Vec:
    return fem_petsc.create_vector(compiled_form)


def create_matrix(compiled_form) -> PETSc.Mat:
    return fem_petsc.create_matrix(compiled_form)


def assemble_vector_into(vector: PETSc.Vec, compiled_form) -> np.ndarray:
    """Assemble a linear form; returns the owned entries (a view of ``vector``)."""
    with vector.localForm() as local:
        local.set(0.0)
    fem_petsc.assemble_vector(vector, compiled_form)
    vector.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return vector.array


def assemble_matrix_into(matrix: PETSc.Mat, compiled_form) -> PETSc.Mat:
    """Assemble a bilinear form without boundary conditions (finalised)."""
    matrix.zeroEntries()
    fem_petsc.assemble_matrix(matrix, compiled_form)
    matrix.assemble()
    return matrix


def assemble_scalar(compiled_form, comm: MPI.Comm) -> float:
    return comm.allreduce(fem.assemble_scalar(compiled_form), op=MPI.SUM)


def sub_space_dofs_of_nodes(space, layout: DofLayout, nodes: np.ndarray, component: int) -> np.ndarray:
    """Owned local dof indices (block-expanded) of one component at the given input nodes."""
    owned = np.flatnonzero(np.isin(layout.owned_nodes, nodes))
    return 3 * owned + component


class XDMFTimeSeries:
    """A displacement time series for ParaView (XDMF + HDF5)."""

    def __init__(self, comm: MPI.Comm, path, mesh):
        self._file = io.XDMFFile(comm, str(path), "w")
        self._file.write_mesh(mesh)

    def write(self, function, time: float) -> None:
        self._file.write_function(function, time)

    def close(self) -> None:
        self._file.close()


def write_mesh_xdmf(comm: MPI.Comm, path, mesh) -> None:
    with io.XDMFFile(comm, str(path), "w") as xdmf:
        xdmf.write_mesh(mesh)
