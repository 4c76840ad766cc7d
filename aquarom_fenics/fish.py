"""The fish of a scene: nominal mesh, tags and shape-variation matrix U (SPEC §3–§4).

Rank 0 reads or generates the mesh (the mesh cache is written once) and broadcasts it, so every
rank holds the same small numpy description; dolfinx distributes the cells afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from .errors import InputError
from .mesh import FishMesh, block_mesh, read_mesh
from .scene import Scene
from .shapes import check_design, design_points, shape_matrix
from .tags import FishTags, tag_fish


@dataclass(frozen=True)
class Fish:
    mesh: FishMesh
    tags: FishTags
    shape_names: tuple[str, ...]
    shape_matrix: np.ndarray     # U, (3 n_nodes, p), node-major

    def parameter_vector(self, xi: dict[str, float] | np.ndarray | None) -> np.ndarray:
        """ξ as an array ordered like ``shape_names`` (a dict may give a subset; missing = 0)."""
        if xi is None:
            return np.zeros(len(self.shape_names))
        if isinstance(xi, dict):
            unknown = set(xi) - set(self.shape_names)
            if unknown:
                raise InputError(f"design: {', '.join(sorted(unknown))} not among the scene's shape variations "
                                 f"({', '.join(self.shape_names) or 'none'})")
            return np.array([float(xi.get(name, 0.0)) for name in self.shape_names])
        xi = np.asarray(xi, dtype=float)
        if xi.shape != (len(self.shape_names),):
            raise InputError(f"design: expected {len(self.shape_names)} parameters, got {xi.shape}")
        return xi

    def shape_displacement(self, xi) -> np.ndarray:
        """u_ξ = U ξ as an (n_nodes, 3) array [m]."""
        return (self.shape_matrix @ self.parameter_vector(xi)).reshape(-1, 3)

    def design(self, xi) -> np.ndarray:
        """Checked nodal positions x_0 + U ξ of the design (InputError if a cell inverts)."""
        xi = self.parameter_vector(xi)
        moved = design_points(self.mesh.points, self.shape_matrix, xi)
        check_design(self.mesh.points, self.mesh.cells, moved, dict(zip(self.shape_names, xi)), regions=self.tags)
        return moved


def load_mesh(scene: Scene) -> FishMesh:
    if scene.mesh_file is not None:
        return read_mesh(scene.mesh_file, scale=scene.mesh.scale, translate=scene.mesh.translate)
    return block_mesh(scene.mesh.level, scene.mesh.length, scene.mesh.width, scene.mesh.height)


def load_fish(scene: Scene, comm: MPI.Comm = MPI.COMM_WORLD) -> Fish:
    """Mesh (rank 0, broadcast), tags and U of a scene."""
    mesh_or_error = None
    if comm.rank == 0:
        try:
            mesh_or_error = load_mesh(scene)
        except InputError as error:
            mesh_or_error = error
    mesh = comm.bcast(mesh_or_error, root=0)
    if isinstance(mesh, InputError):
        raise mesh
    tags = tag_fish(mesh, head_fraction=scene.regions.head_fraction, muscle_range=scene.regions.muscle_range)
    names = tuple(scene.shape_names)
    relative = tags.box.relative(mesh.points)
    matrix = shape_matrix(names, relative, tags.box) if names else np.zeros((mesh.points.size, 0))
    return Fish(mesh, tags, names, matrix)
