"""The computation of one validation case: FOM, reduced model, mesh measures, FOM under mpirun.

Each function returns the fields of the case's record (status, message, numbers, trajectory);
the model's own failures become a status, never an exception.
"""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from aquarom_fenics.verification.validation.cases import Case


class Runner(Protocol):
    """What a computation asks of the runner that calls it (``runner.Runner``): the fish of a scene
    (cached), the warm-up before a timed run, the output folder and the time limit [s]."""

    out: Path
    time_limit: float

    def fish(self, scene): ...

    def warm_up(self, scene, parametric) -> None: ...

SOLVE_REPEATS = 3
"""Reduced solves are repeated and the shortest time kept (they last ~0.1 s: one slow run in a
busy machine would bend the cost-against-cells fit)."""


def _finite(*values) -> bool:
    return all(value is None or math.isfinite(value) for value in values)


def _newton_stats(iterations) -> dict:
    iterations = np.asarray(iterations[1:], dtype=float)
    if not iterations.size:
        return {"mean": None, "max": None, "total": 0}
    return {"mean": float(iterations.mean()), "max": int(iterations.max()), "total": int(iterations.sum())}


def _trajectory(arrays: dict) -> dict:
    return {name: np.asarray(arrays[name]).tolist() for name in ("time", "head_x", "tail_y", "com_x")}


def _outcome(completed: bool, error: str | None, *numbers) -> tuple[str, str | None]:
    if not completed:
        return "stopped", error
    if not _finite(*numbers):
        return "non-finite", "completed with non-finite results"
    return "completed", None


def compute_fom(runner: Runner, case: Case) -> dict:
    from aquarom_fenics.dynamics.simulate import simulate_fom

    scene, options = case.scene, case.options
    fish = runner.fish(scene)
    runner.warm_up(scene, None)
    energy = options.get("energy", False)
    result = simulate_fom(scene, options.get("xi"), fish=fish, progress=False, keep_states=energy)
    arrays = result.trajectory.arrays()
    status, message = _outcome(result.completed, result.error, result.distance, result.tail_amplitude,
                               *arrays["head_x"])
    record = {"status": status, "message": message, "completed": result.completed,
              "distance": result.distance, "tail_amplitude": result.tail_amplitude,
              "head_x_final": float(arrays["head_x"][-1]), "stopped_at": float(arrays["time"][-1]),
              "wall_time": result.wall_time, "setup_time": result.timings.get("setup"),
              "solve_time": result.timings.get("time_integration"), "cells": result.n_cells,
              "dofs": result.n_dofs, "newton": _newton_stats(arrays["newton_iterations"]),
              "cut_steps": result.cut_steps, "trajectory": _trajectory(arrays)}
    if energy:
        record["energy"] = energy_record(result)
        if not _finite(record["energy"].get("relative_imbalance")):
            record.update(status="non-finite", message="energy balance not finite")
    result.states.clear()
    if record["status"] == "completed":       # the same answer as the studies' FOM at this design: shared with them
        from aquarom_fenics.studies.fom_cache import offer_answer

        offer_answer(scene, dict(zip(scene.shape_names, map(float, fish.parameter_vector(options.get("xi"))))), result)
    return record


def energy_record(result) -> dict:
    """The per-force energy balance of a FOM run (:mod:`aquarom_fenics.verification.energy`) [J]: final
    values, the throughput, the relative imbalance (the Newton residual of the steps) and the
    numerical dissipation relative to the throughput, with the cumulative series for the figure.

    A run with cut steps has no balance on the grid of h: ``available`` False and the reason.
    """
    from aquarom_fenics.verification.energy import energy_balance

    if result.cut_steps:
        return {"available": False,
                "message": f"not available: the run cut {result.cut_steps} steps (the balance needs uniform steps of h)"}
    balance = energy_balance(result)
    summary = balance.summary()
    throughput = summary["throughput"]
    work = sum(balance.works.values())
    stored = balance.kinetic_change + balance.strain_change
    return summary | {
        "available": True,
        "work_thrust": summary["work_thrust_acceleration"] + summary["work_thrust_velocity"],
        "numerical_dissipation_relative": summary["dissipated_numerical"] / throughput if throughput > 0 else None,
        "series": {"time": balance.time.tolist(), "work": work.tolist(),
                   "dissipated_rayleigh": balance.dissipated_rayleigh.tolist(),
                   "dissipated_numerical": balance.dissipated_numerical.tolist(), "stored": stored.tolist()}}


def compute_mesh(runner: Runner, case: Case) -> dict:
    from aquarom_fenics.verification.convergence import measure

    runner.warm_up(case.scene, None)
    measured = asdict(measure(case.scene, runner.fish(case.scene)))
    status, message = _outcome(True, None, *(value for value in measured.values()))
    return {"status": status, "message": message} | measured


