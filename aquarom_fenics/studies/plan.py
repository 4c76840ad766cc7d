"""`--dry-run`: what a command would build or reuse, what it skips, and how long it should take.

Time estimates come from the benchmark JSON files under results/bench/ when they exist (fitted
power laws in the number of cells), otherwise from the reference figures measured on 2 cores.
"""
from __future__ import annotations

import json
import math

import numpy as np

from aquarom_fenics.errors import InputError

from aquarom_fenics.geometry.block import LEVEL_TARGET_CELLS, block_cache_path
from aquarom_fenics.geometry.fish import planned_body
from aquarom_fenics.io.paths import bench_results
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.optimization.prom_builder import screens_tail, stability_plan
from aquarom_fenics.verification.local_stability import tail_sample_steps
from aquarom_fenics.reduction.basis import candidate_labels, response_labels

# Reference costs at 7944 cells (level 3, 2 cores): FOM 2 s simulation, PROM build with p
# parameters ≈ 0.5 + 0.33 p s, reduced solve ≈ 0.1 s (0.2 s with sensitivities).
REFERENCE_CELLS = 7944
REFERENCE_FOM_SECONDS = 10.3
REFERENCE_FOM_EXPONENT = 1.1
QUADRATIC_COST_FACTOR = {1: 1.0, 2: 8.6}
"""Cost of a quadratic mesh against the linear one on the same cells (level 1 FOM: 16.4 s against 1.9 s)."""
TAIL_SCREEN_SECONDS_PER_STATE = 0.33
"""Tail screen per linearised state at the default mesh (degree 2, level 2: 16.5 s for 51 states)."""


def power_law_fit(sizes, times) -> dict | None:
    """Least squares of log t = log c + e log n over the positive, finite pairs: exponent e, prefactor c
    and the number of points (None below two distinct sizes)."""
    sizes, times = np.asarray(sizes, dtype=float), np.asarray(times, dtype=float)
    keep = np.isfinite(sizes) & np.isfinite(times) & (sizes > 0) & (times > 0)
    if np.unique(sizes[keep]).size < 2:
        return None
    exponent, intercept = np.polyfit(np.log(sizes[keep]), np.log(times[keep]), 1)
    return {"exponent": float(exponent), "prefactor": float(np.exp(intercept)), "points": int(keep.sum())}


def tail_screen_seconds(scene: Scene) -> float:
    """Estimated time of one tail screen [s] (0 when the optimisers skip it): the states of the last
    stroke at the default mesh's cost per state, whatever the mesh."""
    return tail_sample_steps(scene).size * TAIL_SCREEN_SECONDS_PER_STATE if screens_tail(scene) else 0.0


def fom_seconds(cells: int, steps: int, degree: int = 1) -> float:
    """Estimated FOM wall time [s] for ``steps`` Newmark steps."""
    runs = _bench_runs("fom.json", lambda r: r.get("ranks") == 1 and "failed" not in r
                       and r.get("degree", 1) == degree)
    fit = power_law_fit([r["cells"] for r in runs], [r["time_integration"] for r in runs])
    if fit:
        return fit["prefactor"] * cells ** fit["exponent"] * steps / 100
    return (QUADRATIC_COST_FACTOR[degree] * REFERENCE_FOM_SECONDS * (cells / REFERENCE_CELLS) ** REFERENCE_FOM_EXPONENT
            * steps / 100)


def prom_build_seconds(cells: int, parameters: int, degree: int = 1) -> float:
    runs = _bench_runs("prom.json", lambda r: r["parameters"] == parameters and r.get("degree", 1) == degree)
    fit = power_law_fit([r["cells"] for r in runs], [r["build_time"] for r in runs])
    if fit:
        return fit["prefactor"] * cells ** fit["exponent"]
    return QUADRATIC_COST_FACTOR[degree] * (0.5 + 0.33 * parameters) * cells / REFERENCE_CELLS


EIGEN_SECONDS_PER_MODE = 0.02
"""SLEPc's generalised eigensolve per vibration mode at level 1, degree 1 (1232 cells: 0.019 s for one)."""
STATIC_SOLVE_SECONDS = 0.01
"""One static solve of a modal derivative at level 1, degree 1 (1232 cells)."""
TENSOR_SECONDS = 0.1
"""The internal-force tensors of an 8-vector basis at level 1, degree 1; they grow as m⁴ and with the cells."""
LEVEL_1_CELLS = 1232


