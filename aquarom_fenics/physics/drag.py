"""Form drag (SPEC §5): f_drag = g(ξ) v_x², v_x = w·u̇ the head's x-velocity.

w averages u̇_x over the head's volume (with ``[fluid] stations = "nodes"``: the head node's u̇_x).
g is the skin form of ``forms/drag.py`` on the rest shape. The law, its Jacobian
∂f/∂u̇ = 2 g v_x wᵀ (rank one) and its ξ-derivative ∂f/∂ξ_k = (∂g/∂ξ_k) v_x² are written here once,
for the full and the reduced model. In the FOM's Newton matrix only the single-column Jacobian of
the nodal model is kept; the head average's (dense over the head) is left to the Newton updates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from petsc4py import PETSc

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.drag import drag_direction_form
from aquarom_fenics.physics.taylor import Taylor


def drag_fluid_density(fluid) -> float:
    """c_D ρ_w [kg/m³]: ``[fluid] drag_factor`` × ``density``, the density g is linear in (C_d = 2 c_D (n·e_x)²)."""
    return fluid.density * fluid.drag_factor


def drag_force(direction: np.ndarray, head_velocity_x: float) -> np.ndarray:
    """f = g v_x² [N]; with ∂g/∂ξ_k (shape (p, n)) in place of g, ∂f/∂ξ_k."""
    return direction * head_velocity_x ** 2


def drag_velocity_jacobian(direction: np.ndarray, head_velocity_x: float) -> np.ndarray:
    """∂f/∂v_x = 2 g v_x [N s/m]: the column of ∂f/∂u̇ at the head's x dof."""
    return 2.0 * head_velocity_x * direction


class DragTerm:
    """g assembled on the FOM's rest shape; the force and its column of the Newton matrix."""

    def __init__(self, fom):
        self.fom = fom
        fluid_density = fx.constant(fom.mesh, drag_fluid_density(fom.scene.fluid))
        # The skin of the rest shape: u_ξ interpolated at the displacement nodes (SPEC §5).
        self.direction_form = fom.mass_rule(drag_direction_form(
            fom.test_function, ufl.grad(fom.shape_displacement), fluid_density, fom.mesh))
        self._compiled = fx.compile_form(self.direction_form)
        self._vector = fx.create_vector(self._compiled)
        self.assemble()

    def destroy(self) -> None:
        """Release g's PETSc vector."""
        self._vector.destroy()

    def assemble(self) -> None:
        """g at the FOM's design (again after the design moved), its rows."""
        self.direction = fx.assemble_vector_into(self._vector, self._compiled).copy()
        self.rows = np.flatnonzero(self.direction)
        self.global_rows = self.fom.global_dofs(self.rows)

    def force(self, v: np.ndarray) -> np.ndarray:
        """f_drag on the owned dofs [N]."""
        return drag_force(self.direction, self.fom.head_velocity_x(v))

    @property
    def nodal(self) -> bool:
        """The nodal model: v_x of the head node, whose Jacobian column goes into the Newton matrix."""
        return self.fom.station_averages is None

    def newton_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """(global rows, global columns) of the entries ``add_newton_matrix`` adds: the head x column."""
        if not self.nodal:
            none = np.zeros(0, dtype=np.int32)
            return none, none
        return self.global_rows, np.full(self.global_rows.size, self.fom.head_x_global_dof)

    def add_newton_matrix(self, matrix: PETSc.Mat, velocity_factor: float, v: np.ndarray) -> None:
        """S += -k_v ∂f/∂u̇ (f_drag is on the right of the equations of motion), for the nodal model."""
        if not self.nodal:
            return
        column = drag_velocity_jacobian(self.direction[self.rows], self.fom.head_velocity_x(v))
        head = np.array([self.fom.head_x_global_dof], dtype=np.int32)
        matrix.setValues(self.global_rows, head, (-velocity_factor * column).reshape(-1, 1), addv=PETSc.InsertMode.ADD_VALUES)

    def newton_correction(self, velocity_factor: float, v: np.ndarray):
        """x ↦ (S_exact - S_matrix) x of the head-averaged drag: -k_v 2 g v_x (w·x) (rank one), None for
        the nodal model (its column is in the matrix)."""
        if self.nodal:
            return None
        column = -velocity_factor * drag_velocity_jacobian(self.direction, self.fom.head_velocity_x(v))
        return lambda x: column * self.fom.head_velocity_x(x)

    def coupling_block(self, velocity_factor: float, v: np.ndarray, dofs: np.ndarray) -> np.ndarray | None:
        """(S_exact - S_matrix)[dofs, dofs] = -k_v 2 v_x g_R w_Rᵀ on owned ``dofs``; None for the nodal model."""
        if self.nodal:
            return None
        fom = self.fom
        weights = np.zeros(fom.n_owned_dofs)
        weights[fom._head_velocity_dofs] = fom._head_velocity_weights
        column = -velocity_factor * drag_velocity_jacobian(self.direction[dofs], fom.head_velocity_x(v))
        return np.outer(column, weights[dofs])

    def reduce(self, projector) -> "DragTensors":
        return DragTensors(projector.taylor(self.direction_form), self.fom.head_velocity_row(projector.vectors))


@dataclass
class DragTensors:
    """The reduced drag: f_drag,r = g_r v_x², v_x = (wᵀ V)·η̇."""

    direction: Taylor                    # g_r = Vᵀ g, (m,)
    velocity_row: np.ndarray             # (m,) wᵀ V: the head's x-velocity from η̇

    def at(self, delta: np.ndarray) -> "ReducedDrag":
        return ReducedDrag(self, delta, self.velocity_row)


class ReducedDrag:
    """The reduced drag at one design ξ (a :class:`ReducedTerm`)."""

    def __init__(self, tensors: DragTensors, delta: np.ndarray, velocity_row: np.ndarray):
        self.tensors, self.delta, self.velocity_row = tensors, delta, velocity_row
        self.direction = tensors.direction.at(delta)
        self.direction_gradient = tensors.direction.gradient(delta)            # ∂g_r/∂ξ_k, (p, m)

    def force(self, eta_dot: np.ndarray) -> np.ndarray:
        return drag_force(self.direction, self.velocity_row @ eta_dot)

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """C_t part -∂f/∂η̇ = -2 g_r v_x (wᵀ V)ᵀ."""
        column = drag_velocity_jacobian(self.direction, self.velocity_row @ eta_dot)
        return None, np.multiply.outer(-column, self.velocity_row), None

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        return -drag_force(self.direction_gradient, self.velocity_row @ eta_dot)
