"""Stability of one design's FOM: completion, per-force energy balance, the spine's dominant mode, the tail's modes.

For each time step and spine-force form: the PROM's stability verdict at the design, does the FOM at the design complete (cut steps), where
does the energy come from (``aquarom_fenics.verification.energy``), which spine motion carries the late-time
response (``aquarom_fenics.verification.energy.spine_spectrum``) and, with ``--tail-radius``, the frozen linearisation
of the tail region at the stored states, with the thrust and without it
(``aquarom_fenics.verification.local_stability``). Writes <out>/stability_<name>.json.

    .venv/bin/python scripts/stability_co.py --optimum results/optimize/co/summary.json --level 3
    .venv/bin/python scripts/stability_co.py --optimum results/pareto/co-default/w1_0.7/summary.json --level 2 \
        --time-steps 0.02 --spine-forces source --no-prom --set solver.min_time_step=0.005 --tail-radius 0.015 --name co07
    .venv/bin/python scripts/stability_co.py --scene nominal --set material.young_modulus=52e3 \
        --set solver.min_time_step=1.0 --spine-forces source --no-prom --name soft
"""
from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

import numpy as np

from aquarom_fenics.dynamics.reduced_dynamics import reduced_stability
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.verification.energy import energy_balance, spine_spectrum
from aquarom_fenics.verification.local_stability import local_stability, region_dofs

REPOSITORY = Path(__file__).resolve().parent.parent


def design_of(summary: dict, scene: Scene) -> tuple[list[float], float]:
    """(ξ in the scene's shape order, amplitude A) of an `aquarom optimize` summary."""
    optimum = summary["optimum"]
    return [optimum[name] for name in scene.shape_names], optimum.get("amplitude", scene.actuation.amplitude)


def scene_overrides(assignments: list[str]) -> dict:
    """{"solver": {"integrator": "newmark"}, ...} from ["solver.integrator=newmark", ...] (numbers read as TOML)."""
    sections: dict = {}
    for item in assignments:
        key, value = item.split("=", 1)
        section, name = key.split(".", 1)
        number = value[:1].isdigit() or value[:1] in "+-."
        sections.setdefault(section, {})[name] = tomllib.loads(f"v = {value}" if number else f'v = "{value}"')["v"]
    return sections


def tail_modes(scene: Scene, fish, xi, result, radius: float, every: int) -> dict:
    """Frozen linearisation of the tail region (nodes within ``radius`` of the tail station) at every
    ``every``-th stored state: fastest growth, its frequency and the step map's spectral radius, with the
    thrust (the run's model) and with the thrust switched off (same states)."""
    without_thrust = FullOrderModel(scene.replace("fluid", thrust=False), fish, xi)
    h = scene.solver.time_step
    dofs = region_dofs(result.model, result.model.tail_point(), radius)      # same mesh, design and fixed dofs
    records = {}
    for name, model in (("with_thrust", result.model), ("without_thrust", without_thrust)):
        records[name] = [local_stability(model, step * h, *state, dofs, model.scheme).summary()
                         for step, state in enumerate(result.states) if step % every == 0]
    without_thrust.destroy()
    return {"radius": radius, "region_dofs": int(dofs.size), **records}


def run_case(scene: Scene, fish, xi, time_step: float, spine_force: str, tail_radius: float | None = None,
             tail_every: int = 2) -> dict:
    scene = scene.replace("solver", time_step=time_step).replace("fluid", spine_force=spine_force)
    result = simulate_fom(scene, xi=xi, fish=fish, progress=False, keep_states=True)
    arrays = result.trajectory.arrays()
    record = {"time_step": time_step, "spine_force": spine_force, "completed": result.completed,
              "error": result.error, "cut_steps": result.cut_steps, "stopped_at": float(arrays["time"][-1]),
              "distance": result.distance, "wall_time": result.wall_time,
              "mean_newton_iterations": result.summary()["mean_newton_iterations"],
              "max_newton_iterations": int(max(arrays["newton_iterations"]))}
    if result.cut_steps == 0:
        record["energy"] = energy_balance(result).summary()
    model = result.model
    times = arrays["time"][: len(result.states)]
    lateral = np.array([model.spine_values(u)[:, 1] for u, *_ in result.states])
    record["spine"] = spine_spectrum(times, lateral, scene.actuation.frequency)
    if tail_radius:
        record["tail_modes"] = tail_modes(scene, fish, xi, result, tail_radius, tail_every)
    model.destroy()
    return record


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--optimum", type=Path, help="summary.json of `aquarom optimize` (default: the scene's start)")
    parser.add_argument("--scene", default="co")
    parser.add_argument("--level", type=int, default=3)
    parser.add_argument("--time-steps", default="0.02,0.01")
    parser.add_argument("--spine-forces", default="source,lagrangian")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation")
    parser.add_argument("--name", default="co98")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="scene override, e.g. solver.integrator=newmark, solver.min_time_step=1.0 (no step "
                             "cuts), material.young_modulus=52e3")
    parser.add_argument("--no-prom", action="store_true", help="skip the PROM stability verdicts")
    parser.add_argument("--tail-radius", type=float, help="also linearise the tail region of this radius [m] "
                        "at every --tail-every-th stored state (serial)")
    parser.add_argument("--tail-every", type=int, default=2)
    args = parser.parse_args(argv)
    scene = Scene.load(args.scene).replace("mesh", level=args.level)
    for section, values in scene_overrides(args.set).items():
        scene = scene.replace(section, **values)
    optimum = json.loads(args.optimum.read_text()) if args.optimum else {"optimum": {}}
    xi, amplitude = design_of(optimum, scene)
    scene = scene.replace("actuation", amplitude=amplitude)
    fish = load_fish(scene)
    cases, verdicts = [], {}
    for spine_force in [] if args.no_prom else args.spine_forces.split(","):
        varied = scene.replace("fluid", spine_force=spine_force)
        stable, reason = reduced_stability(build_prom(varied, xi_center=xi, fish=fish), varied, xi)
        verdicts[spine_force] = {"stable": stable, "reason": reason}
        print(f"PROM at the design, spine force {spine_force}: {reason}", flush=True)
    for spine_force in args.spine_forces.split(","):
        for time_step in (float(h) for h in args.time_steps.split(",")):
            case = run_case(scene, fish, xi, time_step, spine_force, args.tail_radius, args.tail_every)
            print(json.dumps({k: v for k, v in case.items() if k not in ("spine", "tail_modes")} | {
                "spine_peak": case["spine"]["peak"]}, default=float), flush=True)
            cases.append(case)
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / f"stability_{args.name}.json",
                      {"scene": args.scene, "level": args.level, "overrides": scene_overrides(args.set), "xi": dict(zip(scene.shape_names, xi)),
                       "amplitude": amplitude, "prom_stability": verdicts, "cases": cases})
    return 0


if __name__ == "__main__":
    sys.exit(main())
