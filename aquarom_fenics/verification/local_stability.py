"""Frozen-coefficient stability of a FOM state on a region of the body (SPEC §5–§6).

Linearised about a state (u, u̇, ü) at time t, the FOM's equations r = M ü + C u̇ + f_int - f_ext = 0 read

    M_t δü + C_t δu̇ + K_t δu = 0,   M_t = ∂r/∂ü,  C_t = ∂r/∂u̇,  K_t = ∂r/∂u

(the thrust's added mass is in M_t, its velocity Jacobian in C_t, its position Jacobian and the muscles'
stiffness in K_t). Restricted to the dofs of a region, the rest of the body held fixed, with the
coefficients frozen at the state:

- continuous: the eigenvalues λ of λ² M_t + λ C_t + K_t; a mode with Re λ > 0 grows like e^{Re λ t};
- discrete: the spectral radius ρ of generalized-α's step map (δu, δu̇, δü)_n → (δu, δu̇, δü)_{n+1}
  of that linear system at step h; ρ > 1 grows by ρ per step.

Frozen coefficients describe modes much faster than the state changes (here kHz modes of the tail
against a 1 Hz gait); the region must be small for dense eigenvalues (a few hundred nodes).

:func:`prom_tail_stability` is the PROM-side screen built on it: the same linearisation at FOM states
rebuilt from a PROM trajectory, for the tail modes the PROM's basis does not hold.
"""
from __future__ import annotations

import os
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.sparse
from mpi4py import MPI

from aquarom_fenics.dynamics.integrator import TimeScheme
from aquarom_fenics.dynamics.reduced_dynamics import Stability, simulate_reduced
from aquarom_fenics.dynamics.simulate import check_time_grid
from aquarom_fenics.dynamics.trajectory import last_stroke_start
from aquarom_fenics.errors import InputError
from aquarom_fenics.parallel import in_worker, worker_threads
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import Fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.prom import ReducedModel
from aquarom_fenics.reduction.reductor import reused_basis


@dataclass
class LocalStability:
    """The region's frozen linearisation at one state."""

    time: float                     # [s]
    growth_rate: float              # max Re λ [1/s]
    frequency: float                # |Im λ| / 2π of that eigenvalue [Hz]
    spectral_radius: float          # ρ of the scheme's step map at the scheme's h

    def summary(self) -> dict:
        return {"time": self.time, "growth_rate": self.growth_rate, "frequency": self.frequency,
                "spectral_radius": self.spectral_radius}


def tangents(model, time: float, u, v, a) -> tuple[scipy.sparse.csr_matrix, ...]:
    """(K_t, C_t, M_t) of a serial FOM at a state as the model's matrices hold them (fixed dofs: unit
    rows); with stations the coupling over slabs is not in them (see :func:`region_tangents`)."""
    if model.comm.size > 1:
        raise ValueError("the local stability analysis runs on one rank")
    return tuple(_scipy_copy(matrix) for matrix in model.tangents(time, u, v, a))


def _scipy_copy(matrix) -> scipy.sparse.csr_matrix:
    rows, columns, values = matrix.getValuesCSR()
    return scipy.sparse.csr_matrix((values.copy(), columns.copy(), rows.copy()))


def region_dofs(model, center, radius: float) -> np.ndarray:
    """Free dofs of the nodes within ``radius`` [m] of the point ``center`` (3,) [m] (rest shape)."""
    center = np.asarray(center, dtype=float)
    positions = model.rest_points[model.layout.owned_nodes]
    distances = np.linalg.norm(positions - center, axis=1)
    near = np.flatnonzero(distances < radius)
    dofs = np.setdiff1d((3 * near[:, None] + np.arange(3)).ravel(), model.fixed_dofs)
    if not dofs.size:
        free_nodes = np.setdiff1d(np.arange(positions.shape[0]), model.fixed_dofs // 3)
        where = ", ".join(f"{value:.4g}" for value in center)
        raise InputError(f"the region of radius {radius:g} m around ({where}) m holds no free node; "
                         f"the nearest free node is {distances[free_nodes].min():.3g} m away: use a larger radius")
    return dofs


def pencil_eigenvalues(stiffness: np.ndarray, damping: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """λ with (λ² M + λ C + K) x = 0: the eigenvalues of the companion matrix [[0, I], [-M⁻¹K, -M⁻¹C]]
    (M, a mass matrix with the added mass, is invertible)."""
    n = stiffness.shape[0]
    scaled_stiffness, scaled_damping = np.hsplit(np.linalg.solve(mass, np.hstack([stiffness, damping])), 2)
    return np.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)], [-scaled_stiffness, -scaled_damping]]))


