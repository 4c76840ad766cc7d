"""Muscle actuation (SPEC §5): f_act = -∂Π_act/∂u with the muscle energy of ``forms/muscle.py``,

    Π_act = Σ_j ½ k a_j(t) ∫_muscle_j |F_2 m_j|² dV_ξ,   a_j(t) = A s_j r(t) sin(2π f_j t + φ_j),

over the scene's muscles j (``[[muscles]]``: region, fibre m_j, scale s_j, phase φ_j, frequency f_j;
without them the antagonist pair (a_left, a_right) = A r(t) sin(2π f t) (1, -1)). r = 1 (SPEC) or,
with ``[actuation] start_ramp`` τ > 0, the smooth start r(t) = sin²(π t / 2τ) for t < τ (then
a ~ t³ at t = 0 instead of a jump of ȧ that rings the stiff modes, and a_j ~ t² instead of the jump
a_j(0) = A s_j sin φ_j of a phase-shifted muscle). The default "auto" is τ = 0 for muscles that all
start at zero (phases 0° or 180°: SPEC's law) and a quarter period otherwise (``start_ramp_time``).

The activation law and its derivative in A are written here once, for the full and the reduced
model. Π_act is linear in each a_j: the reduced force is -Σ_j a_j (b_j + B_j η) with b_j, B_j the
projected force and tangent of muscle j alone at unit activation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI
from ufl.algorithms import extract_coefficients

from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.cellwise import leibniz_terms
from aquarom_fenics.forms.muscle import muscle_energy, muscle_stretch
from aquarom_fenics.io.scene_muscles import start_ramp_time
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


@dataclass(frozen=True)
class ActivationLaw:
    """a_j(t) = A s_j r(t) sin(2π f_j t + φ_j) of each muscle j (φ_j in radians here)."""

    scales: tuple[float, ...]
    phases: tuple[float, ...]
    frequencies: tuple[float, ...]          # Hz
    ramp_time: float = 0.0                  # τ [s] of r(t)
    extra_patterns: tuple[tuple[float, ...], ...] = ()
    """More activation patterns the basis must follow: a gait whose phase lag or pair amplitudes are
    design variables moves a(t) out of the span of its own two patterns; its pairs' patterns (each pair's
    muscles at ±1, the others 0) span every such gait (io/scene_gait.py)."""

    @classmethod
    def antagonist(cls, frequency: float, ramp_time: float = 0.0) -> "ActivationLaw":
        """The pair (a_left, a_right) = A r(t) sin(2π f t) (1, -1)."""
        return cls(tuple(ANTAGONIST_PATTERN.tolist()), (0.0, 0.0), (frequency, frequency), ramp_time)

    @classmethod
    def of(cls, scene) -> "ActivationLaw":
        """The law of the scene's muscles (``Scene.actuated_muscles``; phases given in degrees, reduced
        to (-360°, 360°) first, exactly: a phase of 1e300° keeps its angle, no digit is lost to 2π), with
        the scene's smooth start τ (``start_ramp_time``: "auto" ramps a gait whose muscles would jump at t = 0)."""
        from aquarom_fenics.io.scene_gait import pair_patterns

        muscles, actuation = scene.actuated_muscles, scene.actuation
        return cls(tuple(muscle.scale for muscle in muscles),
                   tuple(math.radians(math.fmod(muscle.phase, 360.0)) for muscle in muscles),
                   tuple(actuation.frequency if muscle.frequency is None else muscle.frequency for muscle in muscles),
                   start_ramp_time(scene), pair_patterns(scene))

    @property
    def size(self) -> int:
        return len(self.scales)

    def unit(self, time: float) -> np.ndarray:
        """∂a_j/∂A = s_j r(t) sin(2π f_j t + φ_j), one muscle at a time (the pair's values bit for bit)."""
        ramp = start_ramp(time, self.ramp_time)
        return np.array([ramp * np.sin(2.0 * np.pi * frequency * time + phase) * scale
                         for scale, phase, frequency in zip(self.scales, self.phases, self.frequencies)])

    def patterns(self) -> list[np.ndarray]:
        """The independent activation patterns P_k, with a(t) = A r(t) Σ_k c_k(t) P_k: per frequency f,
        sin(2π f t + φ_j) = cos φ_j sin(2π f t) + sin φ_j cos(2π f t) gives (s_j cos φ_j) and (s_j sin φ_j)
        over its muscles, then the :attr:`extra_patterns`. Orthogonalised in turn (Euclidean); a pattern with
        nothing left is dropped. The first is kept as it is: the pair's is (1, -1)."""
        candidates = []
        for frequency in dict.fromkeys(self.frequencies):
            mask = np.array([f == frequency for f in self.frequencies], dtype=float)
            candidates += [mask * np.array(self.scales) * np.cos(self.phases),
                           mask * np.array(self.scales) * np.sin(self.phases)]
        candidates += [np.array(pattern, dtype=float) for pattern in self.extra_patterns]
        scale = max(np.linalg.norm(candidate) for candidate in candidates)
        kept: list[np.ndarray] = []
        for candidate in candidates:
            remaining = candidate.copy()
            for pattern in kept:
                remaining = remaining - (pattern @ remaining) / (pattern @ pattern) * pattern
            if np.linalg.norm(remaining) > 1e-9 * scale:
                kept.append(remaining if kept else candidate)
        return kept


