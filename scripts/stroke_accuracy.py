"""ROM and PROM accuracy over the stroke: the CO scene's actuation amplitude A against the FOM.

For A in --amplitudes at the nominal shape (ξ = 0) and at the CO corner (z_tail = -0.5, z_head = +0.5,
y_lin_long_tail = +0.4, y_head = +0.5, y_ellipse = +0.5): the FOM's distance and tail amplitude, and
the relative errors of
  - the ROM built at the design (``model = "rom"``, the scene at that A),
  - the CO scene's PROM built at the design's shape (at the scene's A; A enters the reduced run only,
    as in the CO study),
  - at the corner also the PROM built at ξ = 0 evaluated at the corner (the validity radius is lifted:
    it shows how far the PROM's Taylor expansion in ξ reaches).
each with the basis without the stroke vectors ("without", ``[reduction] stroke_amplitude = 0``) and
with them ("stroke", at --stroke-amplitude; docs/theory/basis.md, "Large strokes").
FOM runs are cached under --cache (by the scene's FOM hash, design and A). Writes
results/validation/stroke_accuracy.json (rows, versions, scene) and prints a table.
"""
import argparse
import hashlib
import json
import pickle
from pathlib import Path

from aquarom_fenics.api import Scene, build_prom, simulate
from aquarom_fenics.errors import InputError
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.io.scene_muscles import stroke_amplitude as resolved_stroke_amplitude
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.verification.compare import model_errors

REPOSITORY = Path(__file__).resolve().parents[1]
AMPLITUDES = (0.05, 0.1, 0.2, 0.3, 0.4)
CORNER = {"z_tail": -0.5, "z_head": 0.5, "y_lin_long_tail": 0.4, "y_head": 0.5, "y_ellipse": 0.5}
SHAPES = {"nominal": {}, "corner": CORNER}

def fom_run(scene: Scene, design: dict, cache: Path):
    """The FOM run of ``design`` (distance, tail amplitude, trajectory), from ``cache`` when it holds it."""
    key = hashlib.sha256(json.dumps([scene.fom_hash, sorted(design.items())]).encode()).hexdigest()[:16]
    path = cache / f"fom-{key}.pickle"
    if path.exists():
        with open(path, "rb") as stream:
            return pickle.load(stream)
    result = simulate(scene, design)
    result.model, result.states = None, []
    cache.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as stream:
        pickle.dump(result, stream)
    return result

def errors(fom, reduced) -> dict:
    """Relative distance and tail-amplitude errors, or why the reduced run stopped; the run's wall time [s]."""
    if not reduced.completed:
        return {"completed": False, "error": reduced.error, "wall_time": reduced.wall_time}
    return {"completed": True, "wall_time": reduced.wall_time, **model_errors(fom, reduced)}

def shape_rows(scenes: dict, label: str, design: dict, amplitudes, cache: Path, nominal_proms: dict) -> list[dict]:
    """One row per amplitude for the shape ``design``: the FOM, and per basis (``scenes``: name → scene)
    the ROM and the PROM errors."""
    proms = {}
    for basis, scene in scenes.items():
        proms[basis] = build_prom(scene, design)
        print(f"{label}, {basis} basis: PROM of {proms[basis].size} vectors ({', '.join(proms[basis].labels)})", flush=True)
    rows = []
    for amplitude in amplitudes:
        fom = None
        row = {"shape": label, "design": design, "amplitude": amplitude}
        for basis, scene in scenes.items():
            stroke = scene.replace("actuation", amplitude=amplitude)
            fom = fom or fom_run(stroke, design, cache)
            row.update(fom_completed=fom.completed, fom_distance=fom.distance, fom_tail_amplitude=fom.tail_amplitude)
            if not fom.completed:
                break
            entry = {"prom_size": proms[basis].size,
                     "rom": errors(fom, simulate(stroke, design, model="rom")),
                     "prom": errors(fom, simulate(stroke, design, model="prom", prom=proms[basis]))}
            if basis in nominal_proms:
                entry["prom_from_nominal"] = errors(fom, simulate(stroke, design, model="prom", prom=nominal_proms[basis]))
            row[basis] = entry
        rows.append(row)
        print_row(row, list(scenes))
    return rows

def percent(entry: dict | None, key: str) -> str:
    if entry is None:
        return "-"
    if not entry.get("completed"):
        return "failed"
    return f"{100 * entry[key]:+.2f} %"

