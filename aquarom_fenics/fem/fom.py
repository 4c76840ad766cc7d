"""Full-order model of the swimmer (SPEC §5): the validation reference.

    M ü + C u̇ + f_int(u) = f_thrust(u, u̇, ü) + f_drag(u̇) + f_act(u, t)

on a distributed linear tetrahedral mesh with a degree-1 or degree-2 Lagrange displacement and
PETSc. Each force is a term of ``physics/`` (elastic, muscle, inertia with Rayleigh damping, drag,
thrust): the model sums their residuals, and its Newton system (``newton_system.py``) their
Newton-matrix parts. A design ξ is either pulled back (forms on the nominal mesh with
F_1 = I + ∇u_ξ, ∇u_ξ = Σ ξ_k ∇U_k of the exact shape fields at the quadrature points, SPEC §4) or
meshed directly (``moved_mesh``, u_ξ = 0).
"""
from __future__ import annotations

import time as clock
from collections.abc import Iterator

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from ufl.algorithms import extract_coefficients

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.errors import InputError, SolverError
from aquarom_fenics.fem.linear_solver import mumps_solver, solve_into
from aquarom_fenics.fem.newton_system import NewtonMatrix, NewtonSolver, SolveProfile
from aquarom_fenics.fem.shape_direction import ShapeDirection
from aquarom_fenics.fem.time_scheme import TimeScheme
from aquarom_fenics.geometry.fish import Fish, quadrature_degrees
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.drag import DragTerm
from aquarom_fenics.physics.elastic import ElasticTerm
from aquarom_fenics.physics.inertia import InertiaTerm
from aquarom_fenics.physics.muscle import MuscleTerm
from aquarom_fenics.physics.stations import averages_of
from aquarom_fenics.physics.thrust_full_order import NodalThrustTerm, StationThrustTerm


