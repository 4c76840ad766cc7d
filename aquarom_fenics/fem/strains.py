"""The largest principal Green–Lagrange strain of a run, where and when it occurs.

The Saint Venant–Kirchhoff law (SPEC §5) is justified by small strains: the method's nominal case
keeps the largest principal strain under 5 %. Every FOM run and every single reduced run reports

    ε_max = max over the sampled steps and the evaluation points of λ_max(E),
    E = ½ (F_2ᵀ F_2 - I)   (``forms/kinematics.green_lagrange_strain``, measured from the design's rest shape),

with the time and the region (head, a muscle, the passive body) of its maximum, the tagged
regions of the mesh deciding the region. E is evaluated at the quadrature points of the stiffness
forms (the points the elastic energy is integrated at) of every cell, at every k-th step with
k = ceil(n_steps / STRAIN_SAMPLES) and at the last step. A reduced run's u = V η is evaluated the
same way on the FOM's mesh, through the same UFL expression.
"""
from __future__ import annotations

import logging
import math
import time as clock
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.kinematics import green_lagrange_strain

log = logging.getLogger("aquarom")

STRAIN_LIMIT = 0.10
"""Largest principal Green–Lagrange strain [1] above which a run warns. The method justifies SVK by
ε_max < 5 % in its nominal case; measured here (docs/theory/material-law.md) the nominal design
reaches 9.1 % (level 1), and SVK's peak strain stays within 10 % of the Neo-Hookean FOM's up to
about there while it falls 20-33 % short of it at 16-28 % (the SO2 optimum, the CO corner)."""

STRAIN_SAMPLES = 100
"""About this many steps of a run are evaluated (every k-th step, k = ceil(n_steps / STRAIN_SAMPLES))."""

PASSIVE, HEAD = "passive body", "head"


def sampling_stride(n_steps: int, samples: int = STRAIN_SAMPLES) -> int:
    """k: the strain is evaluated at the steps 0, k, 2k, … and at the last one."""
    return max(1, math.ceil(n_steps / samples))


def is_sampled(step: int, n_steps: int, stride: int) -> bool:
    return step % stride == 0 or step == n_steps


def largest_principal(strains: np.ndarray) -> np.ndarray:
    """λ_max of symmetric 3×3 tensors (..., 3, 3) → (...), in closed form (a batched eigensolver costs
    ten times more): with q = tr A / 3, p = √(|A - qI|² / 6) and r = det((A - qI)/p) / 2,

        λ_max = q + 2 p cos(arccos(r) / 3)   (λ_max = q where p = 0)."""
    a = np.asarray(strains, dtype=float)
    q = np.trace(a, axis1=-2, axis2=-1) / 3.0
    deviator = a - q[..., None, None] * np.eye(3)
    p = np.sqrt(np.einsum("...ij,...ij->...", deviator, deviator) / 6.0)
    safe = np.where(p > 0.0, p, 1.0)
    b = deviator / safe[..., None, None]
    determinant = (b[..., 0, 0] * (b[..., 1, 1] * b[..., 2, 2] - b[..., 1, 2] * b[..., 2, 1])
                   - b[..., 0, 1] * (b[..., 1, 0] * b[..., 2, 2] - b[..., 1, 2] * b[..., 2, 0])
                   + b[..., 0, 2] * (b[..., 1, 0] * b[..., 2, 1] - b[..., 1, 1] * b[..., 2, 0]))
    r = np.clip(determinant / 2.0, -1.0, 1.0)
    return q + np.where(p > 0.0, 2.0 * p * np.cos(np.arccos(r) / 3.0), 0.0)


def region_names(scene, tags, n_cells: int) -> tuple[tuple[str, ...], np.ndarray]:
    """(names, region index of every input cell): 0 the passive body, 1 the head, 2 + j muscle j
    (named by its region), from the fish's tagged regions."""
    from aquarom_fenics.physics.muscle import muscle_cells

    names = [PASSIVE, HEAD]
    region = np.zeros(n_cells, dtype=np.int64)
    region[tags.head_cells] = 1
    for j, (muscle, cells) in enumerate(zip(scene.actuated_muscles, muscle_cells(scene, tags))):
        names.append(muscle.region)
        region[cells] = 2 + j
    return tuple(names), region


@dataclass
class StrainReport:
    """ε_max over a run with its time, region and point, the maximum per region and the sampled history."""

    stride: int
    degree: int
    names: tuple
    limit: float = STRAIN_LIMIT
    times: list = field(default_factory=list)
    values: list = field(default_factory=list)
    maximum: float = -math.inf
    time: float | None = None
    region: str | None = None
    point: list | None = None
    by_region: dict = field(default_factory=dict)
    seconds: float = 0.0                  # wall time of the evaluations [s]

    def add(self, time: float, value: float, region: str, point, by_region: dict) -> None:
        self.times.append(float(time))
        self.values.append(float(value))
        if value > self.maximum:
            self.maximum, self.time, self.region, self.point = float(value), float(time), region, list(map(float, point))
        for name, region_value in by_region.items():
            self.by_region[name] = max(self.by_region.get(name, -math.inf), float(region_value))

    @property
    def above_limit(self) -> bool:
        return self.maximum > self.limit

    def as_dict(self) -> dict:
        """The summary's ``strain`` entry."""
        return {"max_principal": self.maximum, "time": self.time, "region": self.region, "point": self.point,
                "limit": self.limit, "above_limit": self.above_limit, "by_region": self.by_region,
                "every_steps": self.stride, "samples": len(self.times), "wall_time": self.seconds,
                "evaluated_at": f"quadrature points of the stiffness rule (degree {self.degree}) of every cell",
                "history": {"time": self.times, "max_principal": self.values}}

    def line(self) -> str:
        """One line for the console: ε_max, when and where."""
        return (f"max principal strain {100 * self.maximum:.2f} % at t = {self.time:.3g} s in the {self.region} "
                f"(limit {100 * self.limit:g} %)")

    def warning(self) -> str | None:
        """One line when ε_max is above the limit, else None."""
        if not self.above_limit:
            return None
        return (f"the largest principal Green-Lagrange strain, {100 * self.maximum:.1f} % at t = {self.time:.3g} s in "
                f"the {self.region}, is above {100 * self.limit:g} %, where SVK's strains part from a "
                "Neo-Hookean law's (docs/theory/material-law.md)")


