"""The one-period transition matrix of ``reduced_dynamics.reduced_stability`` from the compiled reduced kernel."""
from __future__ import annotations

import numpy as np

from aquarom_fenics.dynamics.batched_system import BatchedSystem, design_rows
from aquarom_fenics.fem.time_scheme import TimeScheme
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.prom import ReducedModel


def compiled_transition(prom: ReducedModel, scene: Scene, xi, amplitude: float | None, n_steps: int,
                        window_start: float) -> np.ndarray | None:
    """Φ of ``reduced_dynamics.transition_matrix`` (from rest, over the (sub-)steps starting at or after
    t_w = ``window_start``) computed by the compiled kernel, or None where the kernel cannot serve: numba missing,
    an empty window, or a step the kernel fails (``transition_matrix``'s step control may cut it; the caller
    runs that)."""
    from aquarom_fenics.dynamics import reduced_kernel

    scheme = TimeScheme.from_solver(scene.solver)
    h = scheme.time_step
    first = next((n for n in range(1, n_steps + 1) if n * h - h >= window_start - 1e-9 * h), None)
    if not reduced_kernel.available() or first is None:
        return None
    amplitude = scene.actuation.amplitude if amplitude is None else amplitude
    system = BatchedSystem(prom, scene, design_rows(xi, prom.n_parameters), scheme, np.array([amplitude]))
    transitions, failed = reduced_kernel.transition_packed(
        reduced_kernel.pack(system, scene, n_steps, False, False, transition_from=first), prom.size)
    return None if failed[0] else transitions[0]
