"""`--dry-run`: what a command would build or reuse, what it skips, and how long it should take.

Time and memory estimates are those of :mod:`aquarom_fenics.studies.estimate` (cells per level from
the mesh recipe, costs from the benchmarks or the reference figures).
"""
from __future__ import annotations

import math

import numpy as np

from aquarom_fenics.errors import InputError

from aquarom_fenics.geometry.block import block_cache_path
from aquarom_fenics.geometry.fish import planned_body
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.scene_muscles import planned_vibration_modes
from aquarom_fenics.optimization.prom_builder import stability_plan
from aquarom_fenics.studies.estimate import (REFERENCE_CELLS, actuation_modes, basis_seconds, expected_basis,
                                             fom_seconds, level_cells, prom_build_seconds, reduced_tensor_bytes, scene_cells, tail_screen_seconds)


def plan(command: str, scene: Scene, model: str | None = None) -> list[str]:
    """Lines describing the work of ``command`` on ``scene``: the scene, its mesh, its body (read and
    checked as the run would, see ``planned_body``), then the work."""
    cells = scene_cells(scene) if not scene.mesh.file else None
    lines = [f"scene {scene.name} (hash {scene.hash})"]
    if scene.mesh_file:
        from aquarom_fenics.geometry.mesh_files import MAX_MESH_FILE_BYTES
        from aquarom_fenics.io.readback import require_regular_file

        require_regular_file(scene.mesh_file, "mesh file", MAX_MESH_FILE_BYTES)    # a dry run refuses what the run would
        lines.append(f"mesh: read {scene.mesh_file} (scale {scene.mesh.scale:g})")
    else:
        cached = block_cache_path(scene.mesh.level, scene.mesh.length, scene.mesh.width, scene.mesh.height,
                                  head_fraction=scene.regions.head_fraction,
                                  muscle_range=scene.regions.muscle_range,
                                  pairs=scene.regions.muscle_pairs).exists()
        lines.append(f"mesh: level {scene.mesh.level} (~{cells} cells), "
                     + ("reused from the mesh cache" if cached else "generated with gmsh and cached"))
    body, body_cells = planned_body(scene)
    lines += body
    if scene.mesh_file:
        cells = body_cells          # the estimates below on the file's own cells
    if command in ("mesh", "shapes", "export"):
        lines.append("work: tags" + {"shapes": ", design check, XDMF and PNG renders",
                                     "export": ", design check, surface checks, the file(s) of --out"}.get(command, ""))
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
                     f"({planned_vibration_modes(scene)} vibration mode(s) by SLEPc, "
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
    if command == "calibrate":
        build_time = prom_build_seconds(cells, 0, degree) + basis_seconds(scene, cells, False)
        lines.append(f"fit: a ROM at the scene's design (~{build_time:.1f} s, rebuilt when a parameter moves by more "
                     "than a fifth of its value), Levenberg–Marquardt on it with sensitivities dη/dθ (~0.1 s per "
                     f"iteration), then Gauss–Newton iterations on the FOM ({steps} steps of {scene.solver.time_step:g} "
                     f"s, ~{fom_time:.1f} s each, at most 6)")
        lines.append(f"estimate: ~{2 * build_time + 3 * fom_time:.1f} s (three FOM iterations)")
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
    cells = scene_cells(scene)
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
        cells = level_cells(level) * cubes / reference
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
    target = level_cells(mesh.level)
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
            tensors = (f"makes a basis of up to {size} vectors, whose reduced tensors would take ~{needed / 1e9:.3g} GB "
                       f"(limit {MAX_TENSOR_BYTES / 1e9:g} GB)")
            modes = actuation_modes(scene)
            if modes > 1 and reduced_tensor_bytes(scene, parametric, 1) <= MAX_TENSOR_BYTES:
                fit = max(k for k in range(1, modes) if reduced_tensor_bytes(scene, parametric, k) <= MAX_TENSOR_BYTES)
                raise InputError(f"scene {scene.source}: its {len(scene.actuated_muscles)} muscles make {modes} actuation "
                                 f"modes (activation patterns: one per frequency, two where its phases are not all "
                                 f"0° or 180°), each with its own basis vectors (ψ, θ_ψ and their products), which "
                                 f"{tensors}; at most {fit} actuation modes fit: give the muscles fewer frequencies, "
                                 f"set [reduction] basis = \"paper\" (no actuation modes), run the FOM or pass {OVERRIDE}")
            raise InputError(f"scene {scene.source}: [reduction] vibration_modes = {scene.reduction.vibration_modes} "
                             f"{tensors}; use fewer modes or pass {OVERRIDE}")
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
