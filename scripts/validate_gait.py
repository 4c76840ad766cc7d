"""The gait variables on the fish (scenes/fish_gait.toml): the reduced model at other gaits, its gait
gradient against the FOM, and the muscles' effort of a gait against the antagonist pair's.

1. Basis: one ROM built at the scene's gait (at the shapes' --design), run at other gaits, against the FOM
   there; with each pair's activation pattern in the basis (as a [gait] scene with phase_lag builds it) and
   with the scene's two patterns alone (``--no-pair-patterns``, the basis before [gait]).
2. Gradient: dd/dg of that ROM at the scene's gait against central differences of the FOM (lag ± 5°,
   f ± 0.02 Hz).
3. Effort: the muscles' mean positive power over the last cycle (``dynamics.muscle_power.mean_positive_power``) of
   the ROM (built at --gait) at the scene's gait, the other gaits of 1. and --gait (all at the scene's A),
   and of the fish's antagonist pair (scenes/fish.toml, [regions] muscles, the same
   frequency and shapes) at the amplitude of equal power (bisection on ROM runs), with both FOM distances.

Writes results/validation/gait.json. Usage::

    python scripts/validate_gait.py --design z_tail=0.1 --gait frequency=1.25 --gait phase_lag=30
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

from aquarom_fenics.api import Scene, simulate
from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io import scene_gait
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene_gait import apply_gait
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.dynamics.muscle_power import mean_positive_power
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]
OTHER_GAITS = [{"phase_lag": 60.0}, {"phase_lag": 30.0}, {"frequency": 1.25}, {"frequency": 0.75, "phase_lag": 180.0}]


def pairs(items: list[str]) -> dict[str, float]:
    return {name: float(value) for name, _, value in (item.partition("=") for item in items)}


def fom_distance(scene, design, fish) -> float:
    run = simulate(scene, design, fish=fish)
    if not run.completed:
        raise SystemExit(f"validate_gait: the FOM stopped at {design}: {run.summary()['stop_reason']}")
    return float(run.distance)


def basis_check(scene, design, fish, gaits) -> dict:
    rom = build_prom(scene, xi_center=[design[name] for name in scene.shape_names], fish=fish, parametric=False)
    rows = []
    for gait in gaits:
        driven = apply_gait(scene, gait)
        reduced = simulate_reduced(rom, driven, gait_sensitivity=True)
        full = fom_distance(driven, design, fish)
        rows.append({"gait": gait, "fom_distance": full, "rom_distance": reduced.distance,
                     "relative": reduced.distance / full - 1.0,
                     "rom_gradient": dict(zip(scene.gait_names, reduced.distance_gradient.tolist()))})
        print(f"  {gait}: FOM {100 * full:.3f} cm, ROM {100 * reduced.distance:.3f} cm "
              f"({100 * rows[-1]['relative']:+.2f} %)", flush=True)
    return {"basis_size": rom.size, "basis": list(rom.labels), "rows": rows, "rom": rom}


def gradient_check(scene, design, fish, rows) -> dict:
    start = {variable.name: variable.start for variable in scene.gait}
    result = {}
    for name, step in (("phase_lag", 5.0), ("frequency", 0.02)):
        if name not in start:
            continue
        plus, minus = (fom_distance(apply_gait(scene, {name: start[name] + sign * step}), design, fish)
                       for sign in (1, -1))
        fom = (plus - minus) / (2 * step)
        rom = rows[0]["rom_gradient"][name]
        result[name] = {"fom_central_difference": fom, "rom": rom, "relative": rom / fom - 1.0}
        print(f"  dd/d{name}: ROM {rom:.4e}, FOM {fom:.4e} ({100 * (rom / fom - 1):+.2f} %)", flush=True)
    return result


def effort_check(scene, design, fish, gait) -> dict:
    driven = apply_gait(scene, gait)
    rom = build_prom(driven, xi_center=[design[name] for name in scene.shape_names], fish=fish, parametric=False)
    run = simulate_reduced(rom, driven)
    power = mean_positive_power(rom, driven, run)
    pair = dataclasses.replace(Scene.load("fish"), shapes=scene.shapes)
    pair = pair.replace("actuation", frequency=driven.actuation.frequency)
    pair_fish = load_fish(pair)
    pair_rom = build_prom(pair, xi_center=[design[name] for name in scene.shape_names], fish=pair_fish,
                          parametric=False)

    def pair_power(amplitude):
        at = pair.replace("actuation", amplitude=amplitude)
        pair_run = simulate_reduced(pair_rom, at, amplitude=amplitude)
        return mean_positive_power(pair_rom, at, pair_run, amplitude=amplitude), pair_run.distance

    low, high = 0.02, 0.4
    for _ in range(30):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if pair_power(middle)[0] < power else (low, middle)
    amplitude = 0.5 * (low + high)
    pair_at = pair.replace("actuation", amplitude=amplitude)
    result = {"gait": gait, "gait_power_w": power, "gait_rom_distance": run.distance,
              "gait_fom_distance": fom_distance(driven, design, fish),
              "pair_amplitude_at_equal_power": amplitude, "pair_power_w": pair_power(amplitude)[0],
              "pair_rom_distance": pair_power(amplitude)[1],
              "pair_fom_distance": fom_distance(pair_at, design, pair_fish),
              "pair_power_at_scene_amplitude_w": pair_power(scene.actuation.amplitude)[0]}
    start = {variable.name: variable.start for variable in scene.gait}
    result["power_by_gait"] = []
    for other in [start] + OTHER_GAITS + [gait]:
        at = apply_gait(scene, other)
        other_run = simulate_reduced(rom, at)
        result["power_by_gait"].append({"gait": other, "power_w": mean_positive_power(rom, at, other_run),
                                        "rom_distance": other_run.distance})
    print("  effort: " + json.dumps(result), flush=True)
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="fish_gait")
    parser.add_argument("--design", action="append", default=[], metavar="NAME=VALUE", help="shapes (default 0)")
    parser.add_argument("--gait", action="append", default=[], metavar="NAME=VALUE", help="the gait of the effort check")
    parser.add_argument("--no-pair-patterns", action="store_true", help="the basis without each pair's pattern")
    parser.add_argument("--skip", action="append", default=[], choices=["basis", "gradient", "effort"])
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "gait.json")
    args = parser.parse_args(argv)
    scene = Scene.load(args.scene)
    design = {name: 0.0 for name in scene.shape_names} | pairs(args.design)
    if args.no_pair_patterns:
        scene_gait.pair_patterns = lambda scene: ()
    fish = load_fish(scene)
    report = {"scene": scene.name, "design": design, "pair_patterns": not args.no_pair_patterns,
              "versions": software_versions()}
    if "basis" not in args.skip:
        start = {variable.name: variable.start for variable in scene.gait}
        basis = basis_check(scene, design, fish, [start] + OTHER_GAITS)
        basis.pop("rom")
        report["basis"] = basis
        if "gradient" not in args.skip:
            report["gradient"] = gradient_check(scene, design, fish, basis["rows"])
    if "effort" not in args.skip:
        report["effort"] = effort_check(scene, design, fish, pairs(args.gait))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, report)
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
