"""Commands that run models at one design: simulate, build, compare."""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

from aquarom_fenics.cli.inputs import (check_plan, check_prom_option, check_time_runs, checked, design_values,
                                       load_scene, run_design, say)
from aquarom_fenics.cli.outputs import claim_output, claim_output_file, shown
from aquarom_fenics.errors import InputError, SolverError


def model_run_inputs(command: str):
    """``simulate`` and ``compare``: the scene and the --xi design, --prom with the PROM only, the
    time grid, and the sizes of one run and of the plan."""
    def inputs(args):
        scene = load_scene(args)
        xi = design_values(args, scene)
        check_prom_option(args)
        check_time_runs(args, scene)
        check_plan(args, command, scene)
        return scene, xi
    return inputs


def build_inputs(args):
    """``build``: the scene, the --xi building point and the size of the PROM."""
    scene = load_scene(args)
    xi = design_values(args, scene)
    check_plan(args, "build", scene)
    return scene, xi


@checked(model_run_inputs("simulate"))
def run_simulate(args, scene, xi) -> int:
    from aquarom_fenics.dynamics.simulate import simulate_fom

    design = run_design(scene, xi)
    out = claim_output(args, args.out or Path("results") / "simulate" / f"{scene.name}-{args.model}")
    if args.model == "fom":
        result = simulate_fom(scene, xi=design, out_dir=out, progress=not args.no_progress)
    else:
        result = run_reduced_model(scene, design, args.model, args.prom, out)
    if not result.completed:
        raise SolverError(f"{result.error}; partial trajectory in {out / 'trajectory.csv'}")
    say(f"{scene.name} ({args.model}): distance {100 * result.distance:.3f} cm, tail amplitude "
        f"{100 * result.tail_amplitude:.3f} cm, {result.wall_time:.2f} s on {MPI.COMM_WORLD.size} rank(s)")
    if result.strain is not None:
        say(f"{scene.name} ({args.model}): {result.strain.line()}")
    written = sorted(path.name for path in out.iterdir() if path.is_file()) if MPI.COMM_WORLD.rank == 0 else []
    say(f"outputs in {shown(args, out)}/ ({', '.join(written)})")
    return 0


def reduced_model(scene, xi: dict, model: str, prom_file: Path | None):
    """A ROM built at the design, or the scene's PROM (loaded from ``prom_file`` or built at the start values)."""
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.prom import ReducedModel
    from aquarom_fenics.reduction.reductor import build_prom

    if prom_file is not None and model == "prom":
        prom = ReducedModel.load(prom_file, prom_hash=scene.prom_hash)
        with build_command_on_refusal(scene, xi):
            prom.delta(np.array([xi.get(name, prom.design_point.get(name, 0.0)) for name in prom.shape_names]))
        return prom
    fish = load_fish(scene)
    center = {s.name: s.start for s in scene.shapes} | (xi if model == "rom" else {})
    vector = fish.parameter_vector(center)
    if model == "prom":
        # Refuse a design beyond the validity radius before spending time on the build.
        with build_command_on_refusal(scene, xi):
            ReducedModel.refuse_outside_radius(scene.shape_names, fish.parameter_vector(center | xi), vector,
                                               np.array(scene.validity_radii()))
    return cached_prom(scene, vector, lambda: build_prom(scene, xi_center=vector, fish=fish,
                                                          parametric=model == "prom"), parametric=model == "prom")


COMPARE_UNITS = {"design": "1 (shape parameters are dimensionless)", "errors": "m for absolute errors, "
                 "1 for *_relative", "fom": "as in a run's summary.json", "speedup": "1 (FOM / reduced wall time)"}
"""The ``units`` block of compare.json."""


@contextmanager
def build_command_on_refusal(scene, design: dict):
    """A validity-radius refusal ends with the command that builds a PROM centred on the design
    (on this run's mesh level and degree; other --set options are to be repeated)."""
    try:
        yield
    except InputError as refusal:
        values = " ".join(f"--xi {name}={value:g}" for name, value in design.items())
        mesh = f"--level {scene.mesh.level} --degree {scene.mesh.degree}" if not scene.mesh.file else ""
        raise InputError(f"{refusal}: run `aquarom build {scene.source} {mesh} {values} --out PROM.npz` "
                         f"and pass --prom PROM.npz") from None


