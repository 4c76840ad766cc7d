"""ROM accuracy against its own FOM, with and without the basis's response vectors (docs/theory/basis.md).

For the nominal fish on the listed meshes: FOM distance and tail amplitude, and the relative errors of
the ROM built at the design with SPEC §7's items 1–5 only (`response_vectors = false`) and with the
default basis (ψ_m added; τ as well with the nodal thrust). With --shape-designs, the same for the SO1 PROM built at ξ = 0 on
degree 2, level 1, at three designs. Writes results/validation/rom_accuracy.json.
"""
import argparse
from pathlib import Path

from aquarom_fenics.api import Scene, build_prom, simulate
from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic
from aquarom_fenics.verification.compare import model_errors

REPOSITORY = Path(__file__).resolve().parents[1]
MESHES = ((2, 3), (2, 2), (2, 1), (1, 3), (1, 1))
SO1_DESIGNS = ({}, {"z_tail": 0.1}, {"z_tail": -0.1, "y_thin": 0.03})


def nominal_row(degree: int, level: int) -> dict:
    scene = Scene.load("nominal").replace("mesh", degree=degree, level=level)
    fom = simulate(scene)
    row = {"degree": degree, "level": level, "fom_distance": fom.distance, "fom_tail_amplitude": fom.tail_amplitude}
    for label, response_vectors in (("items_1_5", False), ("default", True)):
        rom = simulate(scene.replace("reduction", response_vectors=response_vectors), model="rom")
        row[label] = model_errors(fom, rom)
    return row


def shape_rows() -> list[dict]:
    rows = []
    base = Scene.load("so1").replace("mesh", degree=2, level=1)
    for label, response_vectors in (("items_1_5", False), ("default", True)):
        scene = base.replace("reduction", response_vectors=response_vectors)
        prom = build_prom(scene, {name: 0.0 for name in scene.shape_names})
        for design in SO1_DESIGNS:
            fom = simulate(scene, design)
            rows.append({"basis": label, "design": design,
                         **model_errors(fom, simulate(scene, design, model="prom", prom=prom))})
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--shape-designs", action="store_true", help="also the SO1 PROM off its centre")
    parser.add_argument("--meshes", nargs="*", metavar="DEGREE/LEVEL",
                        help="meshes of the nominal rows, e.g. 2/3 2/2 (default: " + " ".join(f"{d}/{l}" for d, l in MESHES) + ")")
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation" / "rom_accuracy.json")
    args = parser.parse_args()
    meshes = [tuple(int(part) for part in text.split("/")) for text in args.meshes] if args.meshes else MESHES
    rows = []
    for degree, level in meshes:
        rows.append(nominal_row(degree, level))
        row = rows[-1]
        print(f"degree {degree}, level {level}: FOM {100 * row['fom_distance']:.3f} cm; ROM distance error "
              f"{100 * row['items_1_5']['distance_relative']:+.2f} % (items 1–5), {100 * row['default']['distance_relative']:+.2f} % "
              f"(default); tail amplitude {100 * row['items_1_5']['tail_amplitude_relative']:+.2f} %, "
              f"{100 * row['default']['tail_amplitude_relative']:+.2f} %", flush=True)
    report = {"nominal": rows, "versions": software_versions()}
    if args.shape_designs:
        report["so1_prom_degree2_level1"] = shape_rows()
        for row in report["so1_prom_degree2_level1"]:
            print(f"SO1 PROM ({row['basis']}) at {row['design']}: distance {100 * row['distance_relative']:+.2f} %, "
                  f"tail amplitude {100 * row['tail_amplitude_relative']:+.2f} %")
    write_json_atomic(args.out, report)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
