"""The Lighthill thrust of ``thrust.py`` as a term of the FOM, on PETSc (SPEC §5).

``StationThrustTerm`` (the default, ``[fluid] stations = N_s``): the law on the station averages
x̄ = B(X + u_ξ + u), v̄ = B u̇, ā = B ü, acting on the body by f = Bᵀ F; the exact coupling Bᵀ J B
stays out of the sparse Newton matrix. ``NodalThrustTerm`` (``stations = "nodes"``, the source's
model, for comparison): the law on the spine nodes, its exact Jacobians in the Newton matrix.
Each projects itself on a basis into the ``ThrustTensors`` of ``thrust_reduced.py``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.shapes import shape_displacement
from aquarom_fenics.physics.stations import skin_line_heights
from aquarom_fenics.physics.thrust import SpineGeometry, added_mass_density, thrust_force, virtual_mass
from aquarom_fenics.physics.thrust_jacobians import thrust_jacobians
from aquarom_fenics.physics.thrust_reduced import ThrustTensors


def shape_rows(fish) -> np.ndarray:
    """U as (n_nodes, 3, p)."""
    return fish.shape_matrix.reshape(fish.nodes.points.shape[0], 3, -1)


def check_spine_is_not_moved(fish) -> None:
    """The nodal thrust (``stations = "nodes"``) keeps the spine's rest x-y in the PROM; no catalog
    shape moves it (all vanish on the axis)."""
    spine_rows = shape_rows(fish)[fish.tags.spine_nodes, :2]
    moving = np.flatnonzero(np.abs(spine_rows).max(axis=(0, 1)) > 1e-12 * max(fish.tags.box.length, 1.0))
    if moving.size:
        names = ", ".join(fish.shape_names[k] for k in moving)
        raise InputError(f"shape variations {names} move the spine in x-y; with [fluid] stations = \"nodes\" the "
                         "PROM supports shape variations that vanish on the body axis (use stations = N_s)")


class NodalThrustTerm:
    """The thrust on one FOM's spine nodes (tail -> head), from the rest shape of its design
    (``[fluid] stations = "nodes"``, not the default): the source's model, with its rear-node rule
    whatever ``[fluid] spine_rule`` says; its exact Jacobians go into the Newton matrix."""

    def __init__(self, fom, rest_points: np.ndarray):
        self.fom = fom
        tags, fluid = fom.fish.tags, fom.scene.fluid
        self.dorsal_z = rest_points[tags.dorsal_nodes, 2] - tags.box.z_axis
        self.spine = SpineGeometry(rest_points[tags.spine_nodes, :2], virtual_mass(self.dorsal_z, added_mass_density(fluid)),
                                   fluid.spine_force)

    def _spine_states(self, u, v, a):
        return [self.fom.spine_values(x)[:, :2] for x in (u, v, a)]

    def force(self, u, v, a) -> np.ndarray:
        """f_thrust scattered to the owned spine dofs (x, y) [N]."""
        fom = self.fom
        force = np.zeros(fom.n_owned_dofs)
        nodal = thrust_force(self.spine, *self._spine_states(u, v, a))
        for component in (0, 1):
            force[3 * fom.spine_blocks + component] = nodal[fom.spine_index, component]
        return force

    def _coupled_spine_dofs(self):
        """(spine index, its x-y global dofs, its neighbours' indices, their x-y global dofs) of every owned
        spine node: the force on a spine node depends on its own and its neighbours' states."""
        fom = self.fom
        n_spine = fom.spine_nodes.size
        spine_dofs = (3 * fom.spine_global_blocks[:, None] + np.arange(2)).astype(np.int32)
        for index in fom.spine_index:
            neighbours = np.arange(max(index - 1, 0), min(index + 2, n_spine))
            yield index, spine_dofs[index], neighbours, spine_dofs[neighbours].ravel()

    def newton_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """(global rows, global columns) of the entries ``add_newton_matrix`` adds."""
        pairs = [np.meshgrid(rows, columns, indexing="ij") for _, rows, _, columns in self._coupled_spine_dofs()]
        none = [np.zeros(0, dtype=np.int32)]          # a rank that owns no spine node
        return (np.concatenate(none + [rows.ravel() for rows, _ in pairs]),
                np.concatenate(none + [columns.ravel() for _, columns in pairs]))

    def add_newton_matrix(self, matrix: PETSc.Mat, scheme, u, v, a) -> None:
        """S += -(k_u ∂f/∂u + k_v ∂f/∂u̇ + k_a ∂f/∂ü) on the owned spine rows (f_thrust is on the right)."""
        jacobians = thrust_jacobians(self.spine, *self._spine_states(u, v, a))
        block = -(scheme.stiffness_factor * jacobians[0] + scheme.velocity_factor * jacobians[1]
                  + scheme.acceleration_factor * jacobians[2])
        for index, rows, neighbours, columns in self._coupled_spine_dofs():
            values = block[np.ix_(2 * index + np.arange(2), (2 * neighbours[:, None] + np.arange(2)).ravel())]
            matrix.setValues(rows, columns, values, addv=PETSc.InsertMode.ADD_VALUES)

    def reduce(self, projector) -> "ThrustTensors":
        """The spine rows of V, the rest spine and the dorsal heights with their exact ξ-gradient."""
        fom, tags = self.fom, self.fom.fish.tags
        spine_rows = np.stack([fom.rows_at(projector.vectors, node) for node in tags.spine_nodes])[:, :2]
        p = projector.n_parameters
        return ThrustTensors(rows=spine_rows, rest_xy=self.spine.rest_xy,
                          rest_xy_gradient=np.zeros(self.spine.rest_xy.shape + (p,)), dorsal_z=self.dorsal_z,
                          dorsal_z_gradient=shape_rows(fom.fish)[tags.dorsal_nodes, 2, :p],
                          fluid_density=added_mass_density(fom.scene.fluid))


class StationThrustTerm:
    """The thrust through the stations of one FOM (SPEC §5; the default, ``[fluid] stations = N_s``): station kinematics x̄ = B(X + u_ξ + u),
    v̄ = B u̇, ā = B ü, the Lighthill law of ``thrust.py`` on them, and f_thrust = Σ_i B_iᵀ F_i.

    The exact Jacobian Bᵀ J B couples whole slabs and stays out of the sparse Newton matrix; the
    matrix gets the lumped stand-in of the added mass, Σ_i b_ij m̃_i ℓ_0,i n_i n_iᵀ on node j's x-y
    block (exact for a rigid motion of a slab), and Newton converges on the exact residual.
    """

    def __init__(self, fom, rest_points: np.ndarray):
        self.fom = fom
        fish, fluid = fom.fish, fom.scene.fluid
        averages = fom.station_averages
        self.owned_weights = averages.weights[:, fom.layout.owned_nodes].tocsr()      # (N_s + 1, owned nodes)
        self.owned_weights_t = self.owned_weights.T.tocsr()
        rest_xy = averages.average(rest_points[:, :2])
        sections = station_sections(fish, averages.stations)
        self.rear_sections = sections.rows(slice(None, -1))
        self.front_sections = sections.rows(slice(1, None)) if fluid.spine_rule == "trapezoid" else None
        self.dorsal_z = self.half_depth(fom.xi, self.rear_sections)
        self.front_dorsal_z = (None if self.front_sections is None
                               else self.half_depth(fom.xi, self.front_sections))
        self.spine = SpineGeometry(rest_xy, virtual_mass(self.dorsal_z, added_mass_density(fluid)), fluid.spine_force,
                                   None if self.front_sections is None else virtual_mass(self.front_dorsal_z, added_mass_density(fluid)))
        n_owned = self.owned_weights.shape[1]
        self._block_rows = np.arange(n_owned + 1, dtype=np.int32)
        self._block_columns = fom.layout.global_block[:n_owned].astype(np.int32)

    def half_depth(self, xi: np.ndarray, sections: "StationSections") -> np.ndarray:
        """d/2 [m] of the design ξ at the ``sections`` (rear or front stations): the nominal half depth
        (z_top - z_bottom)/2 plus Σ_k ξ_k ∂(d/2)/∂ξ_k (exact, see ``half_depth_gradient``)."""
        nominal = 0.5 * (sections.top[:, 2] - sections.bottom[:, 2])
        return nominal + self.half_depth_gradient(xi.size, sections) @ xi if xi.size else nominal

    def half_depth_gradient(self, n_parameters: int, sections: "StationSections") -> np.ndarray:
        """(N_s, p) ∂(d/2)/∂ξ_k = (U_k,z(top) - U_k,z(bottom))/2 of the exact shape fields at each
        section's top and bottom skin points (= U_k,z(top) on a body symmetric about z = z_axis)."""
        fish = self.fom.fish
        names = fish.shape_names[:n_parameters]
        if not names:
            return np.zeros((sections.top.shape[0], 0))
        return np.column_stack([0.5 * (shape_displacement(name, sections.top, fish.tags.box)[:, 2]
                                       - shape_displacement(name, sections.bottom, fish.tags.box)[:, 2])
                                for name in names])

    def station_values(self, owned: np.ndarray) -> np.ndarray:
        """(N_s + 1, 2) x-y station averages B_i of an owned dof array, on every rank."""
        local = self.owned_weights @ owned.reshape(-1, 3)[:, :2]
        return self.fom.comm.allreduce(local, op=MPI.SUM)

    def _station_states(self, u, v, a):
        return [self.station_values(x) for x in (u, v, a)]

    def force(self, u, v, a) -> np.ndarray:
        """f_thrust = Σ_i B_iᵀ F_i on the owned dofs [N]."""
        stations = thrust_force(self.spine, *self._station_states(u, v, a))
        force = np.zeros((self.owned_weights.shape[1], 3))
        force[:, :2] = self.owned_weights_t @ stations
        return force.ravel()

    def newton_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """No entries beyond the tangent's pattern: the lumped added mass sits on the nodes' diagonal blocks."""
        none = np.zeros(0, dtype=np.int32)
        return none, none

    def add_newton_matrix(self, matrix: PETSc.Mat, scheme, u, v, a) -> None:
        """S += k_a Σ_i b_ij m̃_i ℓ_0,i n_i n_iᵀ on each owned node j's x-y block (the lumped -k_a ∂f/∂ü)."""
        added_mass = thrust_jacobians(self.spine, *self._station_states(u, v, a))[2]
        n = self.spine.n_nodes
        station_blocks = added_mass.reshape(n, 2, n, 2)[np.arange(n), :, np.arange(n), :]      # (n, 2, 2)
        nodal = (self.owned_weights_t @ station_blocks.reshape(n, 4)).reshape(-1, 2, 2)
        blocks = np.zeros((nodal.shape[0], 3, 3))
        blocks[:, :2, :2] = -scheme.acceleration_factor * nodal
        matrix.setValuesBlockedCSR(self._block_rows, self._block_columns, blocks.ravel(),
                                   addv=PETSc.InsertMode.ADD_VALUES)

    def _coupling(self, factors, u, v, a):
        """(-(k_u J_u + k_v J_u̇ + k_a J_ü) in station space, (2(N_s+1))², and the lumped added mass
        -k_a Σ_i b_ij J_ü,ii per owned node, (n, 2, 2)) for the factors k of a tangent combination."""
        jacobians = thrust_jacobians(self.spine, *self._station_states(u, v, a))
        station_block = -(factors.stiffness_factor * jacobians[0] + factors.velocity_factor * jacobians[1]
                          + factors.acceleration_factor * jacobians[2])
        n = self.spine.n_nodes
        added_mass = jacobians[2].reshape(n, 2, n, 2)[np.arange(n), :, np.arange(n), :]
        lumped = -factors.acceleration_factor * (self.owned_weights_t @ added_mass.reshape(n, 4)).reshape(-1, 2, 2)
        return station_block, lumped

    def coupling_block(self, factors, u, v, a, dofs: np.ndarray) -> np.ndarray:
        """The dense block (S_exact - S_matrix)[dofs, dofs] of one rank's owned ``dofs`` (a small region)."""
        station_block, lumped = self._coupling(factors, u, v, a)
        nodes, components = dofs // 3, dofs % 3
        planar = components < 2
        averaging = np.zeros((self.spine.n_nodes, 2, dofs.size))        # B restricted to the dofs
        averaging[:, components[planar], np.flatnonzero(planar)] = self.owned_weights[:, nodes[planar]].toarray()
        averaging = averaging.reshape(-1, dofs.size)
        block = averaging.T @ station_block @ averaging
        same_node = (nodes[:, None] == nodes[None, :]) & planar[:, None] & planar[None, :]
        rows, columns = np.nonzero(same_node)
        block[rows, columns] -= lumped[nodes[rows], components[rows], components[columns]]
        return block

    def newton_correction(self, scheme, u, v, a):
        """x ↦ (S_exact - S_matrix) x of the thrust at (u, u̇, ü): -Bᵀ (k_u J_u + k_v J_u̇ + k_a J_ü) B x, the
        exact coupling of the stations, less the lumped added mass the matrix holds (owned dofs)."""
        station_block, lumped = self._coupling(scheme, u, v, a)

        def apply(x: np.ndarray) -> np.ndarray:
            nodal = x.reshape(-1, 3)[:, :2]
            correction = np.zeros((nodal.shape[0], 3))
            stations = (station_block @ self.station_values(x).ravel()).reshape(-1, 2)
            correction[:, :2] = self.owned_weights_t @ stations - np.einsum("jab,jb->ja", lumped, nodal)
            return correction.ravel()
        return apply

    def reduce(self, projector) -> "ThrustTensors":
        """B V (station kinematics exact in η and ξ), the rest stations with their exact ξ-gradient B U,
        and the half depths with theirs."""
        fom = self.fom
        p, m = projector.n_parameters, projector.vectors.shape[1]
        columns = projector.vectors.reshape(-1, 3, m)[:, :2, :].reshape(-1, 2 * m)
        rows = fom.comm.allreduce(self.owned_weights @ columns, op=MPI.SUM).reshape(-1, 2, m)
        shape_xy = shape_rows(fom.fish)[:, :2, :p].reshape(fom.fish.nodes.points.shape[0], 2 * p)
        rest_gradient = fom.station_averages.weights @ shape_xy
        front = {} if self.front_sections is None else {
            "front_dorsal_z": self.front_dorsal_z,
            "front_dorsal_z_gradient": self.half_depth_gradient(p, self.front_sections)}
        return ThrustTensors(rows=rows, rest_xy=self.spine.rest_xy, rest_xy_gradient=np.asarray(rest_gradient).reshape(self.spine.n_nodes, 2, p),
                          dorsal_z=self.dorsal_z, dorsal_z_gradient=self.half_depth_gradient(p, self.rear_sections),
                          fluid_density=added_mass_density(fom.scene.fluid), **front)


@dataclass(frozen=True)
class StationSections:
    """Where each station's vertical line x = X_i, y = y_axis meets the nominal skin: its highest point
    ``top`` and lowest ``bottom``, (n, 3) relative positions [m] (x_rel, 0, z_rel), tail -> head. The
    body's depth there is d = z_top - z_bottom (SPEC §5: d = 2 z_dorsal on a body symmetric about its
    axis, like the block)."""

    top: np.ndarray
    bottom: np.ndarray

    def rows(self, selection) -> "StationSections":
        return StationSections(self.top[selection], self.bottom[selection])


def station_sections(fish, stations: np.ndarray) -> StationSections:
    """The ``StationSections`` at the nominal x [m] of every station (``stations``, N_s + 1, tail -> head;
    the rear stations are all but the last, the front ones all but the first), from the body's own
    skin: no nodes on the axis or on y = 0 are needed.

    An end station whose line misses the skin (a body tapering to a point off the line) has depth 0;
    InputError when the line of an inner station misses it (the body does not cross its mid-plane
    y = y_axis there). Kept on the fish (its nominal skin's): a model moved to another design asks again."""
    key = ("station_sections", np.asarray(stations, dtype=float).tobytes())
    if key not in fish.derived:
        fish.derived[key] = _station_sections(fish, stations)
    return fish.derived[key]


def _station_sections(fish, stations: np.ndarray) -> StationSections:
    tags = fish.tags
    relative = tags.box.relative(fish.mesh.points)
    station_x = np.asarray(stations, dtype=float) - tags.box.x_head
    top, bottom = skin_line_heights(relative, tags.skin_facets, station_x, 0.0)
    missed = np.flatnonzero(np.isnan(top))
    inner = missed[(missed > 0) & (missed < station_x.size - 1)]
    if inner.size:
        raise InputError(f"mesh {fish.mesh.source}: the vertical line y = {tags.box.y_axis:.6g} m at station {inner[0]}, "
                         f"x = {stations[inner[0]]:.6g} m, misses the body; the stations need a body that "
                         "crosses its mid-plane y = y_axis along its whole length")
    top[missed] = bottom[missed] = 0.0
    zeros = np.zeros_like(station_x)
    sections = StationSections(np.column_stack([station_x, zeros, top]), np.column_stack([station_x, zeros, bottom]))
    sections.top.flags.writeable = sections.bottom.flags.writeable = False
    return sections
