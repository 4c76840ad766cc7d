"""Every dolfinx-version-specific call of the toolkit (written against dolfinx 0.5.2).

The rest of the package sees plain numpy arrays of *owned* degrees of freedom, PETSc objects and
compiled forms; a migration to a newer dolfinx touches this module only. It is also the only caller of
FFCx, the form compiler: every form, element and expression is compiled here, in the folder of
``io.paths.forms_cache`` and under the claim of ``fem.jit_cache``.
"""
from __future__ import annotations

import logging
import threading
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import basix
import ffcx
import ffcx.codegeneration.jit
import ffcx.naming
import numpy as np
import ufl
from dolfinx import fem, io
from dolfinx import jit as dolfinx_jit
from dolfinx import mesh as dolfinx_mesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from ufl.algorithms import extract_coefficients, extract_type

from aquarom_fenics.fem.jit_cache import JitCacheError, claimed, is_complete
from aquarom_fenics.io.paths import forms_cache


def create_tet_mesh(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray):
    """Distributed linear-tetrahedron mesh; rank 0's arrays are the input, other ranks pass none."""
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))
    if comm.rank != 0:
        points = np.empty((0, 3), dtype=np.float64)
        cells = np.empty((0, 4), dtype=np.int64)
    return dolfinx_mesh.create_mesh(comm, np.asarray(cells, dtype=np.int64), np.asarray(points, dtype=np.float64), domain)


def cell_tags(mesh, cells: np.ndarray, values: np.ndarray, name: str):
    """Mesh tags ``name`` of the given local cells (sorted) with one integer value each."""
    tags = dolfinx_mesh.meshtags(mesh, 3, cells, values)
    tags.name = name
    return tags


def xdmf_writer(comm: MPI.Comm, path) -> io.XDMFFile:
    """An XDMF file (with its .h5) opened for writing; use as a context manager."""
    return io.XDMFFile(comm, str(path), "w")


def vector_space(mesh, degree: int):
    """Vector Lagrange space of the displacement (degree 1 or 2)."""
    return function_space(mesh, ufl.VectorElement("Lagrange", mesh.ufl_cell(), degree))


def quadrature_tensor_space(mesh, degree: int):
    """3×3 tensors held at the points of the default quadrature rule of ``degree`` (per cell)."""
    element = ufl.TensorElement("Quadrature", mesh.ufl_cell(), degree, quad_scheme="default", shape=(3, 3))
    return function_space(mesh, element)


