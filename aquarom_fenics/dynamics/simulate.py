"""Run the FOM over the scene's horizon and write its outputs (trajectory, summary, plot, XDMF)."""
from __future__ import annotations

import logging
import signal
import threading
import time as clock
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.dynamics.diagnostics import newton_failure_hints, scene_warnings
from aquarom_fenics.errors import InputError, Terminated
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.fem.strains import StrainProbe, StrainReport, report_strains
from aquarom_fenics.dynamics.integrator import IntegrationStopped, NewtonSettings, StepReport, integrate
from aquarom_fenics.io.tables import TrajectoryCSV
from aquarom_fenics.io.stop_signals import stop_between_steps, stop_for
from aquarom_fenics.io.run_outputs import write_run_outputs
from aquarom_fenics.io.xdmf import cell_regions
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.parallel import in_worker
from aquarom_fenics.dynamics.trajectory import DISTANCE_WINDOW, OBSERVED, Trajectory, swimming_distance, tail_amplitude

log = logging.getLogger("aquarom")


@dataclass
class SimulationResult:
    """What one simulation produced; ``error`` says why it stopped early, if it did."""

    trajectory: Trajectory
    distance: float | None
    tail_amplitude: float | None
    completed: bool
    wall_time: float
    n_cells: int
    n_dofs: int
    error: str | None = None
    cut_steps: int = 0                            # sub-steps shorter than h taken by the step control
    factorizations: int = 0                       # of Newton matrices, over the run
    timings: dict = field(default_factory=dict)
    states: list = field(default_factory=list)    # owned (u, u̇, ü) per stored sample, when asked for
    model: FullOrderModel | None = None
    strain: StrainReport | None = None            # the largest principal strain over the run (fem/strains.py)

    def summary(self) -> dict:
        iterations = np.asarray(self.trajectory.newton_iterations[1:])
        return {"strain": self.strain.as_dict() if self.strain is not None else None, "distance": self.distance, "tail_amplitude": self.tail_amplitude, "completed": self.completed,
                "error": self.error, "stop_reason": self.error or "completed", "wall_time": self.wall_time,
                "cells": self.n_cells, "dofs": self.n_dofs, "steps": len(self.trajectory) - 1,
                "cut_steps": self.cut_steps,
                "mean_newton_iterations": float(iterations.mean()) if iterations.size else None,
                "newton_factorizations": self.factorizations, "timings": self.timings}


def check_time_grid(scene: Scene) -> int:
    """Number of steps; the horizon must be a whole number of steps and cover the 0.1 s window."""
    solver = scene.solver
    steps = solver.duration / solver.time_step
    if abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
        raise InputError(f"scene {scene.source}: [solver] duration = {solver.duration} is not a whole number "
                         f"of time steps h = {solver.time_step}")
    if solver.duration < DISTANCE_WINDOW - 1e-12:
        raise InputError(f"scene {scene.source}: [solver] duration = {solver.duration} s is shorter than the "
                         f"{DISTANCE_WINDOW} s averaging window of the swimming distance")
    return int(round(steps))


