"""The PROM's distance gradient against central differences of the FOM (SPEC §9).

A PROM built at ξ = 0 on a scene (default SO1 on its shipped mesh) gives d(distance)/dξ_k from its
sensitivities; the FOM (the design pulled back to the nominal mesh) gives the central difference
[d(ε e_k) - d(-ε e_k)] / 2ε. Writes results/validation/prom_gradient.json.
"""
import argparse
import time
from pathlib import Path

import numpy as np

from aquarom_fenics.dynamics.reduced_dynamics import simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.outputs import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="so1")
    parser.add_argument("--level", type=int, help="mesh level (default: the scene's)")
    parser.add_argument("--step", type=float, default=0.02, help="ε of the FOM's central differences")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "prom_gradient.json")
    args = parser.parse_args()
    scene = Scene.load(args.scene)
    if args.level:
        scene = scene.replace("mesh", level=args.level)
    fish = load_fish(scene)
    started = time.perf_counter()
    prom = build_prom(scene, fish=fish)
    reduced = simulate_reduced(prom, scene, np.zeros(prom.n_parameters), sensitivities=True)
    prom_time = time.perf_counter() - started
    rows = []
    for k, name in enumerate(prom.shape_names):
        distances = []
        for sign in (1.0, -1.0):
            run = simulate_fom(scene, {name: sign * args.step}, fish=fish, progress=False)
            distances.append(run.distance)
        central = (distances[0] - distances[1]) / (2 * args.step)
        row = {"parameter": name, "prom_m": float(reduced.distance_gradient[k]), "fom_central_m": float(central),
               "relative_difference": float(reduced.distance_gradient[k] / central - 1.0)}
        rows.append(row)
        print(row, flush=True)
    write_json_atomic(args.out, {"scene": args.scene, "level": scene.mesh.level, "degree": scene.mesh.degree,
                                 "step": args.step, "prom_distance_m": float(reduced.distance), "rows": rows,
                                 "prom_build_and_solve_s": prom_time, "versions": software_versions()})


if __name__ == "__main__":
    main()
