"""The activations' derivatives in the gait's design variables (``[gait]``, io/scene_gait.py).

The gait variables g change only the activations a_j(t) = A s_j r(t) sin θ_j, θ_j = 2π f t + φ_j, and
the muscle force is linear in each a_j (physics/muscle.py): the reduced residual's derivative is

    ∂r/∂g = Σ_j (∂a_j/∂g) (b_j + B_j η)      (``ReducedMuscle.amplitude_derivative_of``)

with, for muscle j of pair k_j (from 1 at the tail), φ_j = (k_j - 1) λ (λ in degrees):

    ∂a_j/∂f   = A s_j (2π t r cos θ_j + (∂r/∂τ)(dτ/df) sin θ_j)
    ∂a_j/∂λ   = A s_j r cos θ_j (k_j - 1) π/180
    ∂a_j/∂A_k = sign(s_j) r sin θ_j   for the two muscles of pair k (s_j = ±A_k / A), else 0

(times A_run / A where a run's amplitude A_run overrides the scene's A, as a co-design's does).

r(t) = sin²(π t / 2τ) for t < τ: ∂r/∂τ = -(π t / 2τ²) sin(π t / τ) (0 for t ≥ τ, continuous at t = τ).
dτ/df = -τ / f where the smooth start is "auto" and on (τ = 1/(4 f), the quarter period of the gait's
one frequency), else 0 (a τ given in seconds, or none).
"""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.io.scene_gait import gait_pairs, pair_number
from aquarom_fenics.physics.muscle import ActivationLaw, start_ramp


def ramp_time_derivative(time: float, ramp_time: float) -> float:
    """∂r/∂τ of r(t) = sin²(π t / 2τ) for t < τ, else 0 [1/s]."""
    if ramp_time <= 0.0 or time >= ramp_time:
        return 0.0
    return -0.5 * math.pi * time / ramp_time ** 2 * math.sin(math.pi * time / ramp_time)


class GaitRates:
    """∂a_j/∂g of a scene driven by its gait (``apply_gait``), per variable of its ``[gait]`` in order."""

    def __init__(self, scene, law, amplitude: float):
        self.names = scene.gait_names
        self.law, self.amplitude = law, amplitude
        self.pair_factor = amplitude / scene.actuation.amplitude if scene.actuation.amplitude > 0 else 1.0
        muscles = scene.actuated_muscles
        self.pair_of = np.zeros(len(muscles), dtype=int)
        for pair in gait_pairs(muscles, scene.regions):
            self.pair_of[list(pair.muscles)] = pair.number
        quarter = scene.actuation.start_ramp == "auto" and law.ramp_time > 0.0
        self.ramp_rate = -law.ramp_time / law.frequencies[0] if quarter else 0.0      # dτ/df

    def at(self, time: float) -> np.ndarray:
        """(N, q): ∂a_j/∂g_q at time t."""
        law = self.law
        scales, phases = np.array(law.scales), np.array(law.phases)
        angles = 2.0 * np.pi * np.array(law.frequencies) * time + phases
        ramp = start_ramp(time, law.ramp_time)
        columns = []
        for name in self.names:
            if name == "frequency":
                ramp_rate = ramp_time_derivative(time, law.ramp_time) * self.ramp_rate
                column = self.amplitude * scales * (2.0 * np.pi * time * ramp * np.cos(angles)
                                                    + ramp_rate * np.sin(angles))
            elif name == "phase_lag":
                column = self.amplitude * scales * ramp * np.cos(angles) * (self.pair_of - 1) * np.pi / 180.0
            else:
                column = np.where(self.pair_of == pair_number(name),
                                  self.pair_factor * np.sign(scales) * ramp * np.sin(angles), 0.0)
            columns.append(column)
        return np.column_stack(columns) if columns else np.zeros((law.size, 0))