def quadrature_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(points (n_q, 3), weights (n_q,)) of the reference tetrahedron's default rule, as FFCx uses
    it for ``quadrature_degree = degree`` (the weights sum to 1/6)."""
    return basix.make_quadrature(basix.CellType.tetrahedron, degree)


def with_quadrature_degree(form, degree: int):
    """The form with every integral evaluated by the default rule of ``degree``."""
    return ufl.Form([integral.reconstruct(metadata={**integral.metadata(), "quadrature_degree": degree})
                     for integral in form.integrals()])


def local_cells(mesh) -> np.ndarray:
    """Every local cell (owned, then ghosts)."""
    index_map = mesh.topology.index_map(3)
    return np.arange(index_map.size_local + index_map.num_ghosts, dtype=np.int32)


def quadrature_points(mesh, degree: int) -> np.ndarray:
    """(n_local_cells, n_q, 3) physical coordinates of the quadrature points of every local cell."""
    points, _ = quadrature_rule(degree)
    compiled = compile_expression(ufl.SpatialCoordinate(mesh), points)
    return compiled.eval(local_cells(mesh)).reshape(-1, points.shape[0], 3)


def set_quadrature_values(function, values: np.ndarray) -> None:
    """Fill a quadrature tensor function from (n_local_cells, n_q, 3, 3) values."""
    blocks = function.function_space.dofmap.list.array
    function.x.array.reshape(-1, 9)[blocks] = values.reshape(-1, 9)


def quadrature_values(function) -> np.ndarray:
    """(n_local_cells, n_q, 3, 3) values of a quadrature tensor function (``set_quadrature_values``' layout)."""
    blocks = function.function_space.dofmap.list.array
    return function.x.array.reshape(-1, 9)[blocks].reshape(local_cells(function.function_space.mesh).size, -1, 3, 3)


def point_tensor_space(mesh):
    """3×3 tensors held at one point per cell: a quadrature tensor field's stand-in for
    :func:`evaluate_point_by_point`."""
    return quadrature_tensor_space(mesh, 1)


def compile_point_expression(expression, fields: list):
    """``expression`` compiled at one point per cell for :func:`evaluate_point_by_point`. ValueError unless
    its only coefficients are ``fields`` (of :func:`point_tensor_space`) and it does not read the position x:
    anything else would be taken at that one point, not at each point of the rule."""
    others = [c for c in extract_coefficients(expression) if not any(c is field for field in fields)]
    if others or extract_type(expression, ufl.SpatialCoordinate):
        raise ValueError("an expression evaluated point by point may depend on the given point fields, constants and "
                         f"the cell's Jacobian only; it reads {[str(c) for c in others] or 'the position x'}")
    return compile_quadrature_expression(expression, 1)


def evaluate_point_by_point(compiled, fields: list, values: list[np.ndarray], cells: np.ndarray) -> np.ndarray:
    """(n_cells, n_q, value size) values of an expression of ``fields`` (of :func:`point_tensor_space`),
    compiled by :func:`compile_point_expression`, at each of a rule's n_q points in turn, the fields set to
    their ``values`` (each (n_local_cells, n_q, 3, 3)) at that point.

    FFCx 0.5 forms a quadrature field's value at each of a cell's n_q points as a sum over all n_q of its
    values (an identity table, n_q² products per component), so an expression of such fields at the 24
    points of a degree-6 rule spends most of its time there. Point by point, the same arithmetic at each
    point gives the same values (bit for bit in tests/fem/test_point_by_point.py and for the sampled
    inertia) in about a third of the time. The meshes are linear (``create_tet_mesh``): the Jacobian of
    the expression is the cell's at every point.
    """
    by_point = [np.ascontiguousarray(np.moveaxis(array.reshape(array.shape[0], array.shape[1], 9), 1, 0))
                for array in values]
    targets = [field.x.array.reshape(-1, 9) for field in fields]
    blocks = fields[0].function_space.dofmap.list.array
    in_order = np.array_equal(blocks, np.arange(blocks.size))
    result = None
    for q in range(by_point[0].shape[0]):
        for target, array in zip(targets, by_point):
            if in_order:
                target[:blocks.size] = array[q]
            else:
                target[blocks] = array[q]
        at_point = compiled.eval(cells).reshape(cells.size, -1)
        if result is None:
            result = np.empty((cells.size, by_point[0].shape[0], at_point.shape[1]))
        result[:, q] = at_point
    return result


def cellwise_constant_space(mesh):
    return function_space(mesh, ufl.FiniteElement("DG", mesh.ufl_cell(), 0))


def new_function(space, name: str = "f"):
    return fem.Function(space, name=name)


def constant(mesh, value: float):
    return fem.Constant(mesh, PETSc.ScalarType(value))


@dataclass(frozen=True)
class DofLayout:
    """Where the displacement nodes live in a distributed Lagrange vector space (block size 3).

    ``node_of_block[b]`` is the input-mesh node index of local dof block b (owned first, then
    ghosts); ``global_block[b]`` its global PETSc block index; ``n_owned_blocks`` the owned count.
    """

    node_of_block: np.ndarray
    global_block: np.ndarray
    n_owned_blocks: int

    @property
    def owned_nodes(self) -> np.ndarray:
        return self.node_of_block[: self.n_owned_blocks]


def dof_layout(space, nodes_of_pairs) -> DofLayout:
    """The input node of every dof block of a degree-1 or degree-2 space on a linear mesh.

    A vertex dof is named by the pair (v, v) of its input vertex, an edge dof (degree 2) by the
    input vertices (a, b) of its edge; ``nodes_of_pairs`` maps (n, 2) pairs to node indices.
    """
    mesh = space.mesh
    vertices = np.asarray(mesh.geometry.input_global_indices)[mesh.geometry.dofmap.array.reshape(-1, 4)]
    layout = space.dofmap.dof_layout
    dof_blocks = space.dofmap.list.array.reshape(vertices.shape[0], -1)
    pairs = np.empty(dof_blocks.shape + (2,), dtype=np.int64)
    for vertex in range(4):
        pairs[:, layout.entity_dofs(0, vertex), :] = vertices[:, [vertex, vertex]][:, None, :]
    edges = basix.topology(basix.CellType.tetrahedron)[1]
    for edge in range(6) if layout.num_entity_dofs(1) else ():
        pairs[:, layout.entity_dofs(1, edge), :] = vertices[:, edges[edge]][:, None, :]
    index_map = space.dofmap.index_map
    n_local = index_map.size_local + index_map.num_ghosts
    node_of_block = np.empty(n_local, dtype=np.int64)
    node_of_block[dof_blocks.ravel()] = nodes_of_pairs(pairs.reshape(-1, 2))
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


# Every FFCx compile of the toolkit goes through the three functions below: each names the module
# FFCx will use for its object, holds that module's claim in the cache folder while dolfinx compiles
# or loads it (fem/jit_cache.py), and passes dolfinx the folder and parameters the name was made of.
FORM_COMPILER_PARAMETERS = {"scalar_type": "double"}


def jit_parameters() -> dict:
    """dolfinx's JIT parameters with the toolkit's cache folder (``AQUAROM_JIT_CACHE``)."""
    return {"cache_dir": str(forms_cache())}


def ffcx_module_name(ufl_object, kind: str, jit_params: dict) -> str:
    """The name FFCx gives the module of a form, element or expression (``kind``): a hash of the
    object and of the parameters, as in ffcx.codegeneration.jit.compile_forms/elements/expressions."""
    parameters = ffcx.get_parameters(dict(FORM_COMPILER_PARAMETERS))
    jit = dolfinx_jit.get_parameters(jit_params)
    tag = (ffcx.codegeneration.jit._compute_parameter_signature(parameters)
           + str(jit["cffi_extra_compile_args"]) + str(jit["cffi_debug"]))
    return f"libffcx_{kind}_" + ffcx.naming.compute_signature([ufl_object], tag)


_LOADED: dict[tuple[str, str], tuple] = {}
"""What dolfinx's JIT returned in this process, by (cache folder, module name). Loading a module again costs
FFCx a listing of the cache folder and a second hash of the object, about 3 ms: 16 loads a FOM set-up."""
_PENDING = threading.local()
_FFCX_JIT = dolfinx_jit.ffcx_jit


def _ffcx_jit_once(comm, ufl_object, *args, **kwargs):
    """``dolfinx.jit.ffcx_jit`` for the module ``_guarded`` named (this thread's pending key): loaded once a process
    and kept in ``_LOADED``. Every rank holds the same keys (the ranks compile together), so they all skip
    dolfinx's collective JIT or all enter it."""
    key, _PENDING.key = getattr(_PENDING, "key", None), None
    if key is None:
        return _FFCX_JIT(comm, ufl_object, *args, **kwargs)
    if key not in _LOADED:
        _LOADED[key] = _FFCX_JIT(comm, ufl_object, *args, **kwargs)
    return _LOADED[key]


dolfinx_jit.ffcx_jit = _ffcx_jit_once       # dolfinx.fem looks it up at each call


def _guarded(comm: MPI.Comm, ufl_object, kind: str, what: str, compile_function):
    """``compile_function(jit_params)`` with the module's claim held by rank 0, which compiles first
    (dolfinx's MPI JIT) while the other ranks wait to load it. The ranks agree whether the claim was
    taken before any of them enters dolfinx's collective compile, so none waits for a failed one.
    A module this process loaded before is not loaded again (``_LOADED``)."""
    jit_params = jit_parameters()
    with ExitStack() as held:
        failure, module = None, None
        if comm.rank == 0:
            module = ffcx_module_name(ufl_object, kind, jit_params)
            try:
                loaded = (jit_params["cache_dir"], module) in _LOADED
                if not loaded and not is_complete(Path(jit_params["cache_dir"]), module):   # a finished one is loaded
                    held.enter_context(claimed(jit_params["cache_dir"], module, what))
            except JitCacheError as error:
                failure = str(error)
        if comm.size > 1:
            failure, module = comm.bcast((failure, module), root=0)
        if failure is not None:
            raise JitCacheError(failure)
        _PENDING.key = (jit_params["cache_dir"], module)
        try:
            return _quietly(compile_function, jit_params)
        finally:
            _PENDING.key = None


def compile_form(form):
    """JIT-compile a UFL form (cached by FFCx, guarded); the C compiler's INFO log lines are silenced."""
    comm = form.ufl_domain().ufl_cargo().comm
    return _guarded(comm, form, "forms", "a form",
                    lambda jit: fem.form(form, form_compiler_params=dict(FORM_COMPILER_PARAMETERS), jit_params=jit))


def compile_expression(expression, points: np.ndarray):
    """JIT-compile a UFL expression evaluated at ``points`` (n, 3) of the reference cell."""
    points = np.reshape(points, (points.shape[0] if points.ndim == 2 else 1, -1))
    comm = expression.ufl_domain().ufl_cargo().comm
    return _guarded(comm, (expression, points), "expressions", "an expression",
                    lambda jit: fem.Expression(expression, points, form_compiler_params=dict(FORM_COMPILER_PARAMETERS),
                                               jit_params=jit))


def compile_quadrature_expression(expression, degree: int):
    """JIT-compile a UFL expression evaluated at the points of the default rule of ``degree``."""
    return compile_expression(expression, quadrature_rule(degree)[0])


def function_space(mesh, element):
    """The space of a UFL element on ``mesh``, its element and dofmap compiled (guarded)."""
    return _guarded(mesh.comm, element, "elements", "a finite element",
                    lambda jit: fem.FunctionSpace(mesh, element, form_compiler_params=dict(FORM_COMPILER_PARAMETERS),
                                                  jit_params=jit))


def evaluate_expression(compiled, cells: np.ndarray) -> np.ndarray:
    """(n_cells, n_points × value size) values of a compiled expression."""
    return compiled.eval(cells)


def owned_cells(mesh) -> np.ndarray:
    return np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)