def compute_reduced(runner: Runner, case: Case) -> dict:
    from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
    from aquarom_fenics.reduction.reductor import build_prom

    scene, options = case.scene, case.options
    parametric = options["parametric"]
    fish = runner.fish(scene)
    runner.warm_up(scene, parametric)
    started = time.perf_counter()
    prom = build_prom(scene, fish=fish, parametric=parametric)
    build_time = time.perf_counter() - started
    timings = prom.timings
    tensors = timings.get("internal_force_tensors", 0.0) + timings.get("other_tensors", 0.0)
    finite_tensors = all(np.all(np.isfinite(array)) for array in prom.term_arrays().values())
    xi = options.get("xi")
    result = simulate_reduced(prom, scene, xi)
    solve_times = [result.wall_time] + [simulate_reduced(prom, scene, xi).wall_time for _ in range(SOLVE_REPEATS - 1)]
    arrays = result.trajectory.arrays()
    status, message = _outcome(result.completed, result.error, result.distance, result.tail_amplitude,
                               *arrays["head_x"])
    if not finite_tensors:
        status, message = "non-finite", "reduced tensors contain non-finite values"
    record = {"status": status, "message": message, "completed": result.completed,
              "model": "prom" if parametric and prom.n_parameters else "rom", "parameters": prom.n_parameters,
              "parameter_names": list(prom.shape_names), "size": prom.size, "labels": list(prom.labels),
              "dropped": list(prom.dropped), "frequencies": np.asarray(prom.frequencies).tolist(),
              "cells": prom.cells, "dofs": prom.dofs, "finite_tensors": bool(finite_tensors),
              "build_time": build_time, "build_basis": timings.get("basis_total", 0.0), "build_tensors": tensors,
              "build_rest": max(build_time - timings.get("basis_total", 0.0) - tensors, 0.0),
              "build_timings": dict(timings), "solve_time": min(solve_times), "solve_times": solve_times,
              "distance": result.distance, "tail_amplitude": result.tail_amplitude,
              "head_x_final": float(arrays["head_x"][-1]), "stopped_at": float(arrays["time"][-1]),
              "newton": _newton_stats(arrays["newton_iterations"]), "cut_steps": result.cut_steps,
              "trajectory": _trajectory(arrays)}
    if options.get("sensitivities") and prom.n_parameters:
        sensitive = simulate_reduced(prom, scene, xi, sensitivities=True)
        times = [sensitive.wall_time] + [simulate_reduced(prom, scene, xi, sensitivities=True).wall_time
                                         for _ in range(SOLVE_REPEATS - 1)]
        record["solve_time_sensitivities"] = min(times)
        if sensitive.completed and sensitive.sensitivities is not None:
            head = np.einsum("m,smk->sk", prom.observation.head_x_row, sensitive.sensitivities)
            record["head_x_sensitivity"] = head.tolist()
            record["distance_gradient"] = np.asarray(sensitive.distance_gradient).tolist()
            if not np.all(np.isfinite(head)):
                record.update(status="non-finite", message="sensitivities not finite")
    return record


def compute_mpi(runner: Runner, case: Case) -> dict:
    """``mpirun -n R aquarom simulate`` on the case's scene; the summary and trajectory it writes."""
    from aquarom_fenics.io.readback import read_trajectory_csv
    from aquarom_fenics.io.persistence import write_text_atomic

    ranks = case.options["ranks"]
    work = runner.out / "mpi-runs" / f"{case.key}"
    work.mkdir(parents=True, exist_ok=True)
    scene_file = work / "scene.toml"
    write_text_atomic(scene_file, case.scene.to_toml())
    out = work / "out"
    # --force: ``out`` is this case's own folder, left by an earlier attempt (a crash or the time limit)
    command = ["mpirun", "-n", str(ranks), str(Path(sys.executable).with_name("aquarom")), "simulate",
               str(scene_file), "--out", str(out), "--no-progress", "--force"]
    environment = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
                       OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=environment, start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=runner.time_limit)
    except subprocess.TimeoutExpired:
        _stop_process_group(process)
        return {"status": "time-limit", "ranks": ranks, "command": " ".join(command),
                "message": f"mpirun stopped by the validation's time limit of {runner.time_limit:g} s"}
    elapsed = time.perf_counter() - started
    summary_path = out / "summary.json"
    tail = [line for line in (stderr or "").strip().splitlines() if line.strip()][-3:]
    if process.returncode not in (0, 3) or not summary_path.exists():
        return {"status": "crashed", "ranks": ranks, "command": " ".join(command), "returncode": process.returncode,
                "message": f"mpirun exit code {process.returncode}: {' | '.join(tail) or 'no message'}"}
    summary = json.loads(summary_path.read_text())
    arrays = read_trajectory_csv(out / "trajectory.csv")
    status, message = _outcome(summary["completed"], summary.get("error"), summary.get("distance"),
                               summary.get("tail_amplitude"))
    if summary.get("scene_hash") != case.scene.hash:
        status, message = "crashed", (f"the scene file written for mpirun has hash {summary.get('scene_hash')}, "
                                      f"expected {case.scene.hash}")
    return {"status": status, "message": message, "ranks": ranks, "mpi_ranks_reported": summary.get("mpi_ranks"),
            "command": " ".join(command), "completed": summary["completed"], "distance": summary.get("distance"),
            "tail_amplitude": summary.get("tail_amplitude"), "wall_time": summary["wall_time"],
            "process_time": elapsed, "setup_time": summary["timings"].get("setup"),
            "solve_time": summary["timings"].get("time_integration"), "cells": summary["cells"],
            "dofs": summary["dofs"], "mean_newton_iterations": summary.get("mean_newton_iterations"),
            "peak_memory_mb_rank0": summary.get("peak_memory_mb"), "stopped_at": float(np.atleast_1d(arrays["time"])[-1]),
            "newton": _newton_stats(np.atleast_1d(arrays["newton_iterations"])),
            "trajectory": _trajectory({name: np.atleast_1d(values) for name, values in arrays.items()})}


def _stop_process_group(process: subprocess.Popen) -> None:
    """SIGTERM, then SIGKILL, to the process group this module started for mpirun."""
    for sent in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(process.pid, sent)
        except ProcessLookupError:
            return
        try:
            process.wait(timeout=10)
            return
        except subprocess.TimeoutExpired:
            continue
