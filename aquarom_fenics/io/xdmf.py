"""XDMF + HDF5 files for ParaView, written by one process from arrays on the input mesh.

The mesh written is the design's (vertex positions x_0 + U ξ [m]), so ParaView shows the body
that was simulated; the displacement series starts at zero on it. Cell regions, when given, are
written as the cell tags ``regions`` (0 passive, 1 head, 2 left muscle, 3 right muscle).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

REGION_TAG_NAMES = ("passive", "head", "left muscle", "right muscle")
"""What each value of the ``regions`` cell tags means."""


def cell_regions(tags, n_cells: int) -> np.ndarray:
    """Index into REGION_TAG_NAMES of every cell from the fish's tags: passive, head, left or right muscle."""
    region = np.zeros(n_cells, dtype=np.int32)
    region[tags.head_cells] = REGION_TAG_NAMES.index("head")
    region[tags.left_muscle_cells] = REGION_TAG_NAMES.index("left muscle")
    region[tags.right_muscle_cells] = REGION_TAG_NAMES.index("right muscle")
    return region


def _region_tags(mesh, regions: np.ndarray):
    """The cell tags ``regions`` from one value per input cell."""
    from aquarom_fenics.fem import dolfinx_adapter as adapter

    n_cells = mesh.topology.index_map(3).size_local
    input_cell = adapter.input_cell_indices(mesh)[:n_cells]
    return adapter.cell_tags(mesh, np.arange(n_cells, dtype=np.int32),
                             np.asarray(regions, dtype=np.int32)[input_cell], "regions")


def _input_vertex_of_dof(space) -> np.ndarray:
    """Input-vertex index of every dof block of a P1 vector space (the cell's dofs follow its vertices)."""
    mesh = space.mesh
    geometry = mesh.geometry.dofmap.array.reshape(-1, 4)
    vertices = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[geometry]
    dofs = space.dofmap.list.array.reshape(-1, 4)
    vertex_of_dof = np.empty(space.dofmap.index_map.size_local, dtype=np.int64)
    vertex_of_dof[dofs.ravel()] = vertices.ravel()
    return vertex_of_dof


def write_design_xdmf(path: Path, points: np.ndarray, cells: np.ndarray, regions: np.ndarray | None = None,
                      time: np.ndarray | None = None, displacements: np.ndarray | None = None) -> Path:
    """Write ``path`` (.xdmf, with its .h5): the design mesh, its region tags and, when given, the
    vertex displacement series [m] at the sample times [s] as the function ``displacement``.

    ``points`` (n_vertices, 3) are the design's vertex positions [m], ``cells`` (n_cells, 4) the
    tetrahedra, ``regions`` one value of REGION_TAG_NAMES' index per cell, ``displacements``
    (n_samples, n_vertices, 3). Call on one process only.
    """
    from aquarom_fenics.fem import dolfinx_adapter as adapter

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = adapter.create_tet_mesh(MPI.COMM_SELF, points, cells)
    with adapter.xdmf_writer(MPI.COMM_SELF, path) as xdmf:
        xdmf.write_mesh(mesh)
        if regions is not None:
            mesh.topology.create_connectivity(3, 0)
            xdmf.write_meshtags(_region_tags(mesh, regions))
        if displacements is not None:
            space = adapter.vector_space(mesh, 1)
            field = adapter.new_function(space, "displacement")
            vertex_of_dof = _input_vertex_of_dof(space)
            for sample_time, values in zip(time, displacements):
                field.x.array[:] = np.asarray(values)[vertex_of_dof].ravel()
                xdmf.write_function(field, float(sample_time))
    return path
