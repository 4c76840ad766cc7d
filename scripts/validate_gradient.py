"""The PROM's distance gradient against central differences of the FOM (SPEC §9), and with
--radius its distance at ± each parameter's validity radius against the FOM's (SPEC §8).

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
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="so1")
    parser.add_argument("--level", type=int, help="mesh level (default: the scene's)")
    parser.add_argument("--step", type=float, default=0.02, help="ε of the FOM's central differences")
    parser.add_argument("--no-gradient", action="store_true", help="skip the central differences")
    parser.add_argument("--radius", action="store_true", help="also the PROM against the FOM at ± the validity radii")
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
    for k, name in enumerate(() if args.no_gradient else prom.shape_names):
        distances = []
        for sign in (1.0, -1.0):
            run = simulate_fom(scene, {name: sign * args.step}, fish=fish, progress=False)
            distances.append(run.distance)
        central = (distances[0] - distances[1]) / (2 * args.step)
        row = {"parameter": name, "prom_m": float(reduced.distance_gradient[k]), "fom_central_m": float(central),
               "relative_difference": float(reduced.distance_gradient[k] / central - 1.0)}
        rows.append(row)
        print(row, flush=True)
    radius_rows = []
    for k, name in enumerate(prom.shape_names if args.radius else ()):
        for sign in (1.0, -1.0):
            xi = np.zeros(prom.n_parameters)
            xi[k] = sign * prom.validity_radius[k]
            fom = simulate_fom(scene, dict(zip(prom.shape_names, xi)), fish=fish, progress=False)
            reduced_there = simulate_reduced(prom, scene, xi)
            row = {"parameter": name, "value": float(xi[k]), "fom_distance_m": float(fom.distance),
                   "prom_distance_m": float(reduced_there.distance),
                   "relative_error": float(reduced_there.distance / fom.distance - 1.0)}
            radius_rows.append(row)
            print(row, flush=True)
    write_json_atomic(args.out, {"scene": args.scene, "level": scene.mesh.level, "degree": scene.mesh.degree,
                                 "step": args.step, "prom_distance_m": float(reduced.distance), "rows": rows,
                                 "radius_rows": radius_rows,
                                 "prom_build_and_solve_s": prom_time, "versions": software_versions()})


if __name__ == "__main__":
    main()