def simulate_fom(scene: Scene, xi=None, fish: Fish | None = None, moved_mesh: bool = False,
                 out_dir: Path | None = None, comm: MPI.Comm = MPI.COMM_WORLD, progress: bool = True,
                 initial_velocity: np.ndarray | None = None, keep_states: bool = False,
                 keep_model: bool = False) -> SimulationResult:
    """Integrate the FOM of design ξ over [0, T]; outputs go to ``out_dir`` (rank 0 writes).

    The result holds the model (``result.model``) with ``keep_states`` or ``keep_model``; otherwise
    its PETSc objects are freed at the end of the run.

    A solver failure is reported in the result (``completed`` False, ``error`` the message) after
    the converged steps have been written; :class:`InputError` propagates.
    """
    n_steps = check_time_grid(scene)
    started = clock.perf_counter()
    fish = fish or load_fish(scene, comm)
    for warning in scene_warnings(scene, fish):
        log.warning("scene %s: %s", scene.source, warning)
    model = FullOrderModel(scene, fish, xi, moved_mesh=moved_mesh, comm=comm)
    probe = StrainProbe.of_model(model, n_steps)
    setup_time = clock.perf_counter() - started
    log.info("FOM: %d cells, %d dofs, %d steps of %g s (set-up %.2f s)", model.n_cells, model.n_global_dofs,
             n_steps, scene.solver.time_step, setup_time)
    is_writer = comm.rank == 0 and out_dir is not None
    csv = TrajectoryCSV(Path(out_dir) / "trajectory.csv") if is_writer else None
    trajectory = Trajectory()
    states = []
    displacements = [] if out_dir is not None else None
    cut_steps = factorizations = 0

    def record(report: StepReport, u, v, a):
        nonlocal cut_steps, factorizations
        cut_steps = report.cut_steps
        factorizations += report.factorizations
        values, rates = model.observables(u), model.observables(v)    # both linear in their argument
        observed = [values[name] for name in OBSERVED]
        trajectory.append(report.time, *observed, report.iterations, rates=[rates[name] for name in OBSERVED])
        probe.observe(report.step, report.time, u)
        if csv:
            csv.write(report.time, *observed, report.iterations)
        if keep_states:
            states.append((u.copy(), v.copy(), a.copy()))
        if displacements is not None:
            displacements.append(model.nodal_displacement(u)[:fish.nodes.n_vertices])
        if bar:
            bar.update(1)
        agreed_stop[:] = [_asked_to_stop(stop_requested, comm)]
        if agreed_stop[0]:     # Ctrl-C or SIGTERM on any rank: end after this complete sample
            raise KeyboardInterrupt

    bar = _progress_bar(n_steps, "FOM", progress and comm.rank == 0)
    stop_requested = lambda: None     # noqa: E731  (no stop asked until the time loop listens)
    agreed_stop = [None]              # the signal every rank agreed to stop by
    velocity = np.zeros(model.n_owned_dofs) if initial_velocity is None else model.owned_from_nodal(initial_velocity)
    zero = np.zeros(model.n_owned_dofs)
    record(StepReport(0, 0.0, 0, 0), zero, velocity, zero)
    settings = NewtonSettings.from_solver(scene.solver).secant_settings()
    error = interruption = None
    try:
        with stop_between_steps() as stop_requested:
            integrate(model, model.scheme, n_steps, (zero, velocity, zero), settings, record,
                      explain=lambda: "; ".join(newton_failure_hints(scene, model)))
    except IntegrationStopped as failure:
        error, cut_steps = str(failure), failure.cut_steps
    except KeyboardInterrupt as stop:
        number = agreed_stop[0] or stop_requested() or (signal.SIGTERM if isinstance(stop, Terminated)
                                                        else signal.SIGINT)
        interruption = stop_for(number, f"at t = {trajectory.time[-1]:g} s")
        error = str(interruption)
    finally:
        if bar:
            bar.close()
        if csv:
            csv.close()
    arrays = trajectory.arrays()
    completed = error is None
    result = SimulationResult(
        trajectory=trajectory,
        distance=swimming_distance(arrays["time"], arrays["com_x"]) if completed else None,
        tail_amplitude=tail_amplitude(arrays["time"], arrays["tail_y"]) if completed else None,
        completed=completed, wall_time=clock.perf_counter() - started, n_cells=model.n_cells,
        n_dofs=model.n_global_dofs, error=error, cut_steps=cut_steps, factorizations=factorizations,
        timings={"setup": setup_time, "time_integration": clock.perf_counter() - started - setup_time,
                 "newton": model.profile.as_dict()},
        states=states, model=model, strain=probe.report if probe.report.times else None)
    if result.strain is not None and comm.rank == 0:
        report_strains(result.strain, warn=completed)
    if is_writer:
        vertices = fish.nodes.n_vertices
        write_run_outputs(Path(out_dir), scene, result, "fom", dict(zip(fish.shape_names, fish.parameter_vector(xi))),
                          model.rest_points[:vertices], fish.mesh.cells, displacements, comm, trajectory_written=True,
                          regions=cell_regions(fish.tags, fish.mesh.cells.shape[0]))
    if not (keep_states or keep_model):
        model.destroy()
        result.model = None
    if interruption:
        raise interruption
    return result


def _asked_to_stop(stop_requested, comm) -> int | None:
    """The signal (SIGTERM over SIGINT) any rank was asked to stop by, so that every rank ends
    after the same step (a signal may reach the ranks of an MPI run one step apart)."""
    number = stop_requested() or 0
    if comm.size > 1:
        number = comm.allreduce(number, op=MPI.MAX)
    return number or None


PROGRESS_BARS = {"shown": True}
"""Whether FOM runs of this process may show a progress bar (on a terminal): ``--no-progress`` of
every command sets it to False for the command's run (:func:`progress_bars`)."""


@contextmanager
def progress_bars(shown: bool):
    """FOM progress bars shown (on a terminal) or not while the block runs."""
    before = PROGRESS_BARS["shown"]
    PROGRESS_BARS["shown"] = shown
    try:
        yield
    finally:
        PROGRESS_BARS["shown"] = before


WORKER_BAR_LOCK = threading.RLock()
"""The lock of progress bars drawn in a worker process. tqdm's default also makes a multiprocessing
lock (a named semaphore), which in a spawned worker coordinates with no other process and, when
the worker is ended with SIGTERM (Ctrl-C of the command), is reported as leaked at exit."""


def _progress_bar(total: int, label: str, enabled: bool, unit: str = "step"):
    """A progress bar of ``total`` ``unit``s on a terminal (None when not ``enabled`` or bars are off)."""
    if not (enabled and PROGRESS_BARS["shown"]):
        return None
    from tqdm import tqdm

    if in_worker():
        tqdm.set_lock(WORKER_BAR_LOCK)
    return tqdm(total=total, desc=label, unit=unit, leave=False, disable=None)


progress_bar = _progress_bar

