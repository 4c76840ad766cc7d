"""Muscle actuation (SPEC §5): f_act = -∂Π_act/∂u with the muscle energy of ``forms/muscle.py``,

    Π_act = Σ_j ½ k a_j(t) ∫_muscle_j |F_2 m|² dV_ξ,   (a_left, a_right) = A r(t) sin(2π f t) (1, -1),

r = 1 (SPEC) or, with ``[actuation] start_ramp`` τ > 0, the smooth start r(t) = sin²(π t / 2τ) for
t < τ (then a ~ t³ at t = 0 instead of a jump of ȧ that rings the stiff modes).

The activation law and its derivative in A are written here once, for the full and the reduced
model. Π_act is linear in each a_j: the reduced force is -Σ_j a_j (b_j + B_j η) with b_j, B_j the
projected force and tangent of muscle j alone at unit activation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.forms.muscle import muscle_energy, muscle_energy_density
from aquarom_fenics.physics.taylor import Taylor, stack_taylor, taylor_of

LEFT, RIGHT = 1, 2
"""Region numbers of the muscles' cells in the forms' measure."""

ANTAGONIST_PATTERN = np.array([1.0, -1.0])
"""(a_left, a_right) per unit of A sin(2π f t): the left muscle contracts while the right extends."""


def start_ramp(time: float, ramp_time: float) -> float:
    """r(t) = sin²(π t / 2τ) for t < τ, else 1 (τ = ``ramp_time`` [s]; r = 1 for τ = 0)."""
    if time >= ramp_time:
        return 1.0
    return float(np.sin(0.5 * np.pi * time / ramp_time) ** 2)


def unit_activations(frequency: float, time: float, ramp_time: float = 0.0) -> np.ndarray:
    """∂(a_left, a_right)/∂A = r(t) sin(2π f t) (1, -1)."""
    return start_ramp(time, ramp_time) * np.sin(2.0 * np.pi * frequency * time) * ANTAGONIST_PATTERN


def activations(amplitude: float, frequency: float, time: float, ramp_time: float = 0.0) -> np.ndarray:
    """(a_left, a_right) = A r(t) sin(2π f t) (1, -1)."""
    return amplitude * unit_activations(frequency, time, ramp_time)


class MuscleTerm:
    """The two muscles of one FOM: their activations (constants of the form), force and tangent form.

    Off (``on`` False, zero force) when the scene's muscle stiffness k or amplitude A is zero.
    """

    def __init__(self, fom):
        scene, tags = fom.scene, fom.fish.tags
        self.fom = fom
        self.amplitude, self.frequency = scene.actuation.amplitude, scene.actuation.frequency
        self.ramp_time = scene.actuation.start_ramp
        self.on = scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0
        self._activations = [fx.constant(fom.mesh, 0.0), fx.constant(fom.mesh, 0.0)]
        muscles = fx.cell_measure(fom.mesh, {LEFT: tags.left_muscle_cells, RIGHT: tags.right_muscle_cells})
        self.measures = [muscles(LEFT), muscles(RIGHT)]
        self.negative_force_form = self.tangent_form = None
        if self.on:
            u = fom.displacement
            energy = fom.stiffness_rule(muscle_energy(
                u, fom.shape_gradients["stiffness"], fx.constant(fom.mesh, scene.actuation.stiffness),
                self._activations, self.measures, nominal_volume=scene.actuation.muscle_volume == "nominal"))
            self.negative_force_form = ufl.derivative(energy, u, fom.test_function)
            self.tangent_form = ufl.derivative(self.negative_force_form, u, fom.trial_function)
            self._negative_force = fx.compile_form(self.negative_force_form)
            self._vector = fx.create_vector(self._negative_force)

    def destroy(self) -> None:
        """Release the force's PETSc vector (none when the muscles are off)."""
        if self.on:
            self._vector.destroy()

    def set_activations(self, values) -> None:
        """(a_left, a_right) of the forms."""
        for constant, value in zip(self._activations, values):
            constant.value = value

    def set_time(self, time: float) -> None:
        """The activations of the scene's law at time t."""
        self.set_activations(activations(self.amplitude, self.frequency, time, self.ramp_time))

    def force(self) -> np.ndarray:
        """f_act = -∂Π_act/∂u at the FOM's displacement and the current activations [N]."""
        if not self.on:
            return np.zeros(self.fom.n_owned_dofs)
        return -fx.assemble_vector_into(self._vector, self._negative_force)

    def reduce(self, projector) -> "MuscleTensors":
        """b_j = Vᵀ ∂Π_act,j/∂u and B_j = Vᵀ ∂²Π_act,j/∂u² V at rest, a_j = 1 (zero when off), with
        their Taylor terms in ξ, sampled (:func:`sampled_muscle_tensors`)."""
        m = projector.vectors.shape[1]
        if not self.on:
            return MuscleTensors(Taylor(np.zeros((2, m))), Taylor(np.zeros((2, m, m))))
        return sampled_muscle_tensors(self.fom, projector)