class StrainProbe:
    """E of a displacement on a FOM's space at the stiffness rule's quadrature points of the owned cells."""

    def __init__(self, space, shape_gradient, degree: int, names: tuple, region_of_input_cell: np.ndarray,
                 comm: MPI.Comm, n_steps: int):
        mesh = space.mesh
        self.comm, self.names = comm, names
        self.displacement = fx.new_function(space, "strain_displacement")
        self.cells = fx.owned_cells(mesh)
        self.expression = fx.compile_quadrature_expression(
            green_lagrange_strain(self.displacement, shape_gradient), degree)
        self.region = np.asarray(region_of_input_cell)[fx.input_cell_indices(mesh)[self.cells]]
        self.region_cells = [np.flatnonzero(self.region == index) for index in range(len(names))]
        self.points = fx.quadrature_points(mesh, degree)[: self.cells.size]
        self.report = StrainReport(sampling_stride(n_steps), degree, names)
        self.n_steps = n_steps

    @classmethod
    def of_model(cls, fom, n_steps: int) -> "StrainProbe":
        """On the FOM's space, with its design's shape gradient (a separate displacement function)."""
        names, region = region_names(fom.scene, fom.fish.tags, fom.n_cells)
        return cls(fom.space, fom.shape_gradients["stiffness"], fom.quadrature_degrees["stiffness"], names, region,
                   fom.comm, n_steps)

    def observe(self, step: int, time: float, owned: np.ndarray) -> None:
        """Sample the owned displacement dofs ``owned`` at a sampled ``step``."""
        if is_sampled(step, self.n_steps, self.report.stride):
            started = clock.perf_counter()
            fx.set_owned_values(self.displacement, owned)
            self.sample(time)
            self.report.seconds += clock.perf_counter() - started

    def strains(self) -> np.ndarray:
        """(n_owned_cells, n_q, 3, 3) E at the current displacement."""
        values = fx.evaluate_expression(self.expression, self.cells)
        return values.reshape(self.cells.size, -1, 3, 3)

    def sample(self, time: float) -> None:
        """Add the current displacement's ε_max (with its region and point) to the report."""
        principal = largest_principal(self.strains()) if self.cells.size else np.zeros((0, 1))
        by_cell = principal.max(axis=1)
        by_region = {name: float(by_cell[cells].max()) if cells.size else -math.inf
                     for name, cells in zip(self.names, self.region_cells)}
        best = (-math.inf, 0, [0.0, 0.0, 0.0])
        if principal.size:
            cell, point = np.unravel_index(int(np.argmax(principal)), principal.shape)
            best = (float(principal[cell, point]), int(self.region[cell]), self.points[cell, point].tolist())
        if self.comm.size > 1:
            best = max(self.comm.allgather(best), key=lambda entry: entry[0])
            by_region = {name: max(values) for name, values in
                         zip(self.names, zip(*[list(d.values()) for d in self.comm.allgather(by_region)]))}
        by_region = {name: value for name, value in by_region.items() if value > -math.inf}
        self.report.add(time, best[0], self.names[best[1]], best[2], by_region)


def reduced_run_strains(scene, fish, xi, basis: np.ndarray, states: np.ndarray, times: np.ndarray,
                        comm: MPI.Comm = MPI.COMM_WORLD) -> StrainReport:
    """The report of a reduced run: u = V η of the (n_nodes, 3, m) nodal ``basis`` at the sampled
    ``states`` (n_samples, m) on the FOM's mesh of the fish, pulled back with the design ξ's exact ∇u_ξ."""
    from aquarom_fenics.geometry.fish import quadrature_degrees

    mesh = fx.create_tet_mesh(comm, fish.mesh.points, fish.mesh.cells)
    space = fx.vector_space(mesh, fish.degree)
    layout = fx.dof_layout(space, fish.nodes.nodes_of_pairs)
    degree = quadrature_degrees(fish.degree)["stiffness"]
    shape_gradient = fx.new_function(fx.quadrature_tensor_space(mesh, degree), "shape_gradient_stiffness")
    points = fx.quadrature_points(mesh, degree)
    fx.set_quadrature_values(shape_gradient, fish.shape_gradient(fish.parameter_vector(xi), points.reshape(-1, 3)))
    names, region = region_names(scene, fish.tags, fish.mesh.cells.shape[0])
    started = clock.perf_counter()
    n_steps = len(states) - 1
    probe = StrainProbe(space, shape_gradient, degree, names, region, comm, n_steps)
    for step in range(n_steps + 1):
        if is_sampled(step, n_steps, probe.report.stride):
            fx.set_nodal_values(probe.displacement, layout, basis @ states[step])
            probe.sample(times[step])
    probe.report.seconds = clock.perf_counter() - started
    return probe.report


def report_strains(report: StrainReport, warn: bool = True) -> None:
    """Log ε_max (info) and, with ``warn`` (a run that completed: a stopped one ends on its own error
    line), the warning line above the limit."""
    log.info("%s", report.line())
    warning = report.warning()
    if warning and warn:
        log.warning("%s", warning)