def unit_activations(frequency: float, time: float, ramp_time: float = 0.0) -> np.ndarray:
    """∂(a_left, a_right)/∂A = r(t) sin(2π f t) (1, -1) of the antagonist pair."""
    return ActivationLaw.antagonist(frequency, ramp_time).unit(time)


def activations(amplitude: float, frequency: float, time: float, ramp_time: float = 0.0) -> np.ndarray:
    """(a_left, a_right) = A r(t) sin(2π f t) (1, -1) of the antagonist pair."""
    return amplitude * unit_activations(frequency, time, ramp_time)


def muscle_cells(scene, tags) -> tuple[np.ndarray, ...]:
    """The cells of each muscle the scene drives (``FishTags.muscle_cells``), checked to be one per muscle."""
    muscles = scene.actuated_muscles
    cells = tags.muscle_cells or (tags.left_muscle_cells, tags.right_muscle_cells)
    if len(cells) != len(muscles):
        raise ValueError(f"the fish has {len(cells)} muscles and the scene drives {len(muscles)}: "
                         "load the fish from this scene")
    return tuple(cells)


class MuscleTerm:
    """The muscles of one FOM: their activations (constants of the form), force and tangent form.

    Muscle j (from 0) is the region number j + 1 of the forms' measure (LEFT, RIGHT for the pair).
    Off (``on`` False, zero force) when the scene's muscle stiffness k or amplitude A is zero.
    """

    def __init__(self, fom):
        scene = fom.scene
        self.fom = fom
        self.amplitude, self.law = scene.actuation.amplitude, ActivationLaw.of(scene)
        self.on = scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0
        cells = muscle_cells(scene, fom.fish.tags)
        self._activations = [fx.constant(fom.mesh, 0.0) for _ in cells]
        muscles = fx.cell_measure(fom.mesh, {number: region for number, region in enumerate(cells, start=LEFT)})
        self.measures = [muscles(number) for number in range(LEFT, LEFT + len(cells))]
        self.fibres = [muscle.fibre for muscle in scene.actuated_muscles]
        self.negative_force_form = self.tangent_form = None
        if self.on:
            u = fom.displacement
            energy = fom.stiffness_rule(muscle_energy(
                u, fom.shape_gradients["stiffness"], fx.constant(fom.mesh, scene.actuation.stiffness),
                self._activations, self.measures, nominal_volume=scene.actuation.muscle_volume == "nominal",
                fibres=self.fibres))
            self.negative_force_form = ufl.derivative(energy, u, fom.test_function)
            self.tangent_form = ufl.derivative(self.negative_force_form, u, fom.trial_function)
            self._negative_force = fx.compile_form(self.negative_force_form)
            self._vector = fx.create_vector(self._negative_force)

    def destroy(self) -> None:
        """Release the force's PETSc vector (none when the muscles are off)."""
        if self.on:
            self._vector.destroy()

    def set_activations(self, values) -> None:
        """(a_1, …, a_N) of the forms (the pair: (a_left, a_right)); ValueError for another number."""
        if len(values) != len(self._activations):
            raise ValueError(f"{len(values)} activations for {len(self._activations)} muscles")
        for constant, value in zip(self._activations, values):
            constant.value = value

    def set_time(self, time: float) -> None:
        """The activations of the scene's law at time t."""
        self.set_activations(self.amplitude * self.law.unit(time))

    def force(self) -> np.ndarray:
        """f_act = -∂Π_act/∂u at the FOM's displacement and the current activations [N]."""
        if not self.on:
            return np.zeros(self.fom.n_owned_dofs)
        return -fx.assemble_vector_into(self._vector, self._negative_force)

    def reduce(self, projector) -> "MuscleTensors":
        """b_j = Vᵀ ∂Π_act,j/∂u and B_j = Vᵀ ∂²Π_act,j/∂u² V at rest, a_j = 1 (zero when off), with
        their Taylor terms in ξ, sampled (:func:`sampled_muscle_tensors`)."""
        m, n = projector.vectors.shape[1], len(self.measures)
        if not self.on:
            return MuscleTensors(Taylor(np.zeros((n, m))), Taylor(np.zeros((n, m, m))))
        return sampled_muscle_tensors(self.fom, projector)


