"""Full-order model of the swimmer (SPEC §5): the validation reference.

    M ü + C u̇ + f_int(u) = f_thrust(u, u̇, ü) + f_drag(u̇) + f_act(u, t)

on a distributed linear tetrahedral mesh with a degree-1 or degree-2 Lagrange displacement and
PETSc. The elastic, muscle, mass and drag terms are the UFL forms of ``forms/``; the Lighthill
thrust acts on the spine nodes (``thrust.py``). A design ξ is either pulled back (forms on the
nominal mesh with F_1 = I + ∇u_ξ, ∇u_ξ = Σ ξ_k ∇U_k of the exact shape fields at the quadrature
points, SPEC §4) or meshed directly (``moved_mesh``, u_ξ = 0).
"""
from __future__ import annotations

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from ufl.algorithms import extract_coefficients

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.geometry.fish import Fish, quadrature_degrees
from aquarom_fenics.forms.drag import drag_direction_form
from aquarom_fenics.forms.elasticity import strain_energy
from aquarom_fenics.forms.inertia import mass_form, mass_moment_x, total_mass
from aquarom_fenics.forms.muscle import muscle_energy
from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.errors import SolverError
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.thrust import SpineGeometry, thrust_force, thrust_jacobians, virtual_mass

LEFT, RIGHT = 0, 1


def direct_solver(comm: MPI.Comm) -> PETSc.KSP:
    """LU with MUMPS; the factors are kept until the operator changes."""
    solver = PETSc.KSP().create(comm)
    solver.setType("preonly")
    preconditioner = solver.getPC()
    preconditioner.setType("lu")
    preconditioner.setFactorSolverType("mumps")
    return solver


MUMPS_ERRORS = {-6: "structurally singular matrix", -9: "work array too small",
                -10: "numerically singular matrix", -13: "out of memory"}
"""Meaning of the negative INFOG(1) codes of a failed MUMPS factorisation."""


def describe_linear_solve(solver: PETSc.KSP) -> str:
    """KSP converged reason of the last solve and, for MUMPS, INFOG(1) of its factorisation."""
    reasons = {value: name for name, value in vars(PETSc.KSP.ConvergedReason).items() if name.isupper()}
    reason = solver.getConvergedReason()
    text = f"KSP {reasons.get(reason, reason)}"
    if solver.getPC().getFactorSolverType() != "mumps":
        return text
    try:
        info = solver.getPC().getFactorMatrix().getMumpsInfog(1)
    except PETSc.Error:
        return text
    return f"{text}, MUMPS INFOG(1) = {info}" + (f": {MUMPS_ERRORS[info]}" if info in MUMPS_ERRORS else "")