def step_matrix(stiffness: np.ndarray, damping: np.ndarray, mass: np.ndarray, scheme: TimeScheme) -> np.ndarray:
    """G with (δu, δu̇, δü)_{n+1} = G (δu, δu̇, δü)_n: one step of the scheme (its own predictor,
    corrector and evaluation point) on M ü + C u̇ + K u = 0, whose Newton step is exact:
    u_{n+1} = ũ - S⁻¹ r(ũ), S = k_a M + k_v C + k_u K, ũ the predictor."""
    n = stiffness.shape[0]
    old = tuple(np.hstack([np.eye(n) if block == k else np.zeros((n, n)) for block in range(3)]) for k in range(3))
    u_predicted, v_predicted = scheme.predict(*old)
    _, u_point, v_point, a_point = scheme.evaluation_point(
        0.0, old, (u_predicted, v_predicted, np.zeros_like(u_predicted)))
    residual = mass @ a_point + damping @ v_point + stiffness @ u_point
    newton = scheme.acceleration_factor * mass + scheme.velocity_factor * damping + scheme.stiffness_factor * stiffness
    u_new = u_predicted - np.linalg.solve(newton, residual)
    return np.vstack([u_new, *scheme.correct(u_new, u_predicted, v_predicted)])


def region_tangents(model, time: float, u, v, a, dofs: np.ndarray) -> tuple[np.ndarray, ...]:
    """(K_t, C_t, M_t) of ``model`` at (t, u, u̇, ü) restricted to ``dofs`` (dense), exact: with stations
    the slab coupling Bᵀ J B and the head-averaged drag restricted to the region are added."""
    region = np.ix_(dofs, dofs)
    blocks = [matrix[region].toarray() for matrix in tangents(model, time, u, v, a)]
    coupling = model.newton_matrix.coupling_blocks(time, u, v, a, dofs)
    if coupling is not None:
        blocks = [block + extra for block, extra in zip(blocks, coupling)]
    return tuple(blocks)


def fastest_eigenvalue(stiffness: np.ndarray, damping: np.ndarray, mass: np.ndarray) -> complex:
    """The eigenvalue λ of λ² M + λ C + K with the largest real part."""
    eigenvalues = pencil_eigenvalues(stiffness, damping, mass)
    return complex(eigenvalues[np.argmax(eigenvalues.real)])


def local_stability(model, time: float, u, v, a, dofs: np.ndarray, scheme: TimeScheme) -> LocalStability:
    """The frozen linearisation of ``model`` at (t, u, u̇, ü) on ``dofs``: fastest growth and ρ at h."""
    stiffness, damping, mass = region_tangents(model, time, u, v, a, dofs)
    fastest = fastest_eigenvalue(stiffness, damping, mass)
    radius = float(np.abs(np.linalg.eigvals(step_matrix(stiffness, damping, mass, scheme))).max())
    return LocalStability(time, fastest.real, abs(fastest.imag) / (2 * np.pi), radius)


TAIL_SAMPLE_INTERVAL = 0.02
"""Time between the PROM states the tail screen linearises [s]: one step at the default h = 0.02 s
(the CO designs' 2 kHz tail mode grows fast during windows of a few steps only, around the tail's
midline crossings)."""


def tail_sample_steps(scene: Scene) -> np.ndarray:
    """Steps k (t = k h) whose states the tail screen linearises: the last stroke [T - 1/f, T] (the
    whole horizon if shorter), every ``TAIL_SAMPLE_INTERVAL``, never the rest state k = 0."""
    h, n_steps = scene.solver.time_step, check_time_grid(scene)
    window_start = last_stroke_start(scene.solver.duration, scene.actuation.frequency)
    stride = max(1, round(TAIL_SAMPLE_INTERVAL / h))
    steps = np.arange(max(int(np.ceil(window_start / h - 1e-9)), 1), n_steps + 1)
    return steps[steps % stride == 0]


@dataclass(frozen=True)
class TailGrowth:
    """The fastest tail mode the screen met over the PROM states it linearised."""

    time: float                     # of the state [s]
    growth_rate: float              # Re λ [1/s]
    frequency: float                # |Im λ| / 2π [Hz]
    states: int                     # states linearised


