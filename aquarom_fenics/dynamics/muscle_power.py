"""The muscles' mean positive power over the last activation period of a reduced run, and its gradient
over the design (the co-design's effort ``[cooptimization] effort = "power"``, issue 53)."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.trajectory import last_stroke_start
from aquarom_fenics.physics.gait import GaitRates
from aquarom_fenics.physics.muscle import ActivationLaw


def mean_positive_power(prom, scene, result, xi=None, amplitude: float | None = None) -> float:
    """The muscles' mean positive power over the last activation period [W]:

        P̄ = mean over t_n ∈ [T - 1/f, T] of max(0, f_act,r(η_n, t_n) · η̇_n),   f_act,r = -Σ_j a_j (b_j + B_j η)

    the power f_act · u̇ of the muscles' force on the body in reduced coordinates (u = V η), of a completed
    reduced run ``result`` (``simulate_reduced`` of ``scene`` at ξ and A). Work per cycle would reward a
    lower frequency over a fixed horizon; the power does not."""
    return mean_positive_power_gradient(prom, scene, result, xi, amplitude)[0]


def mean_positive_power_gradient(prom, scene, result, xi=None, amplitude: float | None = None,
                                 columns: tuple[bool, bool, bool] | None = None) -> tuple[float, np.ndarray | None]:
    """(P̄, dP̄/dz) of :func:`mean_positive_power`; dP̄/dz (None when ``columns`` is None) over the columns of
    ``result``'s sensitivities, ``columns`` = (ξ, A, gait) as ``simulate_reduced`` ran them:

        dp_n/dz = (∂f_act,r/∂z + K_a dη_n/dz) · η̇_n + f_act,r · dη̇_n/dz   where p_n > 0, else 0

    with K_a = ∂f_act,r/∂η = -Σ_j a_j B_j, ∂f_act,r/∂ξ = -Σ_j a_j (∂b_j/∂ξ + ∂B_j/∂ξ η), ∂f_act,r/∂A =
    -Σ_j u_j (b_j + B_j η) and ∂f_act,r/∂g = -Σ_j (∂a_j/∂g)(b_j + B_j η). The window [T - 1/f, T] is held
    fixed (its samples move with f by whole steps only)."""

    law = ActivationLaw.of(scene)
    muscle = prom.muscle.at(prom.delta(prom.xi_center if xi is None else np.asarray(xi, dtype=float)),
                            scene.actuation.amplitude if amplitude is None else amplitude, law)
    time = np.asarray(result.trajectory.arrays()["time"])
    start = last_stroke_start(scene.solver.duration, min(law.frequencies))
    window = np.flatnonzero(time >= start - 1e-9)
    rates = GaitRates(scene, law, muscle.amplitude) if columns is not None and columns[2] else None
    powers, gradients = [], []
    for n in window:
        t, eta, eta_dot = time[n], result.states[n], result.velocities[n]
        force = muscle.force(t, eta)
        powers.append(max(0.0, float(force @ eta_dot)))
        if columns is None:
            continue
        if powers[-1] == 0.0:
            gradients.append(np.zeros(result.sensitivities.shape[2]))
            continue
        partial = []                                          # ∂f_act,r/∂z at fixed η, one row per column
        if columns[0]:
            partial.append(-muscle.parameter_derivative(t, eta, eta_dot, None))
        if columns[1]:
            partial.append(-muscle.amplitude_derivative(t, eta)[None, :])
        if rates is not None:
            unit = rates.at(t)
            partial += [-muscle.amplitude_derivative_of(unit[:, q], eta)[None, :] for q in range(unit.shape[1])]
        partial = np.vstack(partial) if partial else np.zeros((0, eta.size))
        stiffness = -muscle.tangents(t, eta, eta_dot, None)[0]               # K_a
        gradients.append(partial @ eta_dot + eta_dot @ stiffness @ result.sensitivities[n]
                         + force @ result.velocity_sensitivities[n])
    gradient = np.mean(gradients, axis=0) if columns is not None else None
    return float(np.mean(powers)), gradient