def sampled_muscle_tensors(fom, projector) -> "MuscleTensors":
    """b_j and B_j of each muscle j with their Taylor terms in ξ, from its energy at unit activation
    sampled on the basis. Π_j(u) = ∫_muscle_j ψ(u) dV_0 with the density ψ of ``forms/muscle.py``,
    quadratic in u (the stretch F_2 m is affine in u), so that on u = V η

        Π_j(V η) = Π_j(0) + b_jᵀ η + ½ ηᵀ B_j η,
        b_j,i = (Π_j(V_i) - Π_j(-V_i)) / 2,   B_j,ii = Π_j(V_i) + Π_j(-V_i) - 2 Π_j(0),
        B_j,ik = Π_j(V_i + V_k) - Π_j(0) - b_j,i - b_j,k - ½ (B_j,ii + B_j,kk),

    each Π_j the FOM's quadrature sum Σ_c Σ_q ω_q |det J_c| ψ over muscle j's cells, and its ξ-derivatives
    (UFL derivatives of ψ along the shape directions) in the same evaluations.
    """
    scene, vectors = fom.scene, projector.vectors
    m, p, order = vectors.shape[1], projector.n_parameters, projector.order
    sample = fx.new_function(fom.space, "muscle_sample")
    density = muscle_energy_density(sample, fom.shape_gradients["stiffness"],
                                    fx.constant(fom.mesh, scene.actuation.stiffness),
                                    nominal_volume=scene.actuation.muscle_volume == "nominal")
    directions = [fom.shape_direction(f"muscle_direction_{k}") for k in range(p if order >= 1 else 0)]
    for k, direction in enumerate(directions):
        direction.set_parameter(k)
    first = [fom.shape_derivative(density, direction) for direction in directions]
    pairs = [(k, l) for k in range(p) for l in range(k, p)] if order >= 2 else []
    second = [fom.shape_derivative(first[k], directions[l]) for k, l in pairs]
    degree = fom.quadrature_degrees["stiffness"]
    expression = fx.compile_quadrature_expression(
        abs(ufl.JacobianDeterminant(fom.mesh)) * ufl.as_vector([density] + first + second), degree)
    reference_weights = fx.quadrature_rule(degree)[1]
    n_terms = 1 + len(first) + len(second)
    # the sampled terms: [value, ∂/∂ξ_k (k < p), ∂²/∂ξ_k∂ξ_l (the pairs k ≤ l)], by derivative indices
    column = {indices: n for n, indices in enumerate([()] + [(k,) for k in range(len(first))] + pairs)}
    tags = fom.fish.tags

    def energies(cells, displacement):        # (Π, ∂Π/∂ξ_k, ∂²Π/∂ξ_k∂ξ_l) at u
        fx.set_owned_values(sample, displacement)
        values = fx.evaluate_expression(expression, cells).reshape(cells.size, reference_weights.size, n_terms)
        return np.einsum("cqt,q->t", values, reference_weights)

    shifts = [vectors[:, i] for i in range(m)] + [-vectors[:, i] for i in range(m)]
    pair_list = [(i, k) for i in range(m) for k in range(i + 1, m)]
    shifts += [vectors[:, i] + vectors[:, k] for i, k in pair_list]
    constants, linears = [], []
    for muscle_cells in (tags.left_muscle_cells, tags.right_muscle_cells):
        cells = fx.owned_cells_among(fom.mesh, muscle_cells)
        sampled = np.stack([energies(cells, np.zeros(fom.n_owned_dofs))] + [energies(cells, u) for u in shifts])
        sampled = fom.comm.allreduce(sampled, op=MPI.SUM)
        rest, plus, minus, both = sampled[0], sampled[1: 1 + m], sampled[1 + m: 1 + 2 * m], sampled[1 + 2 * m:]
        gradient = (plus - minus) / 2.0                                                   # (m, n_terms)
        hessian = np.empty((m, m, n_terms))
        for i in range(m):
            hessian[i, i] = plus[i] + minus[i] - 2.0 * rest
        for (i, k), value in zip(pair_list, both):
            hessian[i, k] = hessian[k, i] = value - rest - gradient[i] - gradient[k] - 0.5 * (hessian[i, i] + hessian[k, k])
        b, b_matrix = taylor_of(lambda indices: (gradient[..., column[indices]], hessian[..., column[indices]]),
                                p, order)
        constants.append(b)
        linears.append(b_matrix)
    return MuscleTensors(stack_taylor(constants), stack_taylor(linears))


