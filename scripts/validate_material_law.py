"""Saint Venant-Kirchhoff against compressible Neo-Hookean (``[material] law``) on the FOM, with the
largest principal Green-Lagrange strain of each run, and the reduced models' error on Neo-Hookean.

Cases: the nominal design, the SO1-SO3 optima and the CO corner (A = 0.4, the SO2 shapes at their
bounds) from the optimisations of docs/data/studies, and the fish's travelling wave
(scenes/fish_wave.toml). For each: the FOM with each law (distance, tail amplitude, ε_max with its
time and region, cut steps, Newton iterations), and a reduced model of the Neo-Hookean scene against
its FOM: at the nominal design the SO1 PROM built at its start (the nominal design), elsewhere a ROM
built at the design; the same reduced model of the SVK scene against the SVK FOM is the baseline
(its own error, without the law's). Writes results/validation/material_law.json (``--out``); docs/data/validation
keeps the copy the manual's table is generated from.
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

from aquarom_fenics.dynamics.reduced_dynamics import attach_strains, simulate_reduced
from aquarom_fenics.dynamics.simulate import simulate_fom
from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem.strains import STRAIN_LIMIT
from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.reduction.reductor import build_prom

REPOSITORY = Path(__file__).resolve().parents[1]
STUDIES = REPOSITORY / "docs" / "data" / "studies"
LAWS = ("svk", "neo-hookean")


def optimum(study: str) -> dict:
    """The optimum ξ (and A) of a study of docs/data/studies."""
    return json.loads((STUDIES / study / "summary.json").read_text())["optimum"]


def cases() -> list[dict]:
    """(name, scene, design ξ, actuation amplitude or None, reduced model) of every case."""
    corner = dict(optimum("co/w1_0.98"))
    amplitude = corner.pop("amplitude")
    listed = [{"name": "nominal", "scene": "so1", "xi": {}, "amplitude": None, "reduced": "prom"}]
    listed += [{"name": f"{study.upper()} optimum", "scene": study, "xi": optimum(study), "amplitude": None,
                "reduced": "rom"} for study in ("so1", "so2", "so3")]
    listed.append({"name": f"CO corner (A = {amplitude:g})", "scene": "co", "xi": corner, "amplitude": amplitude,
                   "reduced": "rom"})
    listed.append({"name": "fish wave", "scene": "fish_wave", "xi": {}, "amplitude": None, "reduced": "rom"})
    return listed


def scene_of(case: dict, law: str, level: int | None) -> Scene:
    scene = Scene.load(case["scene"]).replace("material", law=law)
    if case["amplitude"] is not None:
        scene = scene.replace("actuation", amplitude=case["amplitude"])
        scene = scene.replace("cooptimization", enabled=False)
    if level and not scene.mesh.file:
        scene = scene.replace("mesh", level=level)
    return scene


def run_facts(result) -> dict:
    """Distance, tail amplitude [m], ε_max with its time [s] and region, and the solver's effort."""
    strain = result.strain.as_dict() if result.strain is not None else {}
    facts = {"distance": result.distance, "tail_amplitude": result.tail_amplitude, "completed": result.completed,
             "error": result.error, "wall_time": result.wall_time, "cut_steps": result.cut_steps,
             "max_principal_strain": strain.get("max_principal"), "strain_time": strain.get("time"),
             "strain_region": strain.get("region"), "strain_by_region": strain.get("by_region")}
    iterations = np.asarray(result.trajectory.newton_iterations[1:])
    facts["mean_newton_iterations"] = float(iterations.mean()) if iterations.size else None
    return facts


def relative(value, reference):
    return None if value is None or not reference else (value - reference) / reference


def reduced_run(case: dict, law: str, level: int | None, reference: dict) -> dict:
    """The case's reduced model of the ``law``'s scene against that law's FOM (``reference``)."""
    scene = scene_of(case, law, level)
    fish = load_fish(scene)
    started = time.perf_counter()
    parametric = case["reduced"] == "prom"
    try:
        model = build_prom(scene, xi_center=None if parametric else case["xi"], fish=fish, parametric=parametric)
    except SolverError as failure:
        return {"model": case["reduced"], "error": str(failure), "completed": False}
    xi = fish.parameter_vector(case["xi"])[:model.n_parameters]       # a ROM has no parameters
    reduced = attach_strains(simulate_reduced(model, scene, xi), model, scene, xi, fish)
    facts = run_facts(reduced) | {"model": case["reduced"], "size": model.size,
                                  "build_and_run_time": time.perf_counter() - started}
    facts["distance_error"] = relative(facts["distance"], reference["distance"])
    facts["tail_amplitude_error"] = relative(facts["tail_amplitude"], reference["tail_amplitude"])
    print(f"{case['name']} {law} {case['reduced']}: {facts['distance']} m ({facts['distance_error']})", flush=True)
    return facts


def measure(case: dict, level: int | None, earlier: dict) -> dict:
    """Both laws' FOMs (those of ``earlier``, an entry of a previous output, when given) and their
    reduced models of one case."""
    entry = {"case": case["name"], "scene": case["scene"], "xi": case["xi"], "amplitude": case["amplitude"]}
    for law in LAWS:
        if law in earlier:
            entry[law] = earlier[law]
            continue
        scene = scene_of(case, law, level)
        fish = load_fish(scene)
        entry[law] = run_facts(simulate_fom(scene, xi=case["xi"], fish=fish, progress=False))
        print(f"{case['name']} {law}: {entry[law]['distance']} m, strain {entry[law]['max_principal_strain']}",
              flush=True)
    svk, neo = entry["svk"], entry["neo-hookean"]
    entry["distance_difference"] = relative(neo["distance"], svk["distance"])
    entry["tail_amplitude_difference"] = relative(neo["tail_amplitude"], svk["tail_amplitude"])
    for law in LAWS:
        entry[f"{law}_reduced"] = reduced_run(case, law, level, entry[law])
    return entry


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--level", type=int, help="mesh level of the block scenes (default: the scene's)")
    parser.add_argument("--only", nargs="*", help="case names to run (default: all)")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "material_law.json")
    parser.add_argument("--reuse-fom", type=Path, help="an earlier output whose FOM runs are taken as they are")
    args = parser.parse_args()
    started = time.perf_counter()
    earlier = {}
    if args.reuse_fom:
        earlier = {entry["case"]: entry for entry in json.loads(args.reuse_fom.read_text())["cases"]}
    entries = [measure(case, args.level, earlier.get(case["name"], {})) for case in cases()
               if not args.only or case["name"] in args.only]
    write_json_atomic(args.out, {
        "cases": entries, "strain_limit": STRAIN_LIMIT, "level": args.level, "wall_time": time.perf_counter() - started,
        "versions": software_versions(),
        "units": {"distance": "m", "tail_amplitude": "m", "wall_time": "s", "build_and_run_time": "s",
                  "max_principal_strain": "1", "strain_time": "s", "*_difference": "1, Neo-Hookean against SVK",
                  "*_error": "1, the reduced model against the FOM of the same law"}})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
