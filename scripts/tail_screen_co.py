"""Does the tail screen separate the CO designs the FOM can simulate from those it cannot?

For every point of a finished CO Pareto sweep (its FOM checks done without the screen): the PROM at
the point's optimum, the fastest mode of the FOM's tail region linearised at the PROM's last-stroke
states (``aquarom_fenics.verification.local_stability.prom_tail_growth``, no early stop) for each
region radius, next to the FOM check's outcome. Writes <out>/tail_screen_co.json.

    .venv/bin/python scripts/tail_screen_co.py --pareto results/pareto/co-default --radii 0.01,0.015
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.reductor import build_prom
from aquarom_fenics.verification.local_stability import prom_tail_growth

REPOSITORY = Path(__file__).resolve().parent.parent


def screen_point(scene: Scene, fish, summary: dict, radii: list[float]) -> dict:
    """The screen's fastest tail mode per radius at one Pareto point's optimum, and its FOM check."""
    optimum = summary["optimum"]
    xi = [optimum[name] for name in scene.shape_names]
    scene = scene.replace("actuation", amplitude=optimum["amplitude"])
    check = summary["fom_check"]
    record = {"w1": summary["cost_weights"]["distance"],
              "amplitude": optimum["amplitude"], "fom_completed": check["error"] is None,
              "fom_optimal_distance": check["optimal_distance"], "fom_error": check["error"], "screen": {}}
    prom = build_prom(scene, xi_center=xi, fish=fish)
    for radius in radii:
        started = time.perf_counter()
        growth = prom_tail_growth(prom, scene.replace("optimizer", tail_region_radius=radius), fish, xi)
        record["screen"][f"{radius:g}"] = (
            {"prom_stopped": growth} if isinstance(growth, str) else
            {"growth_rate": growth.growth_rate, "frequency": growth.frequency, "time": growth.time,
             "states": growth.states, "wall_time": time.perf_counter() - started})
    return record


def separation(points: list[dict], radius: str, limit: float) -> dict:
    """Largest growth among the completed FOM checks, smallest among the stopped ones, and whether
    the limit lies between them."""
    completed = [p["screen"][radius]["growth_rate"] for p in points if p["fom_completed"]]
    stopped = [p["screen"][radius]["growth_rate"] for p in points if not p["fom_completed"]]
    largest, smallest = max(completed, default=None), min(stopped, default=None)
    return {"largest_growth_of_completed": largest, "smallest_growth_of_stopped": smallest,
            "limit_separates": (largest is None or largest <= limit) and (smallest is None or smallest > limit)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pareto", type=Path, default=REPOSITORY / "results" / "pareto" / "co-default")
    parser.add_argument("--scene", default="co")
    parser.add_argument("--radii", default="0.01,0.015", help="tail region radii [m]")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation")
    args = parser.parse_args(argv)
    scene = Scene.load(args.scene)
    fish = load_fish(scene)
    radii = [float(radius) for radius in args.radii.split(",")]
    points = []
    for folder in sorted(args.pareto.glob("w1_*")):
        summary = json.loads((folder / "summary.json").read_text())
        point = {"point": folder.name, **screen_point(scene, fish, summary, radii)}
        print(json.dumps(point, default=float), flush=True)
        points.append(point)
    limit = scene.optimizer.tail_growth_limit
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "tail_screen_co.json", {
        "scene": args.scene, "pareto": str(args.pareto), "mesh": {"level": scene.mesh.level, "degree": scene.mesh.degree},
        "time_step": scene.solver.time_step, "tail_growth_limit": limit, "points": points,
        "separation": {f"{radius:g}": separation(points, f"{radius:g}", limit) for radius in radii}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
