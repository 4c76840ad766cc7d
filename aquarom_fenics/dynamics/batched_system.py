"""The PROM's terms at a stack of designs ξ_b (b = 1..B) at once: residuals, tangents and ξ-derivatives as
(B, ...) arrays, design by design what :class:`~aquarom_fenics.dynamics.reduced_dynamics.ReducedSystem`
computes (to rounding).

The elastic force is contracted through its Taylor terms rather than through each design's tensors: with
c(Δξ) = (1, Δξ_k, ½ Δξ_k Δξ_l) the Taylor weights and T_j the Taylor terms (j = 1..J),

    K3(Δξ) η η η = Σ_j c_j(Δξ) T3_j η η η,   T3_j η η η = Σ_{k≤l≤n} μ_kln T3_j[:, k, l, n] η_k η_l η_n,

μ the number of orderings of (k, l, n) (the tensors are symmetric in their last indices), so that all
designs' forces are one matrix product of the monomials of η (B, m + m(m+1)/2 + m(m+1)(m+2)/6) with
the J Taylor terms' shared coefficients; no design's m⁴ tensor is formed (B m⁴ numbers: 2.6 GB at
m = 24, B = 1000).
"""
from __future__ import annotations

import copy
import functools
import itertools
import math

import numpy as np

from aquarom_fenics.fem.time_scheme import TimeScheme
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.physics.muscle import ActivationLaw
from aquarom_fenics.physics.taylor import Taylor
from aquarom_fenics.physics.thrust_batched import BatchedThrust
from aquarom_fenics.reduction.prom import ReducedModel