def sampled_muscle_tensors(fom, projector) -> "MuscleTensors":
    """b_j and B_j of each muscle j with their Taylor terms in ξ, from the stretch of each basis vector.

    Π_j(u) = ∫_muscle_j ½ w |s(u)|² dV_0 with the density ψ = ½ k |s|² v of ``forms/muscle.py``: the stretch
    s = F_2 m is affine in u, s(V η) = s_0 + Σ_i η_i s_i with s_0 = s(0) and s_i = s(V_i) - s_0, and w = k v. So

        b_j,i = ∂Π_j/∂η_i |_0 = ∫ w s_0·s_i,   B_j,ik = ∂²Π_j/∂η_i∂η_k = ∫ w s_i·s_k,

    each ∫ the FOM's quadrature sum Σ_c Σ_q ω_q |det J_c| over muscle j's cells, and their ξ-derivatives by
    Leibniz' rule over the three factors, ∂_I (w a·b) = Σ_{A⊔B⊔C=I} ∂_A w ∂_B a·∂_C b, from w, s and their
    ξ-derivatives (UFL derivatives along the shape directions), one stacked expression per fibre direction
    evaluated at u = 0 and at each basis vector: 1 + m evaluations per muscle.
    """
    scene, vectors = fom.scene, projector.vectors
    m, p, order = vectors.shape[1], projector.n_parameters, projector.order
    sample, expressions = fom.keep(("muscle_stretch", p, order), lambda: _muscle_expressions(fom, p, order))
    indices = derivative_indices(p, order)
    column = {index: n for n, index in enumerate(indices)}
    reference_weights = fx.quadrature_rule(fom.quadrature_degrees["stiffness"])[1]
    fibres = [tuple(muscle.fibre) for muscle in scene.actuated_muscles]

    def evaluated(expression, cells, displacement):        # (n_samples, n_terms, 4): (w, s) and ξ-derivatives
        fx.set_owned_values(sample, displacement)
        return fx.evaluate_expression(expression, cells).reshape(-1, len(indices), 4)

    constants, linears = [], []
    for region, fibre in zip(muscle_cells(scene, fom.fish.tags), fibres):
        cells, expression = fx.owned_cells_among(fom.mesh, region), expressions[fibre]
        rest = evaluated(expression, cells, np.zeros(fom.n_owned_dofs))
        weight = (rest[..., 0].reshape(cells.size, reference_weights.size, -1)
                  * reference_weights[:, None]).reshape(-1, len(indices))            # ω_q |det J| ∂_A w
        stretch = np.stack([rest[..., 1:]] + [evaluated(expression, cells, vectors[:, i])[..., 1:] - rest[..., 1:]
                                              for i in range(m)])                   # (1 + m, n_samples, n_terms, 3)
        products = np.stack([stretch_products(weight, stretch, index, column) for index in indices])
        products = fom.comm.allreduce(products, op=MPI.SUM)
        b, b_matrix = taylor_of(lambda index: (products[column[index], 0, 1:], products[column[index], 1:, 1:]),
                                p, order)
        constants.append(b)
        linears.append(b_matrix)
    return MuscleTensors(stack_taylor(constants), stack_taylor(linears))


def derivative_indices(p: int, order: int) -> list[tuple[int, ...]]:
    """The ξ-derivatives the Taylor terms need: (), (k,) at order ≥ 1, (k, l) with k ≤ l at order 2."""
    first = [(k,) for k in range(p)] if order >= 1 else []
    return [()] + first + ([(k, l) for k in range(p) for l in range(k, p)] if order >= 2 else [])


def stretch_products(weight: np.ndarray, stretch: np.ndarray, index: tuple, column: dict) -> np.ndarray:
    """∂_I Σ_s w_s a_s·b_s for every pair (a, b) of the stretches (s_0, s_1, …, s_m), (1 + m, 1 + m): Leibniz'
    rule, each position of I = ``index`` given to w, a or b (:func:`leibniz_terms`, 3^|I| terms); ``weight``
    (n_samples, n_terms), ``stretch`` (1 + m, n_samples, n_terms, 3), their terms in the order of ``column``."""
    total = 0.0
    for term in leibniz_terms(index, 3):
        parts = [column[indices] for indices in term]
        left = stretch[:, :, parts[1]] * weight[:, parts[0], None]
        right = stretch[:, :, parts[2]]
        total = total + left.reshape(left.shape[0], -1) @ right.reshape(right.shape[0], -1).T
    return total


