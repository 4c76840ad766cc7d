"""Cases of `make validate` (scripts/validate.py): cached FOM, ROM/PROM and MPI runs.

A case is a scene plus the model settings that are not in the scene (model kind, ξ, ROM or
PROM, sensitivities, energy balance, MPI ranks). Its key is a hash of the scene hash, those
settings and the toolkit version; its record is one JSON file ``<kind>-<key>.json`` in the cases
folder, written atomically when the case has an answer (completed, or stopped by the solver with
its message). A case that hits the time limit or raises is reported but not cached, so that a
rerun tries it again; a rerun with everything cached only reads files.

Every record says ``status``: ``completed``, ``stopped`` (a clean solver stop: the message names
the time), ``non-finite`` (completed with NaN/inf numbers: a bug, never expected), ``time-limit``
or ``crashed`` (exception type and message).
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import platform
import resource
import signal
import subprocess
import sys
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
if str(REPOSITORY) not in sys.path:
    sys.path.insert(0, str(REPOSITORY))

from aquarom_fenics import __version__  # noqa: E402
from aquarom_fenics.io.outputs import write_json_atomic  # noqa: E402
from aquarom_fenics.io.scene import Scene  # noqa: E402

CASE_FORMAT = 1
"""Version of the case records; part of every key (bump it when a record's content changes)."""

CACHED_STATUSES = ("completed", "stopped", "non-finite")

SOLVE_REPEATS = 3
"""Reduced solves are repeated and the shortest time kept (they last ~0.1 s: one slow run in a
busy machine would bend the cost-against-cells fit)."""
"""Outcomes that are answers of the model and therefore cached; time limits and crashes are not."""


# ---------------------------------------------------------------------------------------------
# Case descriptors


@dataclass
class Case:
    """One run: ``kind`` is ``fom``, ``reduced`` or ``mpi``; ``options`` holds plain JSON values."""

    kind: str
    label: str
    scene: Scene
    options: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        payload = {"kind": self.kind, "scene_hash": self.scene.hash, "options": self.options,
                   "version": __version__, "format": CASE_FORMAT}
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]

    @property
    def file_name(self) -> str:
        return f"{self.kind}-{self.key}.json"


def fom_case(label: str, scene: Scene, xi=None, energy: bool = True) -> Case:
    """The FOM (serial, in this process); ``energy`` keeps the states and computes the energy balance
    after the run (outside its timing; a few per cent of its cost)."""
    return Case("fom", label, scene, {"xi": _plain_xi(xi), "energy": bool(energy)})


def reduced_case(label: str, scene: Scene, parametric: bool, xi=None, sensitivities: bool = False) -> Case:
    """A ROM (``parametric`` False) or the scene's PROM built at ξ_c = 0, run at ξ."""
    return Case("reduced", label, scene, {"parametric": bool(parametric), "xi": _plain_xi(xi),
                                          "sensitivities": bool(sensitivities)})


def mesh_case(label: str, scene: Scene) -> Case:
    """The nominal fish's FOM run, first frequency and static peak-muscle deflection (mesh convergence)."""
    return Case("mesh", label, scene, {})


def mpi_case(label: str, scene: Scene, ranks: int) -> Case:
    """The FOM through ``mpirun -n ranks aquarom simulate`` in a subprocess."""
    return Case("mpi", label, scene, {"ranks": int(ranks)})


def _plain_xi(xi):
    return None if xi is None else [float(value) for value in xi]


# ---------------------------------------------------------------------------------------------
# Running with cache, progress and time limit


class CaseTimeLimit(Exception):
    """Raised by the alarm when a case runs past its time limit."""


class CasesCollected(Exception):
    """Raised by a collecting Runner: the study's case list is known, nothing was run."""