def taylor_weights(deltas: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(c (B, J), ∂c/∂Δξ (B, p, J)) of T(Δξ) = Σ_j c_j T_j with T_j = (T0, T1[k], T2[k, l] (all k, l)):
    c = (1, Δξ_k, ½ Δξ_k Δξ_l)."""
    batch, p = deltas.shape
    parts, derivatives = [np.ones((batch, 1))], [np.zeros((batch, p, 1))]
    if order >= 1:
        parts.append(deltas)
        derivatives.append(np.broadcast_to(np.eye(p), (batch, p, p)))
    if order >= 2:
        parts.append(0.5 * np.einsum("bk,bl->bkl", deltas, deltas).reshape(batch, -1))
        eye = np.eye(p)
        # ∂(½ Δξ_k Δξ_l)/∂Δξ_q = ½ (δ_qk Δξ_l + Δξ_k δ_ql)
        derivatives.append(0.5 * (np.einsum("qk,bl->bqkl", eye, deltas) + np.einsum("bk,ql->bqkl", deltas, eye))
                           .reshape(batch, p, -1))
    return np.concatenate(parts, axis=1), np.concatenate(derivatives, axis=2)


def taylor_terms(taylor: Taylor, p: int, order: int) -> np.ndarray:
    """The Taylor terms T_j = (T0, T1[k], T2[k, l]) up to ``order`` stacked, (J, ...) (zero above the tensor's own
    order)."""
    shape = np.shape(taylor.constant)
    terms = [np.asarray(taylor.constant, dtype=float)[None]]
    if order >= 1:
        terms.append(taylor.first if taylor.first is not None else np.zeros((p,) + shape))
    if order >= 2:
        terms.append(taylor.second.reshape((-1,) + shape) if taylor.second is not None else np.zeros((p * p,) + shape))
    return np.concatenate(terms)


def taylor_order(taylors: list[Taylor], p: int) -> int:
    """The highest order of the Taylor polynomials (0 without parameters)."""
    if not p:
        return 0
    return max(2 if t.second is not None else 1 if t.first is not None else 0 for t in taylors)


def taylor_at(taylor: Taylor, deltas: np.ndarray) -> np.ndarray:
    """T(Δξ_b) of every design, (B, ...)."""
    value = np.broadcast_to(np.asarray(taylor.constant, dtype=float), (deltas.shape[0],) + np.shape(taylor.constant))
    if taylor.first is not None and deltas.shape[1]:
        value = value + np.tensordot(deltas, taylor.first, axes=1)
    if taylor.second is not None and deltas.shape[1]:
        value = value + 0.5 * np.einsum("bk,bl,kl...->b...", deltas, deltas, taylor.second)
    return np.array(value)


def taylor_gradient(taylor: Taylor, deltas: np.ndarray) -> np.ndarray:
    """∂T/∂ξ_k at every design, (B, p, ...)."""
    batch, p = deltas.shape
    shape = np.shape(taylor.constant)
    if taylor.first is None:
        return np.zeros((batch, p) + shape)
    value = np.broadcast_to(taylor.first, (batch,) + taylor.first.shape)
    if taylor.second is not None:
        value = value + np.tensordot(deltas, taylor.second, axes=1)
    return np.array(value)


@functools.lru_cache(maxsize=8)
def monomial_indices(m: int, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """The sorted index tuples k₁ ≤ … ≤ k_d of the degree-d monomials of η (n, d) and their orderings μ (n,)."""
    tuples = np.array(list(itertools.combinations_with_replacement(range(m), degree)), dtype=int).reshape(-1, degree)
    counts = np.array([math.factorial(degree) // math.prod(math.factorial(list(row).count(k)) for k in set(row))
                       for row in tuples.tolist()], dtype=float)
    return tuples, counts


class SharedElastic:
    """The design-independent part of :class:`BatchedElastic` for one PROM's elastic tensors: the Taylor order,
    the monomials' indices and the Taylor terms' force and tangent coefficients."""

    def __init__(self, tensors, m: int, p: int):
        taylors = (tensors.linear, tensors.quadratic, tensors.cubic)
        self.order = taylor_order(taylors, p)
        linear, quadratic, cubic = (taylor_terms(t, p, self.order) for t in taylors)
        self.n_terms = linear.shape[0]
        self.pairs, pair_counts = monomial_indices(m, 2)
        self.triples, triple_counts = monomial_indices(m, 3)
        # force coefficients on the monomials (η_k; η_k η_l, k ≤ l; η_k η_l η_n, k ≤ l ≤ n): rows monomials, columns (j, i)
        pair_rows = quadratic[:, :, self.pairs[:, 0], self.pairs[:, 1]] * pair_counts          # (J, m, n2)
        triple_rows = cubic[:, :, self.triples[:, 0], self.triples[:, 1], self.triples[:, 2]] * triple_counts
        self.force_coefficients = np.concatenate([linear, pair_rows, triple_rows], axis=2).transpose(2, 0, 1) \
            .reshape(-1, self.n_terms * m).copy()
        # tangent coefficients: K1_j + 2 T2_j η + 3 T3_j η η, rows (1; η_l; η_l η_n, l ≤ n), columns (j, i, k)
        tangent_pairs = 3.0 * cubic[..., self.pairs[:, 0], self.pairs[:, 1]] * pair_counts      # (J, m, m, n2)
        self.tangent_coefficients = np.concatenate(
            [linear[..., None], 2.0 * quadratic, tangent_pairs], axis=3).transpose(3, 0, 1, 2) \
            .reshape(-1, self.n_terms * m * m).copy()
        index = {tuple(pair): n for n, pair in enumerate(self.pairs.tolist())}
        self.pair_of_triple = np.array([index[(k, l)] for k, l, _ in self.triples.tolist()], dtype=int)


_SHARED_ELASTIC: dict = {}
"""id(tensors), p -> (tensors, SharedElastic): the last few PROMs' (a batch of one design would otherwise spend a
fifth of its time forming them again)."""


def shared_elastic(tensors, m: int, p: int) -> SharedElastic:
    """The :class:`SharedElastic` of these elastic tensors, formed once (the last 8 kept)."""
    key = (id(tensors), p)
    kept = _SHARED_ELASTIC.get(key)
    if kept is not None and kept[0] is tensors:
        return kept[1]
    shared = SharedElastic(tensors, m, p)
    if len(_SHARED_ELASTIC) >= 8:
        _SHARED_ELASTIC.pop(next(iter(_SHARED_ELASTIC)))
    _SHARED_ELASTIC[key] = (tensors, shared)
    return shared


class StackedTaylors:
    """Several Taylor polynomials of one PROM as one matrix of their terms (J, Σ sizes): all their values at B
    designs are one product c(Δξ_b) @ terms, all their ξ-derivatives one product ∂c/∂Δξ @ terms (c, ∂c:
    :func:`taylor_weights` at :attr:`order`), instead of two small tensor contractions per polynomial (a batch of
    one design spent a tenth of a millisecond on them). The products are taken design by design: BLAS rounds a
    product of B rows otherwise than B products of one row, and a design's cost must not depend on the designs
    batched with it (the multi-start screen reports the optimiser's own L)."""

    def __init__(self, taylors: dict, p: int):
        self.taylors = taylors
        self.order = taylor_order(list(taylors.values()), p)
        self.shapes = {name: np.shape(taylor.constant) for name, taylor in taylors.items()}
        blocks = [taylor_terms(taylor, p, self.order) for taylor in taylors.values()]
        self.n_terms = blocks[0].shape[0]
        self.terms = np.concatenate([block.reshape(self.n_terms, -1) for block in blocks], axis=1)
        ends = np.cumsum([block[0].size for block in blocks])
        self.columns = {name: slice(end - block[0].size, end) for name, block, end in zip(taylors, blocks, ends)}

    def at(self, weights: np.ndarray, weight_derivatives: np.ndarray) -> tuple[dict, dict]:
        """({name: T(Δξ_b) (B, ...)}, {name: ∂T/∂ξ_k (B, p, ...)}) from the designs' weights (B, J) and their
        derivatives (B, p, J)."""
        batch, p, _ = weight_derivatives.shape
        values, gradients = np.empty((batch, self.terms.shape[1])), np.empty((batch, p, self.terms.shape[1]))
        for b in range(batch):          # one product per design: its numbers do not depend on the batch it is in
            values[b] = weights[b] @ self.terms
            gradients[b] = weight_derivatives[b] @ self.terms
        return ({name: values[:, part].reshape((batch,) + self.shapes[name]) for name, part in self.columns.items()},
                {name: gradients[:, :, part].reshape((batch, p) + self.shapes[name])
                 for name, part in self.columns.items()})


_STACKED: dict = {}
"""(ids of the Taylors, p) -> StackedTaylors of the last few PROMs."""


def stacked_taylors(taylors: dict, p: int) -> StackedTaylors:
    """The :class:`StackedTaylors` of these polynomials, formed once (the last 8 kept)."""
    key = (tuple(id(taylor) for taylor in taylors.values()), tuple(taylors), p)
    kept = _STACKED.get(key)
    if kept is not None and all(a is b for a, b in zip(kept.taylors.values(), taylors.values())):
        return kept
    stacked = StackedTaylors(dict(taylors), p)
    if len(_STACKED) >= 8:
        _STACKED.pop(next(iter(_STACKED)))
    _STACKED[key] = stacked
    return stacked


class BatchedElastic:
    """f_int,r(η_b; ξ_b) = Σ_j c_j(Δξ_b) (T1_j η + T2_j η η + T3_j η η η) of B designs."""

    def __init__(self, prom: ReducedModel, deltas: np.ndarray, linear: np.ndarray | None = None):
        tensors = prom.elastic
        shared = shared_elastic(tensors, prom.size, deltas.shape[1])
        self.weights, self.weight_derivatives = taylor_weights(deltas, shared.order)  # (B, J), (B, p, J)
        self.n_terms, self.pairs, self.triples = shared.n_terms, shared.pairs, shared.triples
        self.force_coefficients, self.tangent_coefficients = shared.force_coefficients, shared.tangent_coefficients
        self.pair_of_triple = shared.pair_of_triple
        # K1 = K_0,r (B, m, m); ``linear``: already evaluated by the caller
        self.linear = taylor_at(tensors.linear, deltas) if linear is None else linear

    def select(self, rows: np.ndarray) -> "BatchedElastic":
        """The term of the designs ``rows``."""
        part = copy.copy(self)
        part.weights, part.weight_derivatives, part.linear = (self.weights[rows], self.weight_derivatives[rows],
                                                              self.linear[rows])
        return part

    def monomials(self, eta: np.ndarray) -> np.ndarray:
        """(η_k; η_k η_l, k ≤ l; η_k η_l η_n, k ≤ l ≤ n) of every design, (B, n_monomials)."""
        products = eta[:, self.pairs[:, 0]] * eta[:, self.pairs[:, 1]]
        return np.concatenate([eta, products, products[:, self.pair_of_triple] * eta[:, self.triples[:, 2]]], axis=1)

    def tangent_monomials(self, eta: np.ndarray) -> np.ndarray:
        """(1; η_l; η_l η_n, l ≤ n) of every design, (B, 1 + m + m(m+1)/2)."""
        products = eta[:, self.pairs[:, 0]] * eta[:, self.pairs[:, 1]]
        return np.concatenate([np.ones((eta.shape[0], 1)), eta, products], axis=1)

    def term_forces(self, eta: np.ndarray) -> np.ndarray:
        """Each Taylor term's force T1_j η + T2_j η η + T3_j η η η, (B, J, m)."""
        return (self.monomials(eta) @ self.force_coefficients).reshape(eta.shape[0], self.n_terms, -1)

    def force(self, eta: np.ndarray) -> np.ndarray:
        return np.einsum("bj,bji->bi", self.weights, self.term_forces(eta))

    def tangent(self, eta: np.ndarray) -> np.ndarray:
        """K1 + 2 K2 η + 3 K3 η η, (B, m, m)."""
        batch, m = eta.shape
        terms = (self.tangent_monomials(eta) @ self.tangent_coefficients).reshape(batch, self.n_terms, m * m)
        return np.einsum("bj,bji->bi", self.weights, terms).reshape(batch, m, m)

    def force_gradient(self, eta: np.ndarray) -> np.ndarray:
        """∂f_int,r/∂ξ_k, (B, p, m)."""
        return np.einsum("bkj,bji->bki", self.weight_derivatives, self.term_forces(eta))


class BatchedSystem:
    """r_r of B designs (and actuation amplitudes A_b): the terms of ``ReducedSystem`` with a batch axis.

    r_r = M_r η̈ + C_r η̇ + f_int,r(η) - f_act,r(η, t) - f_thrust,r(η, η̇, η̈) - f_drag,r(η̇), each (B, m).
    """

    def __init__(self, prom: ReducedModel, scene: Scene, xis: np.ndarray, scheme: TimeScheme,
                 amplitudes: np.ndarray | None = None, laws: list | None = None):
        self.prom, self.scheme = prom, scheme
        xis = design_rows(xis, prom.n_parameters)
        self.deltas = d = np.array([prom.delta(xi) for xi in xis]).reshape(xis.shape)
        batch = d.shape[0]
        inertia, muscle = prom.inertia, prom.muscle
        taylors = {"mass": inertia.mass, "total_mass": inertia.total_mass, "moment": inertia.mass_moment_x,
                   "stiffness": prom.elastic.linear, "muscle_constant": muscle.constant, "muscle_linear": muscle.linear}
        if prom.drag is not None:
            taylors["drag"] = prom.drag.direction
        stacked = stacked_taylors(taylors, d.shape[1])
        value, gradient = stacked.at(*taylor_weights(d, stacked.order))
        self.elastic = BatchedElastic(prom, d, linear=value["stiffness"])
        self.mass = value["mass"]
        self.damping = inertia.damping(self.mass, self.elastic.linear)
        total_mass = value["total_mass"]
        self.com_weights = value["moment"] / total_mass[:, None]
        self.mass_gradient = gradient["mass"]                                              # (B, p, m, m)
        self.damping_gradient = inertia.damping(self.mass_gradient, gradient["stiffness"])
        if inertia.mass_moment_x.first is None:
            self.com_gradient = np.zeros((batch, d.shape[1], prom.size))
        else:
            moment, total = gradient["moment"], gradient["total_mass"][:, :, None]
            self.com_gradient = (moment - total * self.com_weights[:, None, :]) / total_mass[:, None, None]
        amplitude = np.full(batch, scene.actuation.amplitude) if amplitudes is None else np.asarray(amplitudes, float)
        self.amplitudes, self.law = amplitude.reshape(batch), ActivationLaw.of(scene)
        self.laws = None                        # (B,) ActivationLaw: a gait per design, else the scene's law
        if laws is not None:
            self.laws = np.empty(batch, dtype=object)
            for b, law in enumerate(laws):
                self.laws[b] = law
        self.muscle_constant = value["muscle_constant"]                                    # (B, N, m)
        self.muscle_linear = value["muscle_linear"]                                        # (B, N, m, m)
        self.muscle_constant_gradient = gradient["muscle_constant"]                        # (B, p, N, m)
        self.muscle_linear_gradient = gradient["muscle_linear"]                            # (B, p, N, m, m)
        self.thrust = BatchedThrust(prom.thrust, d, scene.fluid.spine_force) if prom.thrust is not None else None
        self.drag = None
        if prom.drag is not None:
            self.drag = (value["drag"], gradient["drag"], prom.drag.velocity_row)
        self.tail_row, self.head_row = prom.observation.tail_y_row, prom.observation.head_x_row

    @property
    def size(self) -> int:
        return self.deltas.shape[0]

    PER_DESIGN = ("deltas", "mass", "damping", "com_weights", "mass_gradient", "damping_gradient", "com_gradient",
                  "amplitudes", "muscle_constant", "muscle_linear", "muscle_constant_gradient", "muscle_linear_gradient",
                  "laws")
    """The attributes with one entry per design (leading axis)."""

    def select(self, rows: np.ndarray) -> "BatchedSystem":
        """The system of the designs ``rows`` (indices; itself for all of them, in order)."""
        if rows.size == self.size and np.array_equal(rows, np.arange(self.size)):
            return self
        part = copy.copy(self)
        for name in self.PER_DESIGN:
            if getattr(self, name) is not None:
                setattr(part, name, getattr(self, name)[rows])
        part.elastic = self.elastic.select(rows)
        part.thrust = self.thrust.select(rows) if self.thrust is not None else None
        if self.drag is not None:
            part.drag = (self.drag[0][rows], self.drag[1][rows], self.drag[2])
        return part

    def set_time_step(self, scheme: TimeScheme) -> None:
        self.scheme = scheme

    # ------------------------------------------------------------------ forces
    def units(self, time: float) -> np.ndarray:
        """(B, N) each design's activations per unit amplitude at time t: the scene's law, or each design's own
        (``laws``: the scene driven by each design's gait)."""
        if self.laws is None:
            return np.broadcast_to(self.law.unit(time), (self.size, self.law.size))
        return np.array([law.unit(time) for law in self.laws])

    def _muscle_stiffness(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """(a_b (B, N), Σ_j a_j B_j (B, m, m)) at time t."""
        activations = self.amplitudes[:, None] * self.units(time)
        return activations, np.einsum("bn,bnkl->bkl", activations, self.muscle_linear)

    def residual(self, time, eta, eta_dot, eta_ddot) -> tuple[np.ndarray, np.ndarray]:
        """(r_r (B, m), the force scale of Newton's test per design (B,))."""
        inertia = np.einsum("bkl,bl->bk", self.mass, eta_ddot)
        internal = self.elastic.force(eta)
        activations, stiffness = self._muscle_stiffness(time)
        external = -(np.einsum("bn,bnk->bk", activations, self.muscle_constant) + np.einsum("bkl,bl->bk", stiffness, eta))
        if self.thrust is not None:
            external = external + self.thrust.force(eta, eta_dot, eta_ddot)
        if self.drag is not None:
            direction, _, row = self.drag
            external = external + direction * ((eta_dot @ row) ** 2)[:, None]
        residual = inertia + np.einsum("bkl,bl->bk", self.damping, eta_dot) + internal - external
        scale = np.sqrt(np.maximum(np.maximum(norms2(internal), norms2(external)), norms2(inertia)))
        return residual, scale

    def tangents(self, time, eta, eta_dot, eta_ddot):
        """(K_t, C_t, M_t) = ∂r/∂(η, η̇, η̈), each (B, m, m)."""
        stiffness = self.elastic.tangent(eta) + self._muscle_stiffness(time)[1]
        damping, mass = self.damping, self.mass
        if self.thrust is not None:
            thrust = self.thrust.tangents(time, eta, eta_dot, eta_ddot)
            stiffness, damping, mass = stiffness + thrust[0], damping + thrust[1], mass + thrust[2]
        if self.drag is not None:
            direction, _, row = self.drag
            column = 2.0 * (eta_dot @ row)[:, None] * direction
            damping = damping + (-column)[:, :, None] * row
        return stiffness, damping, mass

    def newton_matrix(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """S = (1 - α_f) K_t + (1 - α_f)(γ/(βh)) C_t + ((1 - α_m)/(βh²)) M_t, (B, m, m)."""
        scheme = self.scheme
        factors = (scheme.stiffness_factor, scheme.velocity_factor, scheme.acceleration_factor)
        stiffness = self.elastic.tangent(eta) + self._muscle_stiffness(time)[1]
        damping = self.damping
        if self.drag is not None:
            direction, _, row = self.drag
            damping = damping + (-2.0 * (eta_dot @ row)[:, None] * direction)[:, :, None] * row
        matrix = factors[0] * stiffness + factors[1] * damping + factors[2] * self.mass
        if self.thrust is not None:
            matrix += self.thrust.newton_part(factors, eta, eta_dot, eta_ddot)
        return matrix

    def parameter_derivative(self, time, eta, eta_dot, eta_ddot) -> np.ndarray:
        """∂r/∂ξ_k at fixed (η, η̇, η̈), (B, m, p)."""
        batch, m = eta.shape
        p = self.deltas.shape[1]
        if p == 0 or self.prom.inertia.mass.first is None:
            return np.zeros((batch, m, p))
        derivative = self.elastic.force_gradient(eta)
        activations = self.amplitudes[:, None] * self.units(time)
        derivative = derivative + (np.einsum("bn,bknl->bkl", activations, self.muscle_constant_gradient)
                                   + np.einsum("bn,bknil,bl->bki", activations, self.muscle_linear_gradient, eta))
        derivative = derivative + (np.einsum("bkij,bj->bki", self.mass_gradient, eta_ddot)
                                   + np.einsum("bkij,bj->bki", self.damping_gradient, eta_dot))
        if self.thrust is not None:
            derivative = derivative + self.thrust.parameter_derivative(time, eta, eta_dot, eta_ddot)
        if self.drag is not None:
            _, direction_gradient, row = self.drag
            derivative = derivative - direction_gradient * ((eta_dot @ row) ** 2)[:, None, None]
        return np.swapaxes(derivative, 1, 2)

    def amplitude_derivative(self, time, eta) -> np.ndarray:
        """∂r/∂A_b = Σ_j (∂a_j/∂A) (b_j + B_j η), (B, m)."""
        unit = self.units(time)
        return (np.einsum("bn,bnk->bk", unit, self.muscle_constant)
                + np.einsum("bn,bnkl,bl->bk", unit, self.muscle_linear, eta))

    def observables(self, eta) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(head x, tail y, centre-of-mass x) [m] of every design, each (B,)."""
        return eta @ self.head_row, eta @ self.tail_row, np.einsum("bk,bk->b", self.com_weights, eta)


def design_rows(xis, p: int) -> np.ndarray:
    """Designs as rows (B, p); one design (p,) is a batch of one."""
    xis = np.asarray(xis, dtype=float)
    return xis.reshape(1, p) if xis.ndim < 2 else xis.reshape(xis.shape[0], p)


def norms2(vectors: np.ndarray) -> np.ndarray:
    """‖x_b‖² of (B, m) rows."""
    return np.einsum("bk,bk->b", vectors, vectors)
