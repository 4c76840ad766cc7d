"""The Lighthill thrust of ``thrust.py`` as a term of the full and the reduced model (SPEC §5, §8).

FOM: the force on the spine nodes' x-y dofs and its exact Jacobians in the Newton matrix.
Reduced: the same law, evaluated exactly on the reduced spine coordinates x_spine = V_spine η;
its virtual mass is quadratic in ξ (z_dorsal linear), the spine's rest x-y does not move with the
catalog's shape variations (checked when the PROM is built).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from aquarom_fenics.errors import InputError
from aquarom_fenics.physics.thrust import (SpineGeometry, thrust_force, thrust_force_per_virtual_mass,
                                           thrust_jacobians, virtual_mass, virtual_mass_gradient)


def shape_rows(fish) -> np.ndarray:
    """U as (n_nodes, 3, p)."""
    return fish.shape_matrix.reshape(fish.nodes.points.shape[0], 3, -1)


def check_spine_is_not_moved(fish) -> None:
    """The reduced thrust keeps the spine's rest x-y; no catalog shape moves it (all vanish on the axis)."""
    spine_rows = shape_rows(fish)[fish.tags.spine_nodes, :2]
    moving = np.flatnonzero(np.abs(spine_rows).max(axis=(0, 1)) > 1e-12 * max(fish.tags.box.length, 1.0))
    if moving.size:
        names = ", ".join(fish.shape_names[k] for k in moving)
        raise InputError(f"shape variations {names} move the spine in x-y; the PROM supports shape "
                         "variations that vanish on the body axis")


class ThrustTerm:
    """The thrust on one FOM's spine nodes (tail -> head), from the rest shape of its design."""

    def __init__(self, fom, rest_points: np.ndarray):
        self.fom = fom
        tags, fluid = fom.fish.tags, fom.scene.fluid
        self.dorsal_z = rest_points[tags.dorsal_nodes, 2] - tags.box.z_axis
        self.spine = SpineGeometry(rest_points[tags.spine_nodes, :2], virtual_mass(self.dorsal_z, fluid.density),
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

    def reduce(self, projector) -> "ThrustData":
        """The spine rows of V, the rest spine and the dorsal heights with their exact ξ-gradient."""
        fom, tags = self.fom, self.fom.fish.tags
        spine_rows = np.stack([fom.rows_at(projector.vectors, node) for node in tags.spine_nodes])[:, :2]
        return ThrustData(spine_rows=spine_rows, spine_rest_xy=self.spine.rest_xy, dorsal_z=self.dorsal_z,
                          dorsal_z_gradient=shape_rows(fom.fish)[tags.dorsal_nodes, 2, :projector.n_parameters],
                          fluid_density=fom.scene.fluid.density)


@dataclass
class ThrustData:
    """What the reduced thrust needs: f_thrust,r = V_spineᵀ f_thrust(V_spine η, V_spine η̇, V_spine η̈; ξ)."""

    spine_rows: np.ndarray               # (n_spine, 2, m): x-y rows of V at the spine nodes
    spine_rest_xy: np.ndarray            # (n_spine, 2) at ξ_c
    dorsal_z: np.ndarray                 # (n_segments,) z_dorsal - z_axis at ξ_c
    dorsal_z_gradient: np.ndarray        # (n_segments, p) ∂z_dorsal/∂ξ (U rows: exact)
    fluid_density: float                 # ρ_w [kg/m³]

    def at(self, delta: np.ndarray, spine_force: str) -> "ReducedThrust":
        return ReducedThrust(self, delta, spine_force)


class ReducedThrust:
    """The reduced thrust at one design ξ (a :class:`ReducedTerm`)."""

    def __init__(self, data: ThrustData, delta: np.ndarray, spine_force: str):
        self.data = data
        self.dorsal_z = data.dorsal_z + data.dorsal_z_gradient @ delta if delta.size else data.dorsal_z
        self.spine = SpineGeometry(data.spine_rest_xy, virtual_mass(self.dorsal_z, data.fluid_density), spine_force)
        self.rows = data.spine_rows.reshape(-1, data.spine_rows.shape[-1])      # (2 n_spine, m)

    def _spine_states(self, eta, eta_dot, eta_ddot):
        return [(self.rows @ x).reshape(-1, 2) for x in (eta, eta_dot, eta_ddot)]

    def force(self, eta, eta_dot, eta_ddot) -> np.ndarray:
        return self.rows.T @ thrust_force(self.spine, *self._spine_states(eta, eta_dot, eta_ddot)).ravel()

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """-V_spineᵀ (∂f/∂u, ∂f/∂u̇, ∂f/∂ü) V_spine."""
        jacobians = thrust_jacobians(self.spine, *self._spine_states(eta, eta_dot, eta_ddot))
        return tuple(-(self.rows.T @ jacobian @ self.rows) for jacobian in jacobians)

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """-V_spineᵀ Σ_i (∂f/∂m̃_i) ∂m̃_i/∂ξ_k, shape (p, m)."""
        per_mass = thrust_force_per_virtual_mass(self.spine, *self._spine_states(eta, eta_dot, eta_ddot))
        mass_gradient = virtual_mass_gradient(self.dorsal_z, self.data.dorsal_z_gradient, self.data.fluid_density)
        thrust_k = np.einsum("snc,sk->knc", per_mass, mass_gradient).reshape(mass_gradient.shape[1], -1)
        return -(thrust_k @ self.rows)