def print_row(row: dict, bases: list[str]) -> None:
    if not row["fom_completed"]:
        print(f"{row['shape']:8s} A = {row['amplitude']:.2f}: the FOM did not complete", flush=True)
        return
    text = (f"{row['shape']:8s} A = {row['amplitude']:.2f}: FOM {100 * row['fom_distance']:7.3f} cm, tail "
            f"{100 * row['fom_tail_amplitude']:6.3f} cm")
    for basis in bases:
        entry = row[basis]
        text += (f" | {basis}: ROM {percent(entry['rom'], 'distance_relative')} (tail "
                 f"{percent(entry['rom'], 'tail_amplitude_relative')}), PROM {percent(entry['prom'], 'distance_relative')} "
                 f"(tail {percent(entry['prom'], 'tail_amplitude_relative')})")
        if "prom_from_nominal" in entry:
            text += f", PROM(ξ=0) {percent(entry['prom_from_nominal'], 'distance_relative')}"
    print(text, flush=True)

def scene_of(args, parser) -> Scene:
    """The scene with --duration and --set applied; its shapes must name the corner's when it is asked for."""
    scene = Scene.load(args.scene)
    if args.duration is not None:
        scene = scene.replace("solver", duration=args.duration)
    for item in args.set:
        key, _, value = item.partition("=")
        section, _, name = key.partition(".")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = None
        if not (section and name and value) or parsed is None:
            parser.error(f"--set {item!r}: expected SECTION.KEY=VALUE with a JSON value, e.g. reduction.response_vectors=false")
        scene = scene.replace(section, **{name: parsed})
    missing = sorted(set(CORNER) - set(scene.shape_names))
    if "corner" in args.shapes and missing:
        parser.error(f"--scene {args.scene}: its shapes lack {', '.join(missing)} of the CO corner; use a scene with "
                     "the CO shapes or --shapes nominal")
    if not args.amplitudes or min(args.amplitudes) <= 0:
        parser.error(f"--amplitudes {args.amplitudes}: give one or more amplitudes A > 0")
    return scene

def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="co", help="scene name or file (default: co)")
    parser.add_argument("--amplitudes", nargs="*", type=float, default=AMPLITUDES, metavar="A")
    parser.add_argument("--shapes", nargs="*", choices=sorted(SHAPES), default=list(SHAPES))
    parser.add_argument("--duration", type=float, default=None, help="simulated time [s] (default: the scene's)")
    parser.add_argument("--set", nargs="*", default=[], metavar="SECTION.KEY=VALUE",
                        help="scene overrides, e.g. reduction.response_vectors=false (JSON values)")
    parser.add_argument("--stroke-amplitude", type=float, default=None, metavar="A_S",
                        help="the basis with the stroke vectors at [reduction] stroke_amplitude = A_S (default: the scene's, else the "
                             "largest A; 0: none) besides the basis without them")
    parser.add_argument("--cache", type=Path, default=REPOSITORY / "results" / "cache" / "stroke_accuracy")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "stroke_accuracy.json")
    args = parser.parse_args()
    try:
        scene = scene_of(args, parser)
    except InputError as error:
        parser.error(str(error))
    stroke_amplitude = args.stroke_amplitude
    if stroke_amplitude is None:
        stroke_amplitude = resolved_stroke_amplitude(scene) or max(args.amplitudes)
    scenes = {"without": scene.replace("reduction", stroke_amplitude=0.0)}
    if stroke_amplitude > 0:
        scenes["stroke"] = scene.replace("reduction", stroke_amplitude=stroke_amplitude)
    rows = []
    nominal_proms = {}
    for label in args.shapes:
        if label == "corner":
            # the PROMs at ξ = 0 with their radius lifted to reach the corner (neither capped)
            nominal_proms = {basis: build_prom(value.replace("reduction", validity_fraction=1.0, validity_change=0.0),
                                               {name: 0.0 for name in scene.shape_names})
                             for basis, value in scenes.items()}
        rows += shape_rows(scenes, label, SHAPES[label], args.amplitudes, args.cache,
                           nominal_proms if label == "corner" else {})
    report = {"rows": rows, "bases": {basis: value.to_dict()["reduction"] for basis, value in scenes.items()},
              "scene": scene.to_dict(), "scene_hash": scene.hash, "versions": software_versions()}
    write_json_atomic(args.out, report)
    print(f"wrote {args.out}")

if __name__ == "__main__":
    main()