def basis_seconds(scene: Scene, cells: float, parametric: bool) -> float:
    """Estimated time [s] of the steps of a PROM build that grow with the basis: the eigensolve of the
    n_vm vibration modes (∝ n_vm × cells), the static solves of the modal derivatives (∝ their
    count × cells) and the cubic internal-force tensors (∝ m⁴ × cells), all from level-1 figures."""
    modes = scene.reduction.vibration_modes
    size = len(expected_basis(scene, parametric))
    derivatives = modes * (modes + 1) // 2 if scene.reduction.modal_derivatives else 0
    scale = QUADRATIC_COST_FACTOR[scene.mesh.degree] * cells / LEVEL_1_CELLS
    return scale * (EIGEN_SECONDS_PER_MODE * modes + STATIC_SOLVE_SECONDS * derivatives
                    + TENSOR_SECONDS * (size / 8) ** 4)


def reduced_tensor_bytes(scene: Scene, parametric: bool = True) -> float:
    """Memory of the reduced internal-force tensor [bytes]: 8 m⁴ for its cubic part, times 1 + p
    for its first ξ-derivatives (and + p² at Taylor order 2), m the candidate basis size."""
    size = len(expected_basis(scene, parametric))
    p = len(scene.shapes) if parametric else 0
    return 8.0 * size ** 4 * (1 + p + (p * p if scene.reduction.taylor_order == 2 else 0))


def _bench_runs(name: str, keep) -> list[dict]:
    folder = bench_results()
    path = folder / name if folder else None
    if path is None or not path.exists():
        return []
    try:
        return [r for r in json.loads(path.read_text())["runs"] if keep(r)]
    except (json.JSONDecodeError, KeyError):
        return []


def expected_basis(scene: Scene, parametric: bool) -> list[str]:
    """Candidate basis vectors (SPEC §7); dependent ones are dropped at build time."""
    reduction = scene.reduction
    actuation_modes = reduction.basis == "default" and scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0
    responses = response_labels(reduction.basis == "default" and reduction.response_vectors, actuation_modes,
                                scene.fluid.thrust)
    return candidate_labels(reduction.vibration_modes, reduction.modal_derivatives,
                            len(scene.shapes) if parametric else 0, actuation_modes, responses)