@dataclass
class MuscleTensors:
    """The reduced muscles: f_act,r = -Σ_j a_j (b_j + B_j η)."""

    constant: Taylor                     # b_j (2, m): ∂Π_act,j/∂u at rest for a_j = 1 (left, right)
    linear: Taylor                       # B_j (2, m, m): ∂²Π_act,j/∂u² for a_j = 1

    def at(self, delta: np.ndarray, amplitude: float, frequency: float, ramp_time: float = 0.0) -> "ReducedMuscle":
        return ReducedMuscle(self, delta, amplitude, frequency, ramp_time)


class ReducedMuscle:
    """The reduced muscles at one design ξ and amplitude A (a :class:`ReducedTerm`).

    B_j and ∂B_j/∂ξ_k are kept flat, (2, m²) and (p, 2, m²), to contract Σ_j a_j B_j as one product.
    """

    def __init__(self, tensors: MuscleTensors, delta: np.ndarray, amplitude: float, frequency: float,
                 ramp_time: float = 0.0):
        self.tensors, self.delta = tensors, delta
        self.amplitude, self.frequency, self.ramp_time = amplitude, frequency, ramp_time
        self.constant = tensors.constant.at(delta)
        self.linear = tensors.linear.at(delta)
        m = self.constant.shape[-1]
        self._linear_rows = self.linear.reshape(2, m * m)
        self.constant_gradient = tensors.constant.gradient(delta)                      # (p, 2, m)
        self._linear_gradient_rows = tensors.linear.gradient(delta).reshape(-1, 2, m * m)
        self._time, self._activations = None, None

    def activations(self, time: float) -> np.ndarray:
        """(a_left, a_right) at time t (kept for the same t)."""
        if time != self._time:
            self._time, self._activations = time, activations(self.amplitude, self.frequency, time, self.ramp_time)
        return self._activations

    def _stiffness(self, a: np.ndarray) -> np.ndarray:
        """Σ_j a_j B_j, (m, m)."""
        m = self.constant.shape[-1]
        return (a @ self._linear_rows).reshape(m, m)

    def _per_activation(self, a: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """Σ_j a_j (b_j + B_j η)."""
        return a @ self.constant + self._stiffness(a) @ eta

    def force(self, time: float, eta: np.ndarray) -> np.ndarray:
        return -self._per_activation(self.activations(time), eta)

    def amplitude_derivative(self, time: float, eta: np.ndarray) -> np.ndarray:
        """∂r/∂A = Σ_j (∂a_j/∂A) (b_j + B_j η)."""
        return self._per_activation(unit_activations(self.frequency, time, self.ramp_time), eta)

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """K_t part Σ_j a_j B_j."""
        return self._stiffness(self.activations(time)), None, None

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """Σ_j a_j (∂b_j/∂ξ_k + ∂B_j/∂ξ_k η), shape (p, m)."""
        a = self.activations(time)
        m = eta.size
        return a @ self.constant_gradient + ((a @ self._linear_gradient_rows).reshape(-1, m) @ eta).reshape(-1, m)