class FullOrderModel:
    """One design of a scene, ready to be integrated in time (implements ``NewtonSystem``)."""

    def __init__(self, scene: Scene, fish: Fish, xi=None, moved_mesh: bool = False,
                 comm: MPI.Comm = MPI.COMM_WORLD):
        self.scene, self.fish, self.comm = scene, fish, comm
        self.xi = fish.parameter_vector(xi)
        self.moved_mesh = moved_mesh
        rest_points = fish.design(self.xi)
        shape_displacement = np.zeros_like(rest_points) if moved_mesh else rest_points - fish.nodes.points
        mesh_points = rest_points[:fish.nodes.n_vertices] if moved_mesh else fish.mesh.points
        self.rest_points = rest_points

        self.mesh = fx.create_tet_mesh(comm, mesh_points, fish.mesh.cells)
        self.space = fx.vector_space(self.mesh, fish.degree)
        self.layout = fx.dof_layout(self.space, fish.nodes.nodes_of_pairs)
        self.n_owned_dofs = 3 * self.layout.n_owned_blocks
        self.n_global_dofs = 3 * self.space.dofmap.index_map.size_global
        self.n_cells = fish.mesh.cells.shape[0]

        self.displacement = fx.new_function(self.space, "displacement")
        self.shape_displacement = fx.new_function(self.space, "shape_displacement")
        fx.set_nodal_values(self.shape_displacement, self.layout, shape_displacement)
        self._build_shape_gradients(np.zeros_like(self.xi) if moved_mesh else self.xi)
        self._build_forms()
        self._build_spine(rest_points)
        self._build_boundary_conditions()
        self._build_constant_matrices()
        self._work_in = PETSc.Vec().createMPI((self.n_owned_dofs, self.n_global_dofs), comm=comm)
        self._work_out = self._work_in.duplicate()
        self._solver = None
        self.set_time_step(TimeScheme.from_solver(scene.solver))

    # ------------------------------------------------------------------ set-up
    def _cell_field(self, values_by_cell: np.ndarray, name: str):
        field = fx.new_function(fx.cellwise_constant_space(self.mesh), name)
        fx.set_cell_values(field, values_by_cell)
        return field

    def _build_shape_gradients(self, xi: np.ndarray) -> None:
        """∇u_ξ = Σ_k ξ_k ∇U_k, exact, at the points of each quadrature rule (SPEC §4)."""
        self.quadrature_degrees = quadrature_degrees(self.fish.degree)
        self.quadrature_points = {family: fx.quadrature_points(self.mesh, degree)
                                  for family, degree in self.quadrature_degrees.items()}
        self.shape_gradients = {}
        for family, degree in self.quadrature_degrees.items():
            gradient = fx.new_function(fx.quadrature_tensor_space(self.mesh, degree), f"shape_gradient_{family}")
            points = self.quadrature_points[family]
            fx.set_quadrature_values(gradient, self.fish.shape_gradient(xi, points.reshape(-1, 3)))
            self.shape_gradients[family] = gradient

    def shape_direction(self, name: str) -> "ShapeDirection":
        """A design direction δξ as coefficients of this model's forms (see ``shape_derivative``).

        Only on the pulled-back model: ∇U_k is the gradient with respect to nominal coordinates.
        """
        if self.moved_mesh:
            raise ValueError("shape derivatives need the design pulled back to the nominal mesh (moved_mesh=False)")
        return ShapeDirection(self, name)

    def shape_derivative(self, form, direction: "ShapeDirection"):
        """d/dε form(ξ + ε δξ) at ε = 0: the UFL derivative along δu_ξ = U δξ and ∇δu_ξ = ∇U δξ
        of every shape coefficient that appears in the form."""
        present = set(extract_coefficients(form))
        terms = [ufl.derivative(form, coefficient, variation) for coefficient, variation in direction.pairs()
                 if coefficient in present]
        return sum(terms[1:], terms[0])

    def _build_forms(self):
        scene, tags = self.scene, self.fish.tags
        material = scene.material
        stiffness_by_cell = np.full(self.n_cells, material.young_modulus)
        stiffness_by_cell[tags.head_cells] *= material.head_stiffness_factor
        young_modulus = self._cell_field(stiffness_by_cell, "young_modulus")
        muscles = []
        for cells, name in ((tags.left_muscle_cells, "left_muscle"), (tags.right_muscle_cells, "right_muscle")):
            indicator = np.zeros(self.n_cells)
            indicator[cells] = 1.0
            muscles.append(self._cell_field(indicator, name))
        self.activations = [fx.constant(self.mesh, 0.0), fx.constant(self.mesh, 0.0)]

        # Values enter as constants so that one compiled form serves every scene and design.
        poisson_ratio = fx.constant(self.mesh, material.poisson_ratio)
        density = fx.constant(self.mesh, material.density)
        muscle_stiffness = fx.constant(self.mesh, scene.actuation.stiffness)
        fluid_density = fx.constant(self.mesh, scene.fluid.density)
        u = self.displacement
        grad_stiffness, grad_mass = self.shape_gradients["stiffness"], self.shape_gradients["mass"]
        test, trial = ufl.TestFunction(self.space), ufl.TrialFunction(self.space)
        elastic_energy = self._stiffness_rule(strain_energy(u, grad_stiffness, young_modulus, poisson_ratio))
        internal_force = ufl.derivative(elastic_energy, u, test)
        self.actuation_on = scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0
        tangent = ufl.derivative(internal_force, u, trial)
        forms = {"internal_force": internal_force, "elastic_energy": elastic_energy,
                 "elastic_tangent": tangent}
        if self.actuation_on:
            energy = self._stiffness_rule(muscle_energy(
                u, grad_stiffness, muscle_stiffness, self.activations, muscles,
                nominal_volume=scene.actuation.muscle_volume == "nominal"))
            negative_actuation = ufl.derivative(energy, u, test)
            forms["negative_actuation_force"] = negative_actuation
            tangent = tangent + ufl.derivative(negative_actuation, u, trial)
        forms["tangent"] = tangent
        forms["mass"] = self._mass_rule(mass_form(trial, test, grad_mass, density))
        forms["mass_moment_x"] = self._mass_rule(mass_moment_x(test, grad_mass, density))
        forms["total_mass"] = self._mass_rule(total_mass(grad_mass, density, self.mesh))
        if scene.fluid.drag:
            # The skin of the rest shape: u_ξ interpolated at the displacement nodes (SPEC §5).
            forms["drag_direction"] = self._mass_rule(drag_direction_form(
                test, ufl.grad(self.shape_displacement), fluid_density, self.mesh))
        self.ufl_forms = forms
        self.young_modulus, self.muscle_indicators = young_modulus, muscles
        self.forms = {name: fx.compile_form(form) for name, form in forms.items()}
        self._vectors = {name: fx.create_vector(self.forms[name])
                         for name in ("internal_force", "negative_actuation_force") if name in self.forms}
        self.tangent_matrix = fx.create_matrix(self.forms["tangent"])
        self.tangent_matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)

    def _stiffness_rule(self, form):
        return fx.with_quadrature_degree(form, self.quadrature_degrees["stiffness"])

    def _mass_rule(self, form):
        return fx.with_quadrature_degree(form, self.quadrature_degrees["mass"])

    def owned_positions(self, nodes: np.ndarray):
        """(owned local blocks, index into ``nodes``) of the given input nodes owned by this rank."""
        lookup = np.full(self.fish.nodes.points.shape[0], -1)
        lookup[nodes] = np.arange(nodes.size)
        position = lookup[self.layout.owned_nodes]
        blocks = np.flatnonzero(position >= 0)
        return blocks, position[blocks]

    def _build_spine(self, rest_points):
        tags = self.fish.tags
        self.spine_nodes = tags.spine_nodes
        self._spine_blocks, self._spine_index = self.owned_positions(self.spine_nodes)
        global_blocks = np.zeros(self.spine_nodes.size, dtype=np.int64)
        global_blocks[self._spine_index] = self.layout.global_block[self._spine_blocks]
        self._spine_global_blocks = self.comm.allreduce(global_blocks, op=MPI.SUM)
        dorsal_z = rest_points[tags.dorsal_nodes, 2] - tags.box.z_axis
        self.spine = SpineGeometry(rest_points[self.spine_nodes, :2],
                                   virtual_mass(dorsal_z, self.scene.fluid.density), self.scene.fluid.spine_force)
        self.thrust_on = self.scene.fluid.thrust

    def _build_boundary_conditions(self):
        """Swimming: head nodes fixed in y and z, free in x (SPEC §5). Clamped: all head dofs."""
        head = self.fish.tags.head_nodes
        self.fixed_dofs = self._head_dofs(head, (1, 2))
        self.clamped_dofs = self._head_dofs(head, (0, 1, 2))

    def _head_dofs(self, head_nodes, components) -> np.ndarray:
        return np.sort(np.concatenate([fx.sub_space_dofs_of_nodes(self.space, self.layout, head_nodes, c)
                                       for c in components]))

    def global_dofs(self, owned_dofs: np.ndarray) -> np.ndarray:
        """PETSc global indices of owned local dof indices."""
        return (3 * self.layout.global_block[owned_dofs // 3] + owned_dofs % 3).astype(np.int32)

    def _build_constant_matrices(self):
        material = self.scene.material
        self.mass_matrix = fx.assemble_matrix_into(fx.create_matrix(self.forms["mass"]), self.forms["mass"])
        if material.mass == "lumped":
            row_sums = self.mass_matrix.getRowSum()
            self.mass_matrix.zeroEntries()
            self.mass_matrix.setDiagonal(row_sums)
            self.mass_matrix.assemble()
        self.displacement.x.array[:] = 0.0
        self.rest_stiffness = fx.assemble_matrix_into(fx.create_matrix(self.forms["elastic_tangent"]),
                                                      self.forms["elastic_tangent"])
        self.damping_matrix = self.mass_matrix.copy()
        self.damping_matrix.scale(material.rayleigh_alpha)
        self.damping_matrix.axpy(material.rayleigh_beta, self.rest_stiffness)
        moment = fx.create_vector(self.forms["mass_moment_x"])
        self._com_weights = fx.assemble_vector_into(moment, self.forms["mass_moment_x"]).copy()
        self.total_mass = fx.assemble_scalar(self.forms["total_mass"], self.comm)
        if self.scene.fluid.drag:
            drag = fx.create_vector(self.forms["drag_direction"])
            self._drag_direction = fx.assemble_vector_into(drag, self.forms["drag_direction"]).copy()
            self._drag_rows = np.flatnonzero(self._drag_direction)
        head = self.owned_positions(np.array([self.fish.tags.head_spine_node]))[0]
        self._head_x_owned = 3 * head  # empty on ranks that do not own the head node

    def set_time_step(self, scheme: TimeScheme) -> None:
        """The scheme's factors enter S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t."""
        self.scheme = scheme
        self._inertia_damping = self.mass_matrix.copy()
        self._inertia_damping.scale(scheme.acceleration_factor)
        self._inertia_damping.axpy(scheme.velocity_factor, self.damping_matrix)
        self._inertia_damping_on_newton_pattern = None

    # ------------------------------------------------------------------ evaluations
    def _set_state(self, time: float, u: np.ndarray) -> None:
        fx.set_owned_values(self.displacement, u)
        actuation = self.scene.actuation
        activation = actuation.amplitude * np.sin(2.0 * np.pi * actuation.frequency * time)
        self.activations[LEFT].value = activation
        self.activations[RIGHT].value = -activation

    def matvec(self, matrix: PETSc.Mat, x: np.ndarray) -> np.ndarray:
        self._work_in.array[:] = x
        matrix.mult(self._work_in, self._work_out)
        return self._work_out.array.copy()

    def spine_values(self, owned: np.ndarray) -> np.ndarray:
        """(n_spine, 3) nodal values of an owned dof array at the spine nodes, on every rank."""
        local = np.zeros((self.spine_nodes.size, 3))
        local[self._spine_index] = owned.reshape(-1, 3)[self._spine_blocks]
        return self.comm.allreduce(local, op=MPI.SUM)

    def head_velocity_x(self, v: np.ndarray) -> float:
        return self.comm.allreduce(float(v[self._head_x_owned].sum()), op=MPI.SUM)

    def internal_force(self, u: np.ndarray) -> np.ndarray:
        """f_int(u) = ∂Π/∂u, owned entries [N]."""
        fx.set_owned_values(self.displacement, u)
        return fx.assemble_vector_into(self._vectors["internal_force"], self.forms["internal_force"]).copy()

    def actuation_force(self, time: float, u: np.ndarray) -> np.ndarray:
        """f_act(u, t) = -∂Π_act/∂u [N]."""
        self._set_state(time, u)
        return self._actuation_force_at_current_state()

    def _actuation_force_at_current_state(self) -> np.ndarray:
        if not self.actuation_on:
            return np.zeros(self.n_owned_dofs)
        return -fx.assemble_vector_into(self._vectors["negative_actuation_force"],
                                        self.forms["negative_actuation_force"])

    def thrust_force(self, u, v, a) -> np.ndarray:
        """Lighthill thrust scattered to the owned spine dofs (x, y) [N]."""
        force = np.zeros(self.n_owned_dofs)
        if self.thrust_on:
            nodal = thrust_force(self.spine, *(self.spine_values(x)[:, :2] for x in (u, v, a)))
            for component in (0, 1):
                force[3 * self._spine_blocks + component] = nodal[self._spine_index, component]
        return force

    def drag_force(self, v) -> np.ndarray:
        """f_drag = g(ξ) v_x² with v_x the head's x-velocity [N]."""
        if not self.scene.fluid.drag:
            return np.zeros(self.n_owned_dofs)
        return self._drag_direction * self.head_velocity_x(v) ** 2

    def residual(self, time, u, v, a):
        """r = M ü + C u̇ + f_int - f_act - f_thrust - f_drag (zero on fixed dofs), and the force scale."""
        self._set_state(time, u)
        inertia = self.matvec(self.mass_matrix, a)
        internal = fx.assemble_vector_into(self._vectors["internal_force"], self.forms["internal_force"]).copy()
        external = self._actuation_force_at_current_state() + self.thrust_force(u, v, a) + self.drag_force(v)
        residual = inertia + self.matvec(self.damping_matrix, v) + internal - external
        residual[self.fixed_dofs] = 0.0
        scale = max(self.norm(internal), self.norm(external), self.norm(inertia))
        return residual, scale

    def assemble_newton_matrix(self, time, u, v, a) -> PETSc.Mat:
        """S = ∂r_{n+1-α}/∂u_{n+1} = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t at the
        evaluation point (t, u, u̇, ü), with the exact thrust and drag Jacobians."""
        self._set_state(time, u)
        matrix = fx.assemble_matrix_into(self.tangent_matrix, self.forms["tangent"])
        if self.scheme.stiffness_factor != 1.0:
            matrix.scale(self.scheme.stiffness_factor)
        if self.thrust_on:
            self._add_thrust_jacobian(matrix, u, v, a)
        if self.scene.fluid.drag:
            self._add_drag_jacobian(matrix, v)
        matrix.assemble()
        matrix.axpy(1.0, self._inertia_damping_on(matrix), structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        matrix.zeroRowsColumns(self.global_dofs(self.fixed_dofs), diag=1.0)
        return matrix

    def _inertia_damping_on(self, matrix: PETSc.Mat) -> PETSc.Mat:
        """(1 - α_f)(γ/(βh)) C + ((1 - α_m)/(βh²)) M stored on the pattern of the Newton matrix (tangent,
        thrust and drag entries), so that adding it is one pass over the values."""
        if self._inertia_damping_on_newton_pattern is None:
            padded = matrix.duplicate(copy=False)
            padded.axpy(1.0, self._inertia_damping, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            self._inertia_damping_on_newton_pattern = padded
        return self._inertia_damping_on_newton_pattern

    def _add_thrust_jacobian(self, matrix, u, v, a):
        jacobians = thrust_jacobians(self.spine, *(self.spine_values(x)[:, :2] for x in (u, v, a)))
        scheme = self.scheme
        # S gets -((1 - α_f) ∂f/∂u + (1 - α_f) γ/(βh) ∂f/∂u̇ + (1 - α_m)/(βh²) ∂f/∂ü): f_thrust is on the right.
        block = -(scheme.stiffness_factor * jacobians[0] + scheme.velocity_factor * jacobians[1]
                  + scheme.acceleration_factor * jacobians[2])
        n_spine = self.spine_nodes.size
        spine_dofs = (3 * self._spine_global_blocks[:, None] + np.arange(2)).astype(np.int32)
        for index in self._spine_index:
            neighbours = np.arange(max(index - 1, 0), min(index + 2, n_spine))
            rows = spine_dofs[index]
            columns = spine_dofs[neighbours].ravel()
            values = block[np.ix_(2 * index + np.arange(2), (2 * neighbours[:, None] + np.arange(2)).ravel())]
            matrix.setValues(rows, columns, values, addv=PETSc.InsertMode.ADD_VALUES)

    def _add_drag_jacobian(self, matrix, v):
        """∂(-g v_x²)/∂u_{n+1} = -2 g v_x (1 - α_f)(γ/(βh)) e_head_xᵀ: a column at the head's x dof."""
        head_global = int(3 * self._spine_global_blocks[-1])
        factor = -2.0 * self.head_velocity_x(v) * self.scheme.velocity_factor
        rows = self.global_dofs(self._drag_rows)
        values = (factor * self._drag_direction[self._drag_rows]).reshape(-1, 1)
        matrix.setValues(rows, np.array([head_global], dtype=np.int32), values, addv=PETSc.InsertMode.ADD_VALUES)

    def factorize(self, time, u, v, a) -> None:
        if self._solver is None:
            self._solver = direct_solver(self.comm)
        self._solver.setOperators(self.assemble_newton_matrix(time, u, v, a))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.solve_with(self._solver, rhs)

    def solve_with(self, solver: PETSc.KSP, rhs: np.ndarray) -> np.ndarray:
        """solver⁻¹ rhs; SolverError if PETSc fails or the solve diverges (a failed factorisation)."""
        self._work_in.array[:] = rhs
        try:
            solver.solve(self._work_in, self._work_out)
        except PETSc.Error as error:
            raise SolverError(f"linear solve failed (PETSc {error}; {describe_linear_solve(solver)})") from None
        if solver.getConvergedReason() < 0:
            raise SolverError(f"linear solve failed ({describe_linear_solve(solver)})")
        return self._work_out.array.copy()

    def linear_solve_status(self) -> str:
        """KSP reason and MUMPS status of the Newton matrix's last solve ("" before the first)."""
        return describe_linear_solve(self._solver) if self._solver is not None else ""

    def static_response(self, left: float, right: float, tolerance: float = 1e-10,
                        max_iterations: int = 30) -> np.ndarray:
        """u solving f_int(u) = f_act(u) for fixed activations, head clamped (full Newton)."""
        self.activations[LEFT].value, self.activations[RIGHT].value = left, right
        solver = direct_solver(self.comm)
        u = np.zeros(self.n_owned_dofs)
        for _ in range(max_iterations):
            internal = self.internal_force(u)
            actuation = self._actuation_force_at_current_state()
            residual = internal - actuation
            residual[self.clamped_dofs] = 0.0
            if self.norm(residual) <= tolerance * max(self.norm(internal), self.norm(actuation), 1e-30):
                return u
            tangent = fx.assemble_matrix_into(self.tangent_matrix, self.forms["tangent"])
            tangent.zeroRowsColumns(self.global_dofs(self.clamped_dofs), diag=1.0)
            solver.setOperators(tangent)
            u = u - self.solve_with(solver, residual)
        raise SolverError(f"static solve did not converge in {max_iterations} iterations "
                          f"(activations left {left}, right {right})")

    def norm(self, vector: np.ndarray) -> float:
        return float(np.sqrt(self.comm.allreduce(float(vector @ vector), op=MPI.SUM)))

    # ------------------------------------------------------------------ observables
    def owned_values(self, nodal: np.ndarray) -> np.ndarray:
        """Owned dof array of an (n_input_nodes, 3) field."""
        return nodal[self.layout.owned_nodes].ravel().copy()

    def owned_from_nodal(self, nodal: np.ndarray) -> np.ndarray:
        """Owned dof array of an (n_input_nodes, 3) state field, zero on fixed dofs."""
        owned = self.owned_values(nodal)
        owned[self.fixed_dofs] = 0.0
        return owned

    def observables(self, u: np.ndarray) -> dict[str, float]:
        """Head x, tail y and centre-of-mass x displacements [m]."""
        spine = self.spine_values(u)
        com_x = self.comm.allreduce(float(self._com_weights @ u), op=MPI.SUM) / self.total_mass
        return {"head_x": float(spine[-1, 0]), "tail_y": float(spine[0, 1]), "com_x": com_x}

    def kinetic_energy(self, v: np.ndarray) -> float:
        """½ u̇ᵀ M u̇ [J]."""
        return 0.5 * self.comm.allreduce(float(v @ self.matvec(self.mass_matrix, v)), op=MPI.SUM)

    def elastic_energy(self, u: np.ndarray) -> float:
        """Π(u) [J]."""
        fx.set_owned_values(self.displacement, u)
        return fx.assemble_scalar(self.forms["elastic_energy"], self.comm)

    def nodal_displacement(self, u: np.ndarray) -> np.ndarray:
        """(n_nodes, 3) on every rank (for renders and checks; the vertices come first)."""
        nodal = np.zeros((self.fish.nodes.points.shape[0], 3))
        nodal[self.layout.owned_nodes] = u.reshape(-1, 3)
        return self.comm.allreduce(nodal, op=MPI.SUM)


class ShapeDirection:
    """A design direction δξ as the coefficients the forms are differentiated along.

    δu_ξ = U δξ at the displacement nodes (the skin form) and ∇δu_ξ = ∇U δξ, exact, at the points
    of each quadrature rule (the volume forms), on the model's nominal mesh.
    """

    def __init__(self, fom: FullOrderModel, name: str):
        self.fom = fom
        self.nodal = fx.new_function(fom.space, f"{name}_nodal")
        self.gradients = {family: fx.new_function(gradient.function_space, f"{name}_{family}")
                          for family, gradient in fom.shape_gradients.items()}

    def pairs(self):
        """(shape coefficient, its variation) for every representation of u_ξ."""
        fom = self.fom
        return [(fom.shape_displacement, self.nodal)] + [(fom.shape_gradients[family], self.gradients[family])
                                                        for family in self.gradients]

    def set_parameter(self, k: int) -> None:
        """δξ = e_k: δu_ξ = U_k."""
        fom = self.fom
        fx.set_owned_values(self.nodal, fom.owned_values(fom.fish.shape_matrix[:, k].reshape(-1, 3)))
        for family, function in self.gradients.items():
            points = fom.quadrature_points[family].reshape(-1, 3)
            fx.set_quadrature_values(function, fom.fish.shape_direction_gradient(k, points))