class FullOrderModel:
    """One design of a scene, ready to be integrated in time (implements ``NewtonSystem``)."""

    def __init__(self, scene: Scene, fish: Fish, xi=None, moved_mesh: bool = False,
                 comm: MPI.Comm = MPI.COMM_WORLD):
        self.scene, self.fish, self.comm = scene, fish, comm
        self.xi = fish.parameter_vector(xi)
        self.moved_mesh = moved_mesh
        self.rest_points = rest_points = fish.design(self.xi)
        shape_displacement = np.zeros_like(rest_points) if moved_mesh else rest_points - fish.nodes.points
        mesh_points = rest_points[:fish.nodes.n_vertices] if moved_mesh else fish.mesh.points

        self.mesh = fx.create_tet_mesh(comm, mesh_points, fish.mesh.cells)
        self.space = fx.vector_space(self.mesh, fish.degree)
        self.layout = fx.dof_layout(self.space, fish.nodes.nodes_of_pairs)
        self.n_owned_dofs = 3 * self.layout.n_owned_blocks
        self.n_global_dofs = 3 * self.space.dofmap.index_map.size_global
        self.n_cells = fish.mesh.cells.shape[0]

        # One pair of arguments for every term: the Newton matrix's form sums the terms' tangent forms.
        self.test_function, self.trial_function = ufl.TestFunction(self.space), ufl.TrialFunction(self.space)
        self.displacement = fx.new_function(self.space, "displacement")
        self.shape_displacement = fx.new_function(self.space, "shape_displacement")
        fx.set_nodal_values(self.shape_displacement, self.layout, shape_displacement)
        self._build_shape_gradients(np.zeros_like(self.xi) if moved_mesh else self.xi)
        self._build_spine()
        self._build_stations()
        self._build_boundary_conditions()
        self._build_terms(rest_points)
        self._work_in = PETSc.Vec().createMPI((self.n_owned_dofs, self.n_global_dofs), comm=comm)
        self._work_out = self._work_in.duplicate()
        self._build_newton_system()
        self.kept: dict = {}
        """What the reductions compile on this model (:meth:`keep`), kept for its next designs (:meth:`move_to`)."""

    def _build_newton_system(self) -> None:
        self.newton_matrix = NewtonMatrix(self)
        self.newton_solver = NewtonSolver(self, self.newton_matrix)
        self.set_time_step(TimeScheme.from_solver(self.scene.solver))

    def move_to(self, xi) -> None:
        """This pulled-back model at the design ξ of the same mesh: the shape coefficients take ξ's values,
        what is assembled at the design is assembled again, the compiled forms are kept (as a new
        model at ξ, without its set-up). InputError where the design check refuses ξ."""
        if self.moved_mesh:
            raise ValueError("only a model with the design pulled back to the nominal mesh moves (moved_mesh=False)")
        xi = self.fish.parameter_vector(xi)
        self.rest_points, self.xi = self.fish.design(xi), xi
        fx.set_nodal_values(self.shape_displacement, self.layout, self.rest_points - self.fish.nodes.points)
        for family, gradient in self.shape_gradients.items():
            fx.set_quadrature_values(gradient, self._moved_gradient(family, xi))
        self.elastic.rest_stiffness(self.rest_stiffness)
        self.inertia.assemble(self.rest_stiffness)
        if self.drag is not None:
            self.drag.assemble()
        if self.thrust is not None:
            self.thrust = type(self.thrust)(self, self.rest_points)
        self.newton_solver.destroy()
        self.newton_matrix.destroy()
        self._build_newton_system()

    def keep(self, key, make):
        """``make()`` on this model once per ``key``, kept in :attr:`kept` for its next designs."""
        if key not in self.kept:
            self.kept[key] = make()
        return self.kept[key]

    # ------------------------------------------------------------------ set-up
    def cell_field(self, values_by_cell: np.ndarray, name: str):
        field = fx.new_function(fx.cellwise_constant_space(self.mesh), name)
        fx.set_cell_values(field, values_by_cell)
        return field

    def _build_shape_gradients(self, xi: np.ndarray) -> None:
        """∇u_ξ = Σ_k ξ_k ∇U_k, exact, at the points of each quadrature rule (SPEC §4)."""
        self.quadrature_degrees = quadrature_degrees(self.fish.degree)
        self.quadrature_points = {family: fx.quadrature_points(self.mesh, degree)
                                  for family, degree in self.quadrature_degrees.items()}
        self._direction_gradients: dict[tuple[str, int], np.ndarray] = {}
        self.shape_gradients = {}
        for family, degree in self.quadrature_degrees.items():
            gradient = fx.new_function(fx.quadrature_tensor_space(self.mesh, degree), f"shape_gradient_{family}")
            fx.set_quadrature_values(gradient, self.fish.shape_gradient(xi, self.quadrature_points[family].reshape(-1, 3)))
            self.shape_gradients[family] = gradient

    def _moved_gradient(self, family: str, xi: np.ndarray) -> np.ndarray:
        """∇u_ξ at the ``family``'s points, (n, 3, 3), from the ∇U_k a moved model keeps (its builds set them)."""
        return self.fish.shape_gradient(xi, self.quadrature_points[family].reshape(-1, 3),
                                        lambda k: self.shape_direction_gradient(family, k))

    def shape_direction_gradient(self, family: str, k: int) -> np.ndarray:
        """∇U_k at the points of the ``family``'s rule, (n, 3, 3), kept on the model (a build sets it often)."""
        key = (family, k)
        if key not in self._direction_gradients:
            points = self.quadrature_points[family].reshape(-1, 3)
            self._direction_gradients[key] = self.fish.shape_direction_gradient(k, points)
        return self._direction_gradients[key]

    def shape_direction(self, name: str) -> ShapeDirection:
        """A design direction δξ as coefficients of this model's forms (see ``shape_derivative``); only on the
        pulled-back model, where ∇U_k is the gradient with respect to nominal coordinates."""
        if self.moved_mesh:
            raise ValueError("shape derivatives need the design pulled back to the nominal mesh (moved_mesh=False)")
        return ShapeDirection(self, name)

    def shape_derivative(self, form, direction: ShapeDirection):
        """d/dε form(ξ + ε δξ) at ε = 0: the UFL derivative along δu_ξ = U δξ and ∇δu_ξ = ∇U δξ
        of every shape coefficient that appears in the form."""
        present = set(extract_coefficients(form))
        terms = [ufl.derivative(form, coefficient, variation) for coefficient, variation in direction.pairs()
                 if coefficient in present]
        return sum(terms[1:], terms[0])

    def _build_terms(self, rest_points: np.ndarray) -> None:
        """The force terms; the tangent form K_t sums the elastic and muscle tangents (the thrust's and
        the drag's enter the Newton matrix as entries)."""
        fluid = self.scene.fluid
        self.elastic = ElasticTerm(self)
        self.muscle = MuscleTerm(self)
        self.rest_stiffness = self.elastic.rest_stiffness()
        self.inertia = InertiaTerm(self, self.rest_stiffness)
        self.drag = DragTerm(self) if fluid.drag else None
        thrust_term = NodalThrustTerm if self.station_averages is None else StationThrustTerm
        self.thrust = thrust_term(self, rest_points) if fluid.thrust else None
        tangent = self.elastic.tangent_form
        if self.muscle.on:
            tangent = tangent + self.muscle.tangent_form
        self.tangent_form = fx.compile_form(tangent)

    @property
    def mass_matrix(self) -> PETSc.Mat:
        return self.inertia.mass_matrix

    @property
    def damping_matrix(self) -> PETSc.Mat:
        return self.inertia.damping_matrix

    def stiffness_rule(self, form):
        """The form with the quadrature rule of the stiffness terms (elastic, muscle)."""
        return fx.with_quadrature_degree(form, self.quadrature_degrees["stiffness"])

    def mass_rule(self, form):
        """The form with the quadrature rule of the mass terms (mass, mass moment, skin)."""
        return fx.with_quadrature_degree(form, self.quadrature_degrees["mass"])

    def owned_positions(self, nodes: np.ndarray):
        """(owned local blocks, index into ``nodes``) of the given input nodes owned by this rank."""
        lookup = np.full(self.fish.nodes.points.shape[0], -1)
        lookup[nodes] = np.arange(nodes.size)
        position = lookup[self.layout.owned_nodes]
        blocks = np.flatnonzero(position >= 0)
        return blocks, position[blocks]

    def _build_spine(self):
        """Owned blocks of the spine nodes (tail -> head) and their global blocks on every rank: the nodal
        model's (``stations = "nodes"``); empty for a mesh without nodes on its axis."""
        tags = self.fish.tags
        self.spine_nodes = tags.spine_nodes
        self.spine_blocks, self.spine_index = self.owned_positions(self.spine_nodes)
        global_blocks = np.zeros(self.spine_nodes.size, dtype=np.int64)
        global_blocks[self.spine_index] = self.layout.global_block[self.spine_blocks]
        self.spine_global_blocks = self.comm.allreduce(global_blocks, op=MPI.SUM)
        self.head_x_global_dof = int(3 * self.spine_global_blocks[-1]) if tags.has_spine else None
        head = self.owned_positions(np.array([tags.head_spine_node]))[0] if tags.has_spine else np.zeros(0, int)
        self._head_x_owned = 3 * head  # empty on ranks that do not own the head node

    def _build_stations(self):
        """The station averages B and the head average (SPEC §5), or None for ``stations = "nodes"``;
        the head's reference x-velocity weights on the owned x dofs (the head node for "nodes"), and the
        observed points' weights (``_build_observation``)."""
        n_stations = self.scene.fluid.stations
        if n_stations == "nodes":
            if not self.fish.tags.has_spine:
                raise InputError(f"mesh {self.fish.mesh.source}: no nodes on the body axis y = 0, z = 0, which "
                                 "[fluid] stations = \"nodes\" acts on; use stations = N_s")
            self.station_averages = None
            self._head_velocity_weights = np.ones(self._head_x_owned.size)
            self._head_velocity_dofs = self._head_x_owned
        else:
            self.station_averages = averages_of(self.fish, n_stations, self.scene.fluid.tail_station)
            self._head_velocity_weights = self.station_averages.head_weights[self.layout.owned_nodes]
            self._head_velocity_dofs = 3 * np.arange(self.layout.n_owned_blocks)
        self._build_observation()

    def _build_observation(self):
        """Weights w on the owned dofs of the observed displacements (SPEC §3: outputs, never where a force
        acts), head x = w_head·u and tail y = w_tail·u (tail x its u_x): the head's volume average of u_x (the drag's
        reference, the head being stiff) and the tail station's average of u_y (the end face x = -L with
        ``tail_station = "face"``); the head and tail spine nodes with ``stations = "nodes"``."""
        self._head_x_weights = np.zeros(self.n_owned_dofs)
        self._head_x_weights[self._head_velocity_dofs] = self._head_velocity_weights
        self._tail_y_weights = np.zeros(self.n_owned_dofs)
        if self.station_averages is None:
            tail = self.owned_positions(np.array([self.fish.tags.tail_node]))[0]
            self._tail_y_weights[3 * tail + 1] = 1.0
        else:
            self._tail_y_weights[1::3] = self.station_averages.weights[0][:, self.layout.owned_nodes].toarray().ravel()
        self._tail_x_weights = np.roll(self._tail_y_weights, -1)       # the same point's u_x (dofs x, y, z per node)

    def tail_point(self) -> np.ndarray:
        """(3,) rest position [m] of the tail's observation point in this design: the tail station's
        average of the rest positions (the tail node's with ``stations = "nodes"``)."""
        if self.station_averages is None:
            return self.rest_points[self.fish.tags.tail_node].copy()
        return np.asarray(self.station_averages.weights[0] @ self.rest_points).ravel()

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

    # ------------------------------------------------------------------ evaluations
    def set_displacement(self, u: np.ndarray) -> None:
        """u of the forms (owned dofs)."""
        fx.set_owned_values(self.displacement, u)

    def set_state(self, time: float, u: np.ndarray) -> None:
        """u and the activations at time t of the forms."""
        self.set_displacement(u)
        self.muscle.set_time(time)

    def matvec(self, matrix: PETSc.Mat, x: np.ndarray) -> np.ndarray:
        self._work_in.array[:] = x
        matrix.mult(self._work_in, self._work_out)
        return self._work_out.array.copy()

    def spine_values(self, owned: np.ndarray) -> np.ndarray:
        """(n_spine, 3) nodal values of an owned dof array at the spine nodes, on every rank."""
        local = np.zeros((self.spine_nodes.size, 3))
        local[self.spine_index] = owned.reshape(-1, 3)[self.spine_blocks]
        return self.comm.allreduce(local, op=MPI.SUM)

    def head_velocity_x(self, v: np.ndarray) -> float:
        """The drag's reference velocity v_x [m/s]: the head's volume average of u̇_x (the head node's
        u̇_x with ``stations = "nodes"``)."""
        local = float(self._head_velocity_weights @ v[self._head_velocity_dofs])
        return self.comm.allreduce(local, op=MPI.SUM)

    def head_velocity_row(self, vectors: np.ndarray) -> np.ndarray:
        """(m,) the row giving v_x from reduced velocities η̇ of the owned dof columns ``vectors``."""
        local = self._head_velocity_weights @ vectors[self._head_velocity_dofs]
        return self.comm.allreduce(local, op=MPI.SUM)

    def internal_force(self, u: np.ndarray) -> np.ndarray:
        """f_int(u) = ∂Π/∂u, owned entries [N]."""
        self.set_displacement(u)
        return self.elastic.force()

    def actuation_force(self, time: float, u: np.ndarray) -> np.ndarray:
        """f_act(u, t) = -∂Π_act/∂u [N]."""
        self.set_state(time, u)
        return self.muscle.force()

    def thrust_force(self, u, v, a) -> np.ndarray:
        """Lighthill thrust scattered to the owned spine dofs (x, y) [N]."""
        return self.thrust.force(u, v, a) if self.thrust is not None else np.zeros(self.n_owned_dofs)

    def drag_force(self, v) -> np.ndarray:
        """f_drag = g(ξ) v_x² with v_x the head's x-velocity [N]."""
        return self.drag.force(v) if self.drag is not None else np.zeros(self.n_owned_dofs)

    def residual(self, time, u, v, a):
        """r = M ü + C u̇ + f_int - f_act - f_thrust - f_drag (zero on fixed dofs), and the force scale."""
        started = clock.perf_counter()
        self.set_state(time, u)
        inertia = self.matvec(self.mass_matrix, a)
        internal = self.elastic.force()
        external = self.muscle.force() + self.thrust_force(u, v, a) + self.drag_force(v)
        residual = inertia + self.matvec(self.damping_matrix, v) + internal - external
        residual[self.fixed_dofs] = 0.0
        scale = max(self.norm(internal), self.norm(external), self.norm(inertia))
        self.profile.residuals += clock.perf_counter() - started
        self.profile.counts["residuals"] += 1
        return residual, scale

    # ------------------------------------------------------------------ Newton system (newton_system.py)
    @property
    def scheme(self) -> TimeScheme:
        """The time scheme whose factors S holds."""
        return self.newton_matrix.scheme

    @property
    def profile(self) -> SolveProfile:
        """Wall times of the residuals, assemblies, factorisations and solves so far."""
        return self.newton_solver.profile

    def set_time_step(self, scheme: TimeScheme) -> None:
        """The scheme's factors enter S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t."""
        self.newton_matrix.set_time_step(scheme)

    def tangents(self, time, u, v, a) -> Iterator[PETSc.Mat]:
        """K_t = ∂r/∂u, C_t = ∂r/∂u̇ and M_t = ∂r/∂ü at (t, u, u̇, ü), in the Newton matrix's storage
        (see ``NewtonMatrix.tangents``)."""
        return self.newton_matrix.tangents(time, u, v, a)

    def factorize(self, time, u, v, a) -> None:
        """Assemble S at the evaluation point and factorise it (see ``NewtonSolver``)."""
        self.newton_solver.factorize(time, u, v, a)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """S⁻¹ rhs with the current factors."""
        return self.newton_solver.solve(rhs)

    def linear_solve_status(self) -> str:
        """KSP reason and MUMPS status of the Newton matrix's last solve ("" before the first)."""
        return self.newton_solver.status()

    def solve_with(self, solver: PETSc.KSP, rhs: np.ndarray) -> np.ndarray:
        """solver⁻¹ rhs; SolverError if PETSc fails or the solve diverges (a failed factorisation)."""
        return solve_into(solver, rhs, self._work_in, self._work_out)

    def static_response(self, *activations: float, tolerance: float = 1e-10,
                        max_iterations: int = 30, start: np.ndarray | None = None) -> np.ndarray:
        """u solving f_int(u) = f_act(u) for fixed activations (a_1, …, a_N; the pair: left, right), head
        clamped (full Newton from ``start``, default rest)."""
        self.muscle.set_activations(activations)
        solver = mumps_solver(self.comm)
        u = np.zeros(self.n_owned_dofs) if start is None else np.array(start, dtype=float)
        try:
            for _ in range(max_iterations):
                internal = self.internal_force(u)
                actuation = self.muscle.force()
                residual = internal - actuation
                residual[self.clamped_dofs] = 0.0
                if self.norm(residual) <= tolerance * max(self.norm(internal), self.norm(actuation), 1e-30):
                    return u
                tangent = fx.assemble_matrix_into(self.newton_matrix.storage, self.tangent_form)
                tangent.zeroRowsColumns(self.global_dofs(self.clamped_dofs), diag=1.0)
                solver.setOperators(tangent)
                u = u - self.solve_with(solver, residual)
        finally:
            solver.destroy()
        raise SolverError(f"static solve did not converge in {max_iterations} iterations "
                          f"(activations {', '.join(f'{value:g}' for value in activations)})")

    def destroy(self) -> None:
        """Release the PETSc matrices, vectors and solvers of the model, its Newton system and its
        terms. petsc4py does not free them when the Python objects go, so whoever is done with a model
        calls this; the model is unusable afterwards."""
        self.newton_solver.destroy()
        self.newton_matrix.destroy()
        for term in (self.elastic, self.muscle, self.inertia, self.drag):
            if term is not None:
                term.destroy()
        for petsc_object in (self.rest_stiffness, self._work_in, self._work_out):
            petsc_object.destroy()

    def norm(self, vector: np.ndarray) -> float:
        return float(np.sqrt(self.dot(vector, vector)))

    def dot(self, left: np.ndarray, right: np.ndarray) -> float:
        return float(self.comm.allreduce(float(left @ right), op=MPI.SUM))

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
        """Head x, tail y, centre-of-mass x, tail x and centre-of-mass y displacements [m] (``_build_observation``)."""
        inertia = self.inertia
        local = np.array([self._head_x_weights @ u, self._tail_y_weights @ u, inertia.mass_moment_x @ u,
                          self._tail_x_weights @ u, inertia.mass_moment_y @ u])
        head_x, tail_y, moment, tail_x, moment_y = self.comm.allreduce(local, op=MPI.SUM)
        return {"head_x": float(head_x), "tail_y": float(tail_y), "com_x": float(moment) / inertia.total_mass,
                "tail_x": float(tail_x), "com_y": float(moment_y) / inertia.total_mass}

    def observation_rows(self, vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(head x row, tail y row, tail x row), each (m,): the observed displacements from reduced
        coordinates η of the owned dof columns ``vectors`` (u = V η), on every rank."""
        local = np.stack([self._head_x_weights @ vectors, self._tail_y_weights @ vectors, self._tail_x_weights @ vectors])
        head_x, tail_y, tail_x = self.comm.allreduce(local, op=MPI.SUM)
        return head_x, tail_y, tail_x

    def kinetic_energy(self, v: np.ndarray) -> float:
        """½ u̇ᵀ M u̇ [J]."""
        return 0.5 * self.comm.allreduce(float(v @ self.matvec(self.mass_matrix, v)), op=MPI.SUM)

    def elastic_energy(self, u: np.ndarray) -> float:
        """Π(u) [J]."""
        self.set_displacement(u)
        return self.elastic.energy()

    def rows_at(self, vectors: np.ndarray, node: int) -> np.ndarray:
        """(3, m): the rows of the owned dof columns ``vectors`` at one input node, on every rank."""
        blocks, _ = self.owned_positions(np.array([node]))
        rows = np.zeros((3, vectors.shape[1]))
        if blocks.size:
            rows = vectors[3 * blocks[0]: 3 * blocks[0] + 3]
        return self.comm.allreduce(rows, op=MPI.SUM)

    def nodal_displacement(self, u: np.ndarray) -> np.ndarray:
        """(n_nodes, 3) on every rank (for renders and checks; the vertices come first)."""
        nodal = np.zeros((self.fish.nodes.points.shape[0], 3))
        nodal[self.layout.owned_nodes] = u.reshape(-1, 3)
        return self.comm.allreduce(nodal, op=MPI.SUM)