def _muscle_expressions(fom, p: int, order: int) -> tuple:
    """(the sampled u, one compiled expression per fibre direction of the scene's muscles) of
    :func:`sampled_muscle_tensors`: for each ξ-derivative ∂_I of ``derivative_indices`` (|det J| ∂_I w, ∂_I s) at
    the points of the stiffness rule (the reference weights ω_q not included), kept on the model for its next
    designs."""
    scene = fom.scene
    sample = fx.new_function(fom.space, "muscle_sample")
    directions = [fom.shape_direction(f"muscle_direction_{k}") for k in range(p if order >= 1 else 0)]
    for k, direction in enumerate(directions):
        direction.set_parameter(k)
    stiffness = fx.constant(fom.mesh, scene.actuation.stiffness)
    jacobian = abs(ufl.JacobianDeterminant(fom.mesh))

    def derivatives(expression):          # {I: ∂_I expression}; 0 · expression for one free of the shape (k v = k)
        values = {(): expression}
        for index in derivative_indices(p, order)[1:]:
            previous = values[index[:-1]]
            values[index] = (fom.shape_derivative(previous, directions[index[-1]]) if extract_coefficients(previous)
                             else 0.0 * previous)
        return values

    def compiled(fibre):          # the stacked expression for one fibre direction
        stretch, volume = muscle_stretch(sample, fom.shape_gradients["stiffness"],
                                         nominal_volume=scene.actuation.muscle_volume == "nominal", fibre=fibre)
        weights, stretches = derivatives(stiffness * volume), derivatives(stretch)
        return fx.compile_quadrature_expression(ufl.as_vector(
            [value for index in weights for value in (jacobian * weights[index], *(stretches[index][i] for i in range(3)))]),
            fom.quadrature_degrees["stiffness"])

    fibres = [tuple(muscle.fibre) for muscle in scene.actuated_muscles]
    return sample, {fibre: compiled(fibre) for fibre in dict.fromkeys(fibres)}

@dataclass
class MuscleTensors:
    """The reduced muscles: f_act,r = -Σ_j a_j (b_j + B_j η)."""

    constant: Taylor                     # b_j (N, m): ∂Π_act,j/∂u at rest for a_j = 1 (the pair: left, right)
    linear: Taylor                       # B_j (N, m, m): ∂²Π_act,j/∂u² for a_j = 1

    def at(self, delta: np.ndarray, amplitude: float, law: ActivationLaw) -> "ReducedMuscle":
        return ReducedMuscle(self, delta, amplitude, law)


class ReducedMuscle:
    """The reduced muscles at one design ξ and amplitude A (a :class:`ReducedTerm`).

    B_j and ∂B_j/∂ξ_k are kept flat, (N, m²) and (p, N, m²), to contract Σ_j a_j B_j as one product.
    """

    def __init__(self, tensors: MuscleTensors, delta: np.ndarray, amplitude: float, law: ActivationLaw):
        self.tensors, self.delta = tensors, delta
        self.amplitude, self.law = amplitude, law
        self.constant = tensors.constant.at(delta)
        self.linear = tensors.linear.at(delta)
        n, m = self.constant.shape
        if n != law.size:
            raise ValueError(f"the PROM has {n} muscles and the activation law {law.size}")
        self._linear_rows = self.linear.reshape(n, m * m)
        self.constant_gradient = tensors.constant.gradient(delta)                      # (p, N, m)
        self._linear_gradient_rows = tensors.linear.gradient(delta).reshape(-1, n, m * m)
        self._time, self._activations = None, None

    def activations(self, time: float) -> np.ndarray:
        """(a_1, …, a_N) at time t (kept for the same t)."""
        if time != self._time:
            self._time, self._activations = time, self.amplitude * self.law.unit(time)
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
        return self._per_activation(self.law.unit(time), eta)

    def amplitude_derivative_of(self, rates: np.ndarray, eta: np.ndarray) -> np.ndarray:
        """Σ_j (∂u_j/∂θ) (b_j + B_j η) of the unit activations' derivatives ``rates`` in a parameter θ of the
        law (∂r/∂θ = A × this, a_j = A u_j)."""
        return self._per_activation(rates, eta)

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """K_t part Σ_j a_j B_j."""
        return self._stiffness(self.activations(time)), None, None

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """Σ_j a_j (∂b_j/∂ξ_k + ∂B_j/∂ξ_k η), shape (p, m)."""
        a = self.activations(time)
        m = eta.size
        return a @ self.constant_gradient + ((a @ self._linear_gradient_rows).reshape(-1, m) @ eta).reshape(-1, m)