def owned_cells_among(mesh, input_cells: np.ndarray) -> np.ndarray:
    """Local indices of the owned cells whose input-mesh index is in ``input_cells``."""
    owned = owned_cells(mesh)
    return owned[np.isin(input_cell_indices(mesh)[owned], input_cells)]


def cell_measure(mesh, regions: dict[int, np.ndarray]) -> ufl.Measure:
    """dx whose ``dx(i)`` integrates over the cells of region i only (input-mesh cell indices)."""
    owned = owned_cells(mesh)
    region_of_cell = np.zeros(owned.size, dtype=np.int32)
    for region, cells in regions.items():
        region_of_cell[owned_cells_among(mesh, cells)] = region
    tagged = np.flatnonzero(region_of_cell).astype(np.int32)
    tags = dolfinx_mesh.meshtags(mesh, 3, tagged, region_of_cell[tagged])
    return ufl.Measure("dx", domain=mesh, subdomain_data=tags)


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
    """The form's matrix in block storage (BAIJ, one 3×3 block per pair of displacement nodes): the
    assembly inserts whole blocks instead of scalar AIJ rows, and its products run faster."""
    return fem_petsc.create_matrix(compiled_form, "baij")


def create_matrix_with_entries(compiled_form, rows: np.ndarray, columns: np.ndarray) -> PETSc.Mat:
    """The form's matrix with (rows[i], columns[i]) added to its sparsity pattern (global indices, rows
    owned by this rank; their node blocks are added), so that terms adding entries outside the form's
    pattern need no reallocation (PETSc reallocates the matrix for every row that overflows)."""
    form_matrix = assemble_matrix_into(create_matrix(compiled_form), compiled_form)
    block = form_matrix.getBlockSize()
    indptr, indices, _ = form_matrix.getValuesCSR()
    first_row = form_matrix.getOwnershipRange()[0]
    n_rows, n_columns = form_matrix.getLocalSize()[0], form_matrix.getSize()[1]
    form_rows = np.repeat(np.arange(n_rows, dtype=np.int64), np.diff(indptr))
    scalar_rows = np.concatenate([form_rows, np.asarray(rows, dtype=np.int64) - first_row])
    scalar_columns = np.concatenate([indices, np.asarray(columns, dtype=np.int64)])
    n_block_columns = n_columns // block
    keys = np.unique((scalar_rows // block) * n_block_columns + scalar_columns // block)
    block_rows, block_columns = np.divmod(keys, n_block_columns)
    block_indptr = np.searchsorted(block_rows, np.arange(n_rows // block + 1))
    matrix = PETSc.Mat().createBAIJ(form_matrix.getSizes(), block, comm=form_matrix.comm,
                                    csr=(block_indptr.astype(PETSc.IntType), block_columns.astype(PETSc.IntType)))
    matrix.setLGMap(*form_matrix.getLGMap())
    form_matrix.destroy()
    return matrix


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