def prom_tail_growth(prom: ReducedModel, scene: Scene, fish: Fish, xi=None, stop_above: float = np.inf,
                     comm: MPI.Comm = MPI.COMM_WORLD) -> TailGrowth | str:
    """The fastest tail mode at design ξ along the PROM's last stroke (or the PROM's stop message).

    The PROM is integrated over the horizon; on its last stroke [T - 1/f, T], every
    ``TAIL_SAMPLE_INTERVAL``, the FOM state is rebuilt from the basis V,

        u = V η,  u̇ = V η̇,  ü = V η̈,

    and the FOM at ξ is linearised about it on the tail region (free nodes within
    ``[optimizer] tail_region_radius`` of the tail's observation point, the tail station), coefficients frozen: the largest Re λ of
    λ² M_t + λ C_t + K_t. Stops at the first state whose growth rate exceeds ``stop_above`` [1/s].
    The ranks of ``comm`` share the states (each linearises its own on one rank) and return the
    same answer as one rank: the states up to the first one over the limit.
    """
    xi = prom.xi_center if xi is None else np.asarray(xi, dtype=float)
    result = simulate_reduced(prom, scene, xi)
    if not result.completed:
        return result.error
    times = result.trajectory.arrays()["time"]
    steps = tail_sample_steps(scene)
    model = FullOrderModel(scene, fish, xi, comm=MPI.COMM_SELF)
    rates, failure = [], None           # (position in steps, λ) of this rank's states
    try:
        basis = reused_basis(model, prom).vectors
        dofs = region_dofs(model, model.tail_point(), scene.optimizer.tail_region_radius)

        def tangents_at(position):
            k = steps[position]
            state = (basis @ result.states[k], basis @ result.velocities[k], basis @ result.accelerations[k])
            return region_tangents(model, times[k], *state, dofs)

        rates = _rates_in_order(tangents_at, range(comm.rank, steps.size, comm.size), stop_above,
                                eigenvalue_threads(comm))
    except Exception as error:          # raised on every rank below, so that none waits for the others
        failure = error
    finally:
        model.destroy()
    gathered = comm.allgather((rates, failure))
    for _, error in gathered:
        if error is not None:
            raise error
    rates = sorted((item for part, _ in gathered for item in part), key=lambda item: item[0])
    over = [position for position, eigenvalue in rates if eigenvalue.real > stop_above]
    linearised = [(position, eigenvalue) for position, eigenvalue in rates if not over or position <= over[0]]
    position, eigenvalue = max(linearised, key=lambda item: item[1].real)   # the first of equal maxima
    return TailGrowth(float(times[steps[position]]), eigenvalue.real, abs(eigenvalue.imag) / (2 * np.pi),
                      len(linearised))


def eigenvalue_threads(comm: MPI.Comm) -> int:
    """Threads for the screen's dense eigenvalues: 2 on one rank with a spare core outside a worker
    (the ranks, or the other workers, use the cores otherwise), else 0 (one after the other)."""
    return 2 if comm.size == 1 and (os.cpu_count() or 1) >= 2 and not in_worker() else 0


def _rates_in_order(tangents_at, positions, stop_above: float, threads: int) -> list[tuple[int, complex]]:
    """(position, fastest λ) for ``positions`` in order, up to the first λ with Re λ > ``stop_above``.

    Every eigenvalue call runs on one BLAS thread, so its value does not depend on ``threads``. With
    ``threads`` the calls run in a thread pool (LAPACK releases the GIL) while this thread
    linearises the next states: the same list as one after the other, the states after the first
    over the limit computed at most ``threads`` ahead and dropped.
    """
    rates = []
    with worker_threads():
        if not threads:
            for position in positions:
                rates.append((position, fastest_eigenvalue(*tangents_at(position))))
                if rates[-1][1].real > stop_above:
                    break
            return rates
        with ThreadPoolExecutor(threads) as pool:
            pending = deque()

            def take() -> bool:           # the oldest result; True once one is over the limit
                position, future = pending.popleft()
                rates.append((position, future.result()))
                return rates[-1][1].real > stop_above

            try:
                for position in positions:
                    pending.append((position, pool.submit(fastest_eigenvalue, *tangents_at(position))))
                    if len(pending) > threads and take():
                        return rates
                while pending:
                    if take():
                        return rates
                return rates
            finally:
                for _, future in pending:
                    future.cancel()


def prom_tail_stability(prom: ReducedModel, scene: Scene, fish: Fish, xi=None,
                        amplitude: float | None = None) -> Stability:
    """Does the thrust destabilise the tail at design ξ (amplitude A)? A screen for the PROM, whose
    basis has no tail-local modes and whose own Floquet test cannot see them (docs/studies.md, "What stops
    the A = 0.4 CO designs"):

        unstable ⇔ max_t max Re λ(t) > σ_max = ``[optimizer] tail_growth_limit`` [1/s]

    over the states of :func:`prom_tail_growth`; the first state over the limit decides. A PROM
    run that stops is unstable with its stop message as the reason.
    """
    if amplitude is not None:
        scene = scene.replace("actuation", amplitude=amplitude)
    settings = scene.optimizer
    growth = prom_tail_growth(prom, scene, fish, xi, stop_above=settings.tail_growth_limit)
    if isinstance(growth, str):
        return Stability(False, f"unstable: the PROM stops ({growth})")
    tail = "tail node" if scene.fluid.stations == "nodes" else "tail station"
    where = (f"the tail region's fastest mode (free nodes within {settings.tail_region_radius:g} m of the {tail}, "
             f"linearised at the PROM's states) grows at {growth.growth_rate:.3g} 1/s ({growth.frequency:.3g} Hz) "
             f"at t = {growth.time:.3g} s")
    if growth.growth_rate > settings.tail_growth_limit:
        return Stability(False, f"unstable: {where}, above the limit {settings.tail_growth_limit:g} 1/s")
    return Stability(True, f"stable: {where}, within the limit {settings.tail_growth_limit:g} 1/s "
                           f"({growth.states} PROM states linearised)")