def run_reduced_model(scene, xi: dict, model: str, prom_file: Path | None, out: Path):
    """Simulate the ROM or PROM at the design and write its run outputs to ``out``."""
    from aquarom_fenics.dynamics.reduced_dynamics import attach_strains, simulate_reduced
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.io.run_outputs import write_run_outputs
    from aquarom_fenics.io.xdmf import cell_regions

    reduced = reduced_model(scene, xi, model, prom_file)
    xi_vector = np.array([xi.get(name, reduced.design_point.get(name, 0.0)) for name in reduced.shape_names])
    result = simulate_reduced(reduced, scene, xi_vector)
    fish = load_fish(scene)
    attach_strains(result, reduced, scene, xi_vector, fish)
    if MPI.COMM_WORLD.rank == 0:
        design = reduced.design_point | xi
        vertices = fish.nodes.n_vertices
        write_run_outputs(out, scene, result, model, design, fish.design(design)[:vertices], fish.mesh.cells,
                          np.einsum("ndm,sm->snd", reduced.basis[:vertices], result.states), MPI.COMM_WORLD,
                          extra={"cells": reduced.cells, "dofs": reduced.dofs, "reduced_size": reduced.size,
                                 "basis": reduced.labels, "basis_dropped": reduced.dropped,
                                 "build_timings": reduced.timings},
                          regions=cell_regions(fish.tags, fish.mesh.cells.shape[0]))
    return result


@checked(build_inputs)
def run_build(args, scene, xi) -> int:
    from aquarom_fenics.reduction.cache import cached_prom
    from aquarom_fenics.geometry.fish import load_fish
    from aquarom_fenics.reduction.reductor import build_prom

    xi = {s.name: s.start for s in scene.shapes} | xi
    out = claim_output_file(args, args.out or Path("results") / "build" / f"{scene.name}-prom.npz")
    fish = load_fish(scene)
    center = fish.parameter_vector(xi)
    built = []

    def build():
        built.append(True)
        return build_prom(scene, xi_center=center, fish=fish)

    prom = cached_prom(scene, center, build)
    if MPI.COMM_WORLD.rank == 0:
        prom.save(out)
    origin = (f"built in {prom.timings['total']:.2f} s" if built else
              f"reused from the PROM cache (built there in {prom.timings['total']:.2f} s)")
    combination = "a numerical combination" if len(prom.dropped) == 1 else "numerical combinations"
    dropped = (f"; left out: {', '.join(prom.dropped)} ({combination} of the others: the basis spans the same "
               "motions)" if prom.dropped else "")
    say(f"PROM of {scene.name}: m = {prom.size} ({', '.join(prom.labels)}), p = {prom.n_parameters}{dropped}; "
        f"{origin}; wrote {out}")
    return 0


@checked(model_run_inputs("compare"))
def run_compare(args, scene, xi) -> int:
    from aquarom_fenics.verification.compare import model_errors
    from aquarom_fenics.io.plots import plot_comparison
    from aquarom_fenics.io.persistence import write_json_atomic
    from aquarom_fenics.dynamics.simulate import simulate_fom

    design = run_design(scene, xi)
    out = claim_output(args, args.out or Path("results") / "compare" / scene.name)
    reduced = run_reduced_model(scene, design, args.model, args.prom, out / args.model)
    full = simulate_fom(scene, xi=design, out_dir=out / "fom", progress=not args.no_progress)
    for name, result in (("fom", full), (args.model, reduced)):
        if not result.completed:
            raise SolverError(f"{name}: {result.error}")
    errors = model_errors(full, reduced)
    if MPI.COMM_WORLD.rank == 0:
        write_json_atomic(out / "compare.json", {"design": design, "xi_given": xi, "model": args.model, "errors": errors,
                                                 "fom": full.summary(), args.model: reduced.summary(),
                                                 "speedup": full.wall_time / reduced.wall_time,
                                                 "units": COMPARE_UNITS})
        plot_comparison(out / "compare.png", {"FOM": full.trajectory.arrays(),
                                              args.model.upper(): reduced.trajectory.arrays()},
                        f"{scene.name}: FOM against {args.model.upper()}")
    at = ", ".join(f"{name} = {value:g}" for name, value in design.items()) or "the block (no shapes)"
    say(f"{scene.name} at {at}: distance FOM {100 * full.distance:.3f} cm, "
        f"{args.model.upper()} {100 * reduced.distance:.3f} cm ({100 * errors['distance_relative']:+.2f} %); "
        f"tail amplitude {100 * errors['tail_amplitude_relative']:+.2f} %; outputs in {shown(args, out)}/")
    for name, result in (("fom", full), (args.model, reduced)):
        if result.strain is not None:
            say(f"{scene.name} ({name}): {result.strain.line()}")
    return 0
