"""The arguments of the compiled reduced kernel for one batch, read from a
:class:`~aquarom_fenics.dynamics.batched_system.BatchedSystem` (its per-design terms) and the scene."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass
class Packed:
    """The arguments of the compiled ``integrate_all`` for one batch (contiguous float64/int64 arrays)."""

    arguments: tuple
    columns: int
    batch: int


def _array(values, dtype=float) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=dtype)


@lru_cache(maxsize=64)
def law_units(law, n_steps: int, h: float, alpha_f: float) -> np.ndarray:
    """(steps + 1, N) the activation law's units ∂a_j/∂A at the steps' evaluation times t_n - α_f h (row 0 zero),
    kept per law and time grid: a run of one design would otherwise spend a tenth of its time here."""
    units = np.zeros((n_steps + 1, law.size))
    for step in range(1, n_steps + 1):
        units[step] = law.unit(step * h - alpha_f * h)
    units.flags.writeable = False
    return units


def half_nodes(n_points: int, trapezoid: bool) -> tuple[np.ndarray, np.ndarray]:
    """(own, other) point of every half-segment: the rear half's rear and front points, then (trapezoid rule) the
    mirrored half's front and rear points, segments head -> tail (``thrust.SegmentState``'s rows)."""
    rear = np.arange(n_points - 1)
    if not trapezoid:
        return rear, rear + 1
    return np.concatenate([rear, rear[::-1] + 1]), np.concatenate([rear + 1, rear[::-1]])


def pack(system, scene, n_steps: int, sensitivities: bool, amplitude_sensitivity: bool,
         transition_from: int = 0) -> Packed:
    """The batch's arrays from a :class:`~.batched_system.BatchedSystem` (its per-design terms) and the scene;
    ``transition_from`` = n > 0: the one-period transition matrix from step n on instead of sensitivities."""
    from aquarom_fenics.dynamics.integrator import NewtonSettings
    from aquarom_fenics.dynamics.trajectory import AMPLITUDE_WINDOW, DISTANCE_WINDOW, window_mask

    scheme, prom = system.scheme, system.prom
    settings = NewtonSettings.reduced_settings(scene.solver)
    batch, m, p = system.size, prom.size, system.deltas.shape[1]
    h = scheme.time_step
    times = np.arange(n_steps + 1) * h
    units = np.zeros((batch, n_steps + 1, system.muscle_constant.shape[1]))     # (B, steps + 1, N)
    if system.laws is None:
        units[:] = law_units(system.law, int(n_steps), float(h), float(scheme.alpha_f))
    else:
        for step in range(1, n_steps + 1):
            units[:, step] = system.units(step * h - scheme.alpha_f * h)
    elastic = system.elastic
    thrust = system.thrust
    if thrust is not None:
        data, spine = prom.thrust, thrust.spine
        trapezoid = spine.trapezoid
        own_node, other_node = half_nodes(data.rows.shape[0], trapezoid)
        rows, rest_rows = data.rows, data.rest_xy_gradient
        masses = spine.virtual_mass
        spine_weight, tail_weight_gradient, front_weight = thrust.derivative_weights
        if trapezoid:
            masses = 0.5 * np.concatenate([masses, spine.front_mass[:, ::-1]], axis=1)
            spine_weight = 0.5 * np.concatenate([spine_weight, front_weight[..., ::-1]], axis=-1)
        thrust_arrays = (_array(thrust.half_rest_length), _array(thrust.half_rest_tangent), _array(masses),
                         _array(spine.virtual_mass[:, 0]), _array(spine_weight), _array(tail_weight_gradient))
    else:
        own_node = other_node = np.zeros(0, np.int64)
        rows, rest_rows = np.zeros((0, 2, m)), np.zeros((0, 2, p))
        thrust_arrays = (np.zeros((batch, 0)), np.zeros((batch, 0, 2)), np.zeros((batch, 0)), np.zeros(batch),
                         np.zeros((batch, p, 0)), np.zeros((batch, p)))
    if system.drag is not None:
        drag_direction, drag_gradient, drag_row = system.drag
    else:
        drag_direction, drag_gradient, drag_row = np.zeros((batch, m)), np.zeros((batch, p, m)), np.zeros(m)
    columns = 3 * m if transition_from > 0 else (p if sensitivities else 0) + (1 if amplitude_sensitivity else 0)
    scalars = (float(h), float(scheme.alpha_m), float(scheme.alpha_f), float(scheme.beta), float(scheme.gamma),
               float(settings.tolerance), float(settings.contraction_to_refactor), float(settings.force_floor))
    integers = (int(n_steps), int(settings.max_iterations), int(settings.iterations_per_factorization),
                int(transition_from), int(settings.refresh_each_step))
    shared = (_array(elastic.pairs, np.int64), _array(elastic.pair_of_triple, np.int64),
              _array(elastic.triples, np.int64), _array(elastic.force_coefficients),
              _array(elastic.tangent_coefficients), _array(rows), _array(own_node, np.int64),
              _array(other_node, np.int64), _array(rest_rows),
              _array(drag_row), _array(system.tail_row))
    per_design = (_array(elastic.weights), _array(elastic.weight_derivatives), _array(system.mass),
                  _array(system.damping), _array(system.mass_gradient), _array(system.damping_gradient),
                  _array(system.com_weights), _array(system.com_gradient), _array(system.amplitudes),
                  _array(system.muscle_constant), _array(system.muscle_linear),
                  _array(system.muscle_constant_gradient), _array(system.muscle_linear_gradient),
                  *thrust_arrays, _array(drag_direction), _array(drag_gradient))
    flags = (thrust is not None, bool(thrust is not None and thrust.spine.lagrangian),
             bool(thrust is not None and thrust.moving_rest), system.drag is not None, bool(sensitivities),
             bool(amplitude_sensitivity), bool(p and prom.inertia.mass.first is not None))
    arguments = (scalars, integers, units, _array(window_mask(times, DISTANCE_WINDOW), np.bool_),
                 _array(window_mask(times, AMPLITUDE_WINDOW), np.bool_), shared, per_design, flags)
    return Packed(arguments, columns, batch)


def synthetic(m: int = 2, p: int = 1, halves: int = 1, n_steps: int = 2) -> Packed:
    """A small well-posed batch of one design (unit mass and stiffness, one muscle, one thrust half-segment), for
    compiling the kernel's signature without a PROM."""
    from aquarom_fenics.dynamics.batched_system import monomial_indices

    pairs, _ = monomial_indices(m, 2)
    triples, _ = monomial_indices(m, 3)
    index = {tuple(pair): n for n, pair in enumerate(pairs.tolist())}
    pair_of_triple = np.array([index[(k, l)] for k, l, _ in triples.tolist()], dtype=np.int64)
    n_mono, n_t, terms = m + len(pairs) + len(triples), 1 + m + len(pairs), 1 + p
    force_coefficients = np.zeros((n_mono, terms * m))
    force_coefficients[:m, :m] = np.eye(m)
    tangent_coefficients = np.zeros((n_t, terms * m * m))
    tangent_coefficients[0, :m * m] = np.eye(m).ravel()
    rows = np.zeros((halves + 1, 2, m))
    rows[:, 1, 0] = np.arange(halves + 1)
    own_node, other_node = half_nodes(halves + 1, False)
    shared = (pairs.astype(np.int64), pair_of_triple, triples.astype(np.int64), force_coefficients,
              tangent_coefficients, rows, own_node, other_node, np.zeros((halves + 1, 2, p)), np.zeros(m), np.ones(m))
    eye = np.eye(m)[None]
    per_design = (np.ones((1, terms)), np.zeros((1, p, terms)), eye.copy(), 0.1 * eye, np.zeros((1, p, m, m)),
                  np.zeros((1, p, m, m)), np.ones((1, m)), np.zeros((1, p, m)), np.ones(1), np.ones((1, 1, m)),
                  np.zeros((1, 1, m, m)), np.zeros((1, p, 1, m)), np.zeros((1, p, 1, m, m)), np.ones((1, halves)),
                  np.tile([1.0, 0.0], (1, halves, 1)), np.full((1, halves), 0.1), np.full(1, 0.1),
                  np.zeros((1, p, halves)), np.zeros((1, p)), np.zeros((1, m)), np.zeros((1, p, m)))
    masks = np.ones(n_steps + 1, np.bool_)
    arguments = ((1e-2, -0.5, 0.0, 0.5625, 1.0, 1e-8, 0.25, 1e-12), (n_steps, 30, 4, 0, 1),
                 np.ones((1, n_steps + 1, 1)), masks, masks.copy(), shared, per_design,
                 (True, True, True, False, True, True, True))
    return Packed(arguments, p + 1, 1)