class Runner:
    """Runs cases once: cached records are read, missing ones computed and written.

    ``collect`` True: ``run`` only records the cases it is given and raises CasesCollected (the
    study functions call ``run`` once each), so that a driver can list every case of a set of
    studies and compute them in parallel first (see ``compute_in_parallel``).
    """

    def __init__(self, out: Path, time_limit: float = 1800.0, recompute_failed: bool = False, stream=None,
                 collect: bool = False, concurrent_jobs: int = 1):
        self.out = Path(out)
        self.cases_dir = self.out / "cases"
        self.time_limit = float(time_limit)
        self.recompute_failed = recompute_failed
        self.stream = stream or sys.stdout
        self.collect = collect
        self.collected: list[Case] = []
        self.concurrent_jobs = concurrent_jobs
        self.outcomes: dict[str, str] = {}      # key → "cached" | "computed" | "not cached (…)", once per case
        self.this_run: dict[str, dict] = {}      # records computed in this run (also the uncached ones)
        self.computed_elsewhere: set[str] = set()
        self.compute_time = 0.0
        self._fish = {}
        self._warm = set()
        logging.getLogger("aquarom").setLevel(logging.ERROR)   # dropped vectors etc. are in the records

    @property
    def counts(self) -> dict:
        counts = {"cached": 0, "computed": 0, "not cached (time limit or crash)": 0}
        for outcome in self.outcomes.values():
            counts[outcome] += 1
        return counts

    # ----------------------------------------------------------------- public
    def run(self, study: str, cases: list[Case]) -> list[dict]:
        """Records of ``cases`` in order, computing those missing; one progress line per case."""
        if self.collect:
            self.collected += cases
            raise CasesCollected(study)
        records = []
        width = len(str(len(cases)))
        for number, case in enumerate(cases, start=1):
            prefix = f"[{study} {number:>{width}}/{len(cases)}] {case.label}"
            record = self.this_run.get(case.key) or self.cached(case)
            if record is not None:
                if case.key not in self.outcomes:
                    self.outcomes[case.key] = "computed" if case.key in self.computed_elsewhere else "cached"
                done = "computed in parallel" if case.key in self.computed_elsewhere else (
                    "done" if case.key in self.this_run else "cached")
                self._say(f"{prefix}: {done} — {describe(record)}")
                records.append(record)
                continue
            self._say(f"{prefix}: computing …", end="")
            record, elapsed = self.compute_and_store(case)
            self._say(f" {elapsed:.1f} s — {describe(record)}")
            records.append(record)
        return records

    def cached(self, case: Case) -> dict | None:
        record = read_record(self.cases_dir / case.file_name)
        if record is not None and self.recompute_failed and record["status"] != "completed" \
                and case.key not in self.computed_elsewhere:
            return None
        return record

    def compute_and_store(self, case: Case) -> tuple[dict, float]:
        """Compute a case, write its record when it is an answer of the model; (record, seconds)."""
        started = time.perf_counter()
        record = self.compute(case)
        elapsed = time.perf_counter() - started
        self.compute_time += elapsed
        record["compute_time"] = elapsed
        record["concurrent_jobs"] = self.concurrent_jobs
        if record["status"] in CACHED_STATUSES:
            write_json_atomic(self.cases_dir / case.file_name, record)
            self.outcomes[case.key] = "computed"
        else:
            self.outcomes[case.key] = "not cached (time limit or crash)"
        self.this_run[case.key] = record
        return record, elapsed

    def compute(self, case: Case) -> dict:
        """The record of one case (never raises for the model's own failures)."""
        record = {"kind": case.kind, "key": case.key, "label": case.label, "scene_hash": case.scene.hash,
                  "scene": case.scene.to_dict(), "options": case.options, "version": __version__,
                  "computed_at": time.strftime("%Y-%m-%d %H:%M:%S")}
        try:
            if case.kind == "mpi":
                record.update(compute_mpi(self, case))
            else:
                compute = {"fom": compute_fom, "reduced": compute_reduced, "mesh": compute_mesh}[case.kind]
                record.update(with_time_limit(self.time_limit, lambda: compute(self, case)))
        except CaseTimeLimit:
            record.update(status="time-limit", message=f"stopped by the validation's time limit of "
                                                          f"{self.time_limit:g} s per case (not cached; rerun to retry)")
        except Exception as error:  # noqa: BLE001 — a crash of one case must not end the study
            record.update(status="crashed", message=f"{type(error).__name__}: {error}",
                          traceback=traceback.format_exc(limit=6))
        record["peak_rss_mb_process"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        return record

    def fish(self, scene: Scene):
        """load_fish, shared by cases with the same mesh, regions and shape set."""
        from aquarom_fenics.geometry.fish import load_fish

        key = json.dumps([scene.to_dict()["mesh"], scene.to_dict()["regions"], scene.shape_names], sort_keys=True)
        if key not in self._fish:
            self._fish[key] = load_fish(scene)
        return self._fish[key]

    def warm_up(self, scene: Scene, parametric: bool | None) -> None:
        """Compile (or load from the JIT cache) the forms of a model kind and run it briefly on level 1.

        Keeps form compilation and first-call costs out of the first timed case, which would bend
        the cost fits.
        ``parametric`` None: the FOM's forms.
        """
        order = scene.reduction.taylor_order if parametric and scene.shapes else 0
        key = ("fom",) if parametric is None else ("reduced", order)
        if key in self._warm:
            return
        self._warm.add(key)
        coarse = scene.replace("mesh", level=1) if not scene.mesh.file else scene
        coarse = coarse.replace("solver", duration=0.1, time_step=0.02)
        if parametric is None:
            from aquarom_fenics.dynamics.simulate import simulate_fom

            simulate_fom(coarse, fish=self.fish(coarse), progress=False)
        else:
            from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
            from aquarom_fenics.reduction.reductor import build_prom

            simulate_reduced(build_prom(coarse, fish=self.fish(coarse), parametric=parametric), coarse,
                             sensitivities=True)

    def _say(self, text: str, end: str = "\n") -> None:
        print(text, end=end, file=self.stream, flush=True)


# ---------------------------------------------------------------------------------------------
# Parallel computation of the missing cases (--jobs N)

LEVEL_CELLS = {1: 1232, 2: 4176, 3: 7944, 4: 15392, 5: 25312}

_WORKER: Runner | None = None


def estimated_cost(case: Case) -> float:
    """A rough run time [s], to start the longest cases first."""
    cells = LEVEL_CELLS.get(case.scene.mesh.level, 8000)
    steps = case.scene.n_steps
    if case.kind in ("fom", "mpi", "mesh"):
        quadratic = 8.0 if case.scene.mesh.degree == 2 else 1.0   # measured: level 1, 16 s against 1.9 s
        return quadratic * 7e-4 * cells ** 1.1 * steps / 100.0
    p = len(case.scene.shapes) if case.options.get("parametric") else 0
    order = case.scene.reduction.taylor_order if p else 0
    return 1e-4 * cells * (1 + p) * (4 if order == 2 else 1) + 0.05 * steps / 100.0


def _start_worker(out, time_limit, recompute_failed, jobs):
    global _WORKER
    _WORKER = Runner(out, time_limit, recompute_failed, stream=open(os.devnull, "w"), concurrent_jobs=jobs)


def _work(case: Case):
    return _WORKER.compute_and_store(case)


def compute_in_parallel(runner: Runner, cases: list[Case], jobs: int) -> int:
    """Compute the missing (non-MPI) cases in ``jobs`` worker processes, longest first.

    Workers are fresh interpreters (spawn), each with one BLAS thread; their records are written
    to the cache as usual, and the uncached outcomes (time limit, crash) are handed to ``runner``
    so that the studies do not retry them in the same run. Returns the number of cases computed.
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pending = {}
    for case in cases:
        if case.kind != "mpi" and case.key not in pending and runner.cached(case) is None:
            pending[case.key] = case
    if not pending:
        return 0
    order = sorted(pending.values(), key=estimated_cost, reverse=True)
    print(f"== computing {len(order)} missing cases with {jobs} parallel workers (longest first) ==",
          file=runner.stream, flush=True)
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"
    width = len(str(len(order)))
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=_start_worker,
                             initargs=(runner.out, runner.time_limit, runner.recompute_failed, jobs)) as pool:
        futures = {pool.submit(_work, case): case for case in order}
        for number, future in enumerate(as_completed(futures), start=1):
            case = futures[future]
            prefix = f"[parallel {number:>{width}}/{len(order)}] {case.label}"
            try:
                record, elapsed = future.result()
            except Exception as error:  # noqa: BLE001 — a dead worker: the studies compute the case again
                print(f"{prefix}: worker failed ({type(error).__name__}: {error}); computed again below",
                      file=runner.stream, flush=True)
                continue
            if record["status"] in CACHED_STATUSES:
                runner.computed_elsewhere.add(case.key)
            else:
                runner.this_run[case.key] = record
                runner.outcomes[case.key] = "not cached (time limit or crash)"
            print(f"{prefix}: {elapsed:.1f} s — {describe(record)}", file=runner.stream, flush=True)
    return len(order)


def with_time_limit(seconds: float, function):
    """``function()`` under a SIGALRM time limit (raises CaseTimeLimit); main thread only."""
    def on_alarm(signum, frame):
        raise CaseTimeLimit(f"time limit of {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        return function()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def read_record(path: Path) -> dict | None:
    try:
        record = json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    return record if record.get("status") in CACHED_STATUSES else None


def describe(record: dict) -> str:
    """One line: status and the main numbers of a record."""
    status = record.get("status")
    if status not in ("completed", "non-finite"):
        return f"{status}: {record.get('message')}"
    parts = [status]
    if record.get("distance") is not None:
        parts.append(f"d = {100 * record['distance']:.3f} cm")
    if record.get("tail_amplitude") is not None:
        parts.append(f"A = {100 * record['tail_amplitude']:.3f} cm")
    if record["kind"] == "reduced":
        parts.append(f"m = {record.get('size')}, build {record.get('build_time', 0):.2f} s, "
                     f"solve {record.get('solve_time', 0):.2f} s")
    else:
        parts.append(f"{record.get('wall_time', 0):.1f} s")
    if record["kind"] == "mesh":
        parts.append(f"f_1 = {record['first_frequency']:.3f} Hz, static tail y = "
                     f"{100 * record['static_tail_deflection']:.3f} cm")
    if record.get("energy"):
        parts.append(f"energy imbalance {100 * record['energy']['imbalance_relative']:+.2f}%")
    return ", ".join(parts)


# ---------------------------------------------------------------------------------------------
# Computations


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
        record["energy"] = energy_balance(result)
        if not result.cut_steps:
            from aquarom_fenics.verification.energy import energy_balance as per_force_balance

            record["energy"]["per_force"] = per_force_balance(result).summary()
        if not _finite(record["energy"]["imbalance_relative"]):
            record.update(status="non-finite", message="energy balance not finite")
    result.states.clear()
    return record


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


def energy_balance(result) -> dict:
    """Work of the external forces against dissipated and stored energy of a FOM run [J].

    W_ext = Σ_n ½ (f_n + f_{n+1})·(u_{n+1} - u_n) for f = actuation, thrust and drag (trapezoidal
    rule on the stored samples); D = Σ_n ½ h (u̇_n·C u̇_n + u̇_{n+1}·C u̇_{n+1}); stored = kinetic +
    elastic energy. Accelerations are recovered from the Newmark relations (ü_0 = 0). The
    imbalance W_ext - D - E(T) is relative to the energy throughput Σ_n (|ΔW_act| + |ΔW_thrust| +
    |ΔW_drag|). Serial runs only (owned dofs are all dofs).

    The trapezoidal D over-counts the dissipation by h/4 Δu̇·C Δu̇ per step; the midpoint form
    D_mid = Σ_n h ū·C ū, ū = ½(u̇_n + u̇_{n+1}), is the one of Newmark's own energy identity (with
    γ = ½, β = ¼ the balance then closes up to the trapezoidal error of the nonlinear forces), so
    both are recorded: a residual of D_mid measures the scheme's numerical dissipation.
    """
    model = result.model
    scheme = model.scheme
    h, gamma = scheme.time_step, scheme.gamma
    times = np.asarray(result.trajectory.time)
    states = result.states
    n = len(states)
    accelerations = [np.zeros_like(states[0][0])]
    for index in range(1, n):
        (_, v_old), (_, v_new) = states[index - 1], states[index]
        accelerations.append((v_new - v_old - h * (1.0 - gamma) * accelerations[-1]) / (h * gamma))
    forces = {"actuation": [], "thrust": [], "drag": []}
    damping_power, damping_midpoint, kinetic, elastic = [], [], [], []
    for index, (u, v) in enumerate(states):
        forces["actuation"].append(model.actuation_force(float(times[index]), u))
        forces["thrust"].append(model.thrust_force(u, v, accelerations[index]))
        forces["drag"].append(model.drag_force(v))
        damping_power.append(float(v @ model.matvec(model.damping_matrix, v)))
        if index:
            mean_velocity = 0.5 * (v + states[index - 1][1])
            damping_midpoint.append(float(mean_velocity @ model.matvec(model.damping_matrix, mean_velocity)))
        kinetic.append(model.kinetic_energy(v))
        elastic.append(model.elastic_energy(u))
    cumulative = {}
    for name, values in forces.items():
        increments = [0.5 * float((values[i] + values[i + 1]) @ (states[i + 1][0] - states[i][0]))
                      for i in range(n - 1)]
        cumulative[name] = np.concatenate([[0.0], np.cumsum(increments)])
    dissipated = np.concatenate([[0.0], np.cumsum([0.5 * h * (damping_power[i] + damping_power[i + 1])
                                                     for i in range(n - 1)])])
    midpoint_series = np.concatenate([[0.0], np.cumsum(h * np.asarray(damping_midpoint))])
    midpoint = float(midpoint_series[-1])
    work = cumulative["actuation"] + cumulative["thrust"] + cumulative["drag"]
    stored = np.asarray(kinetic) + np.asarray(elastic)
    # Normalised by the energy throughput Σ_n |ΔW_n| of every force: the final works alone can be
    # near zero (the muscles take back over a cycle what they gave).
    scale = sum(float(np.abs(np.diff(values)).sum()) for values in cumulative.values())
    imbalance = work[-1] - dissipated[-1] - stored[-1]
    imbalance_midpoint = work[-1] - midpoint - stored[-1]
    return {"work_actuation": float(cumulative["actuation"][-1]), "work_thrust": float(cumulative["thrust"][-1]),
            "work_drag": float(cumulative["drag"][-1]), "throughput": float(scale), "dissipated": float(dissipated[-1]),
            "kinetic": float(kinetic[-1]), "elastic": float(elastic[-1]), "imbalance": float(imbalance),
            "imbalance_relative": float(imbalance / scale) if scale > 0 else float("nan"),
            "dissipated_midpoint": midpoint, "imbalance_midpoint": float(imbalance_midpoint),
            "imbalance_midpoint_relative": float(imbalance_midpoint / scale) if scale > 0 else float("nan"),
            "includes": "actuation, thrust and drag work; Rayleigh damping dissipation",
            "series": {"time": times.tolist(), "work": work.tolist(), "dissipated": dissipated.tolist(),
                       "dissipated_midpoint": midpoint_series.tolist(), "stored": stored.tolist()}}


# ---------------------------------------------------------------------------------------------
# MPI runs through the command line


def scene_toml(scene: Scene) -> str:
    """A TOML file of the resolved scene (all sections), read back with the same hash."""
    data = scene.to_dict()
    lines = [f"name = {json.dumps(scene.name)}", f"description = {json.dumps(scene.description)}"]
    for section, values in data.items():
        if section in ("name", "description", "shapes", "constraints"):
            continue
        lines.append(f"\n[{section}]")
        for key, value in values.items():
            lines.append(f"{key} = {_toml_value(value)}")
    if scene.shapes:
        lines.append("\n[shapes]")
        for shape in scene.shapes:
            radius = "" if shape.radius is None else f", radius = {_toml_value(shape.radius)}"
            lines.append(f"{shape.name} = {{ bounds = [{_toml_value(shape.lower)}, {_toml_value(shape.upper)}], "
                         f"start = {_toml_value(shape.start)}{radius} }}")
    for constraint in scene.constraints:
        lines.append("\n[[constraints]]")
        lines.append("coefficients = { " + ", ".join(f"{name} = {_toml_value(value)}"
                                                      for name, value in constraint.coefficients) + " }")
        for bound in ("lower", "upper"):
            value = getattr(constraint, bound)
            if math.isfinite(value):
                lines.append(f"{bound} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    raise TypeError(f"no TOML for {value!r}")


def compute_mpi(runner: Runner, case: Case) -> dict:
    """``mpirun -n R aquarom simulate`` on the case's scene; the summary and trajectory it writes."""
    from aquarom_fenics.io.outputs import read_trajectory_csv

    ranks = case.options["ranks"]
    work = runner.out / "mpi-runs" / f"{case.key}"
    work.mkdir(parents=True, exist_ok=True)
    scene_file = work / "scene.toml"
    scene_file.write_text(scene_toml(case.scene))
    out = work / "out"
    command = ["mpirun", "-n", str(ranks), str(Path(sys.executable).with_name("aquarom")), "simulate",
               str(scene_file), "--out", str(out), "--no-progress"]
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


# ---------------------------------------------------------------------------------------------
# Fits and machine facts


def power_law_fit(sizes, times) -> dict | None:
    """Least squares of log t = log c + e log n: exponent e and prefactor c (None below 2 points)."""
    sizes, times = np.asarray(sizes, dtype=float), np.asarray(times, dtype=float)
    keep = np.isfinite(sizes) & np.isfinite(times) & (sizes > 0) & (times > 0)
    if np.unique(sizes[keep]).size < 2:
        return None
    exponent, intercept = np.polyfit(np.log(sizes[keep]), np.log(times[keep]), 1)
    return {"exponent": float(exponent), "prefactor": float(np.exp(intercept)), "points": int(keep.sum())}


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError):
        memory = None
    return {"cores": os.cpu_count(), "cpu": cpu, "platform": platform.platform(),
            "memory_gib": memory, "hostname": platform.node()}