def plan(command: str, scene: Scene, model: str | None = None) -> list[str]:
    """Lines describing the work of ``command`` on ``scene``: the scene, its mesh, its body (read and
    checked as the run would, see ``planned_body``), then the work."""
    cells = LEVEL_TARGET_CELLS.get(scene.mesh.level, 0) if not scene.mesh.file else None
    lines = [f"scene {scene.name} (hash {scene.hash})"]
    if scene.mesh_file:
        from aquarom_fenics.geometry.mesh_files import MAX_MESH_FILE_BYTES
        from aquarom_fenics.io.readback import require_regular_file

        require_regular_file(scene.mesh_file, "mesh file", MAX_MESH_FILE_BYTES)    # a dry run refuses what the run would
        lines.append(f"mesh: read {scene.mesh_file} (scale {scene.mesh.scale:g})")
    else:
        cached = block_cache_path(scene.mesh.level, scene.mesh.length, scene.mesh.width, scene.mesh.height,
                                  head_fraction=scene.regions.head_fraction,
                                  muscle_range=scene.regions.muscle_range).exists()
        lines.append(f"mesh: level {scene.mesh.level} (~{cells} cells), "
                     + ("reused from the mesh cache" if cached else "generated with gmsh and cached"))
    body, body_cells = planned_body(scene)
    lines += body
    if scene.mesh_file:
        cells = body_cells          # the estimates below on the file's own cells
    if command in ("mesh", "shapes"):
        lines.append("work: tags" + (", design check, XDMF and PNG renders" if command == "shapes" else ""))
        return lines + ["estimate: a few seconds"]
    lines.append("forms: SVK energy, muscle energy, mass, drag (compiled once by FFCx, then reused)")
    steps = scene.n_steps
    degree = scene.mesh.degree
    fom_time = fom_seconds(cells, steps, degree)
    reduced = model in ("rom", "prom") or command in ("build", "optimize", "pareto", "basis", "check")
    if reduced:
        parametric = model != "rom"
        p = len(scene.shapes) if parametric else 0
        lines.append("basis (at most): " + ", ".join(expected_basis(scene, parametric)))
        tensors = ["internal force (cubic in η)", "mass and damping", "centre of mass"]
        skipped = []
        (tensors if scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0 else skipped).append("actuation")
        (tensors if scene.fluid.drag else skipped).append("drag")
        (tensors if scene.fluid.thrust else skipped).append("thrust")
        if p:
            tensors.append(f"Taylor terms in ξ of order {scene.reduction.taylor_order} for {p} parameters")
        else:
            skipped.append("ξ-terms")
        lines.append("tensors: " + ", ".join(tensors))
        lines.append("skipped: " + (", ".join(skipped) or "nothing"))
        build_time = prom_build_seconds(cells, p, degree) + basis_seconds(scene, cells, parametric)
        lines.append(f"PROM: from the PROM cache when an identical one was built before, else ~{build_time:.1f} s "
                     f"({scene.reduction.vibration_modes} vibration mode(s) by SLEPc, "
                     f"~{reduced_tensor_bytes(scene, parametric) / 1e6:.1f} MB of reduced tensors)")
    if command == "simulate" and model == "fom" or command == "compare":
        lines.append(f"FOM: {steps} steps of {scene.solver.time_step:g} s, ~{fom_time:.0f} s")
    if command in ("simulate", "compare") and reduced:
        lines.append("reduced solve: ~0.1 s; sensitivities: not computed")
    if command in ("optimize", "pareto"):
        settings = scene.optimizer
        runs = len(scene.cooptimization.weights) if command == "pareto" else 1
        builds = max(2, settings.max_iterations // max(settings.n_rebuild, 1)) if settings.method == "paper" else 8
        lines.append(f"optimiser: {settings.method}, at most {settings.max_iterations} iterations, ~{builds} PROM "
                     f"builds per run ({runs} run{'s' if runs > 1 else ''}), sensitivities dη/dξ at every built PROM")
        screen = tail_screen_seconds(scene)
        lines.append(f"stability: {stability_plan(scene)}" + (f", ~{screen:.0f} s per screen" if screen else ""))
        lines.append(f"FOM checks: start and optimal design per run (~{fom_time:.0f} s each; the start is cached)")
    if command in ("optimize", "pareto"):
        lines.append(f"estimate: ~{plan_seconds(command, scene, model):.0f} s")
    elif command == "build":
        lines.append(f"estimate: ~{plan_seconds(command, scene, model):.1f} s")
    elif command in ("simulate", "compare"):
        lines.append(f"estimate: ~{plan_seconds(command, scene, model):.0f} s")
    return lines


def plan_seconds(command: str, scene: Scene, model: str | None = None) -> float:
    """Estimated wall time [s] of ``command``: FOM runs, PROM builds (the basis steps that grow with
    the vibration modes included), tail screens and reduced solves, as :func:`plan` lists them."""
    cells = (LEVEL_TARGET_CELLS.get(scene.mesh.level, 0) if not scene.mesh.file else None) or REFERENCE_CELLS
    degree = scene.mesh.degree
    fom_time = fom_seconds(cells, scene.n_steps, degree)
    parametric = model != "rom"
    build = (prom_build_seconds(cells, len(scene.shapes) if parametric else 0, degree)
             + basis_seconds(scene, cells, parametric))
    if command in ("optimize", "pareto"):
        settings = scene.optimizer
        runs = len(scene.cooptimization.weights) if command == "pareto" else 1
        builds = max(2, settings.max_iterations // max(settings.n_rebuild, 1)) if settings.method == "paper" else 8
        return runs * (builds * (build + 0.2 + tail_screen_seconds(scene)) + 2 * fom_time)
    if command in ("build", "basis", "check"):
        return build
    if command in ("simulate", "compare"):
        reduced = model in ("rom", "prom")
        return (fom_time if model == "fom" or command == "compare" else 0.0) + (build + 0.2 if reduced else 0.0)
    return 0.0


# ---------------------------------------------------------------------- bounded plans
MAX_CELLS_FACTOR = 4.0
"""A generated block may have at most this many times its level's advertised number of cells."""
MIN_BLOCK_ASPECT = 0.01
"""Thinnest side over longest side of a generated block below which its cells are too flat."""
MAX_DOF_STEPS = 2e9
"""Largest number of time steps × degrees of freedom of one FOM run (level 5, degree 2 with the
default horizon is 1.4e7)."""
MAX_STORED_BYTES = 1e9
"""Largest stored displacement series of one run [bytes] (samples × vertices × 3 × 8 B)."""
VERTICES_PER_CELL = 0.3
NODES_PER_CELL = {1: 0.3, 2: 1.8}
"""Nodes per cell of the block meshes (level 1: 1232 cells, 362 vertices, 2239 quadratic nodes)."""
OVERRIDE = "--allow-large"


def estimated_block_cells(level: int, length: float, width: float, height: float) -> float:
    """Cells gmsh makes of a block: the level's count times the ratio of element-size cubes that
    fill the box (each side at least one element thick) to those of the reference box."""
    from aquarom_fenics.geometry.block import LEVEL_MESH_SIZE, REFERENCE_BOX, block_mesh_size

    sides = np.array([length, width, height], dtype=np.float64)
    with np.errstate(all="ignore"):      # sides of 1e-300 or 1e300 m: an infinite estimate, refused
        size = np.float64(block_mesh_size(level, *sides))
        cubes = np.prod(np.maximum(sides, size) / size)
        reference = np.prod(np.array(REFERENCE_BOX) / LEVEL_MESH_SIZE[level])
        cells = LEVEL_TARGET_CELLS[level] * cubes / reference
    return float(cells) if np.isfinite(cells) else math.inf


def estimated_cells(scene: Scene) -> float:
    """Cells of the scene's mesh (an external mesh counts as the reference mesh)."""
    if scene.mesh.file:
        return REFERENCE_CELLS
    mesh = scene.mesh
    return estimated_block_cells(mesh.level, mesh.length, mesh.width, mesh.height)


def check_mesh_bounds(scene: Scene) -> None:
    """Refuse (InputError naming --allow-large) a generated block far outside its level's range:
    flat or thin boxes, or several times the level's cells."""
    if scene.mesh.file:
        return
    mesh = scene.mesh
    sides = (mesh.length, mesh.width, mesh.height)
    target = LEVEL_TARGET_CELLS[mesh.level]
    cells = estimated_cells(scene)
    aspect = min(sides) / max(sides)
    box = " × ".join(f"{side:g}" for side in sides)
    if not aspect >= MIN_BLOCK_ASPECT or not cells <= MAX_CELLS_FACTOR * target:
        raise InputError(f"scene {scene.source}: [mesh] block {box} m at level {mesh.level} is far outside the "
                         f"level's range (about {cells:,.0f} cells against ~{target:,}, thinnest/longest side "
                         f"{aspect:.2g}, at least {MIN_BLOCK_ASPECT:g}); change the block or pass {OVERRIDE}")


MAX_PLAN_SECONDS = 3600.0
"""A plan estimated longer than this [s] needs --allow-large."""
MAX_TENSOR_BYTES = 4e9
"""Largest reduced internal-force tensor of a PROM build [bytes]."""
REDUCED_COMMANDS = ("build", "optimize", "pareto", "basis", "check")


def check_plan_bounds(command: str, scene: Scene, model: str | None = None) -> None:
    """Refuse (InputError naming --allow-large) a reduced basis whose tensors would not fit in memory,
    and a run estimated over :data:`MAX_PLAN_SECONDS` (one simulation, build or optimisation; a
    Pareto sweep's weights each), before anything is allocated."""
    reduced = command in REDUCED_COMMANDS or model in ("rom", "prom")
    if reduced:
        parametric = model != "rom"
        needed = reduced_tensor_bytes(scene, parametric)
        if needed > MAX_TENSOR_BYTES:
            size = len(expected_basis(scene, parametric))
            raise InputError(f"scene {scene.source}: [reduction] vibration_modes = {scene.reduction.vibration_modes} "
                             f"makes a basis of up to {size} vectors, whose reduced tensors would take "
                             f"~{needed / 1e9:.3g} GB (limit {MAX_TENSOR_BYTES / 1e9:g} GB); use fewer modes or "
                             f"pass {OVERRIDE}")
    runs = len(scene.cooptimization.weights) if command == "pareto" else 1
    seconds = plan_seconds(command, scene, model) / runs      # one run: a simulation, a build, one weight's optimisation
    if seconds > MAX_PLAN_SECONDS:
        raise InputError(f"scene {scene.source}: one run of `aquarom {command}` is estimated at ~{seconds / 3600:.1f} h "
                         f"(over {MAX_PLAN_SECONDS / 3600:g} h; see --dry-run); use a coarser level, a shorter "
                         f"duration or pass {OVERRIDE}")


def check_run_bounds(scene: Scene) -> None:
    """Refuse (InputError naming --allow-large) a run whose steps × dofs or stored series is too large."""
    steps = scene.n_steps
    cells = estimated_cells(scene)
    dofs = 3 * NODES_PER_CELL[scene.mesh.degree] * cells
    stored = (steps + 1) * VERTICES_PER_CELL * cells * 3 * 8
    solver = scene.solver
    if steps * dofs > MAX_DOF_STEPS:
        raise InputError(f"scene {scene.source}: [solver] duration = {solver.duration:g} s with time_step = "
                         f"{solver.time_step:g} s is {steps:,} steps × ~{dofs:,.0f} dofs = {steps * dofs:.1e}, beyond "
                         f"the limit {MAX_DOF_STEPS:.0e} (about {fom_seconds(cells, steps, scene.mesh.degree):.1e} s); "
                         f"use a larger time_step or pass {OVERRIDE}")
    if stored > MAX_STORED_BYTES:
        raise InputError(f"scene {scene.source}: [solver] {steps:,} steps would store a displacement series of "
                         f"~{stored / 1e9:.1f} GB (limit {MAX_STORED_BYTES / 1e9:g} GB); use a larger time_step "
                         f"or pass {OVERRIDE}")
