"""ROM and PROM against the FOM on travelling waves: the block's wave (scenes/wave.toml), the fish's
wave (scenes/fish_wave.toml, 120° per pair) and the same fish wave at 60° per pair.

Per wave: the FOM (wall time, cut steps, Newton iterations per step, distance, tail amplitude); the
ROM built at the design with the scene's basis (``[reduction] vibration_modes = "auto"``) and, for
comparison, with fixed mode counts (--modes); the PROM of the wave with the shapes of SO1 /
fish_optimize (z_tail, z_head, y_thin), built at ξ = 0 and run at ξ = 0 and at --design. One FOM at a
time. Writes results/validation/waves.json.

Usage::

    python scripts/validate_waves.py [--modes 1 2] [--design z_tail=0.1] [--only fish_wave]
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

from aquarom_fenics.api import Scene, build_prom, simulate
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.verification.compare import model_errors

REPOSITORY = Path(__file__).resolve().parents[1]
WAVES = {                      # label: (shipped scene, phase lag per pair [degrees], scene lending its shapes)
    "block_wave_120": ("wave", 120.0, "so1"),
    "fish_wave_120": ("fish_wave", 120.0, "fish_optimize"),
    "fish_wave_60": ("fish_wave", 60.0, "fish_optimize"),
}


def wave_scene(name: str, lag: float) -> Scene:
    """The shipped wave with pair k's phase (k - 1) × ``lag`` (pairs numbered from the tail, the
    pair of a muscle read from its region's suffix, left_k / right_k)."""
    scene = Scene.load(name)
    muscles = tuple(dataclasses.replace(muscle, phase=(int(muscle.region.rsplit("_", 1)[1]) - 1) * lag)
                    for muscle in scene.muscles)
    return dataclasses.replace(scene, muscles=muscles)


def fom_record(run) -> dict:
    summary = run.summary()
    return {key: summary[key] for key in ("distance", "tail_amplitude", "wall_time", "cut_steps",
                                          "mean_newton_iterations", "steps", "completed")}


def reduced_record(fom, run, seconds: float) -> dict:
    errors = model_errors(fom, run)
    return {"distance": run.distance, "tail_amplitude": run.tail_amplitude, "seconds": seconds,
            "distance_relative": errors["distance_relative"],
            "tail_amplitude_relative": errors["tail_amplitude_relative"]}


def timed(function, *args, **kwargs):
    started = time.perf_counter()
    value = function(*args, **kwargs)
    return value, time.perf_counter() - started


def measure_wave(label: str, modes: list[int], design: dict[str, float]) -> dict:
    name, lag, shapes_from = WAVES[label]
    scene = wave_scene(name, lag)
    fom = simulate(scene)
    row = {"scene": name, "phase_lag_degrees": lag, "fom": fom_record(fom)}
    rom, seconds = timed(simulate, scene, model="rom")
    row["rom"] = reduced_record(fom, rom, seconds)
    for count in modes:
        fixed, seconds = timed(simulate, scene.replace("reduction", vibration_modes=count), model="rom")
        row[f"rom_{count}_modes"] = reduced_record(fom, fixed, seconds)
    shaped = dataclasses.replace(scene, shapes=Scene.load(shapes_from).shapes)
    prom, seconds = timed(build_prom, shaped, {shape.name: 0.0 for shape in shaped.shapes})
    row["prom_build_seconds"] = seconds
    row["prom_basis"] = list(prom.labels)
    run, seconds = timed(simulate, shaped, model="prom", prom=prom)
    row["prom"] = reduced_record(fom, run, seconds)
    if design:
        off = simulate(shaped, design)
        run, seconds = timed(simulate, shaped, design, model="prom", prom=prom)
        row["design"] = design
        row["fom_at_design"] = fom_record(off)
        row["prom_at_design"] = reduced_record(off, run, seconds)
    return row


def describe(label: str, row: dict) -> str:
    fom = row["fom"]
    parts = [f"{label}: FOM {100 * fom['distance']:.3f} cm, tail {100 * fom['tail_amplitude']:.3f} cm, "
             f"{fom['wall_time']:.1f} s, {fom['cut_steps']} cut steps, {fom['mean_newton_iterations']:.2f} Newton/step"]
    for key in [k for k in row if k.startswith("rom") or k.startswith("prom") and isinstance(row[k], dict)]:
        entry = row[key]
        parts.append(f"  {key}: {100 * entry['distance']:.3f} cm ({100 * entry['distance_relative']:+.2f} %), tail "
                     f"{100 * entry['tail_amplitude']:.3f} cm ({100 * entry['tail_amplitude_relative']:+.2f} %)")
    return "\n".join(parts)


def parse_design(items: list[str]) -> dict[str, float]:
    design = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            design[name] = float(value)
        except ValueError:
            sep = ""
        if not sep:
            raise SystemExit(f"validate_waves: --design {item!r} must be NAME=VALUE, e.g. z_tail=0.1")
    return design


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="*", type=int, default=[1, 2], help="fixed vibration-mode counts to compare")
    parser.add_argument("--design", action="append", default=[], metavar="NAME=VALUE",
                        help="also the PROM against the FOM at this design (e.g. z_tail=0.1)")
    parser.add_argument("--only", action="append", choices=sorted(WAVES), help="measure only these waves")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "waves.json")
    args = parser.parse_args(argv)
    design = parse_design(args.design)
    report = {"waves": {}, "versions": software_versions()}
    for label in args.only or WAVES:
        report["waves"][label] = measure_wave(label, args.modes, design)
        print(describe(label, report["waves"][label]), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, report)
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
