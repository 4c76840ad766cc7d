"""Accuracy of a PROM away from its building point (SPEC §8): the validity radius.

Along each shape direction of a scene (default SO1), at 1/8, 1/4 and 1/2 of its bound and both
signs, the PROM built at ξ = 0 (Taylor order 1 and 2) against the FOM on the moved mesh
(`aquarom_fenics.verification.validity`). Writes results/validation/prom_validity.json and a
Markdown table; the radius of a parameter is the largest tested |ξ| at which both signs stay
within 5% in distance.
"""
import argparse
from pathlib import Path

from aquarom_fenics.io.versions import software_versions
from aquarom_fenics.io.persistence import write_json_atomic, write_text_atomic
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.verification.validity import validity_study, validity_table

REPOSITORY = Path(__file__).resolve().parents[1]


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="so1")
    parser.add_argument("--level", type=int, default=3)
    parser.add_argument("--out", type=Path, default=REPOSITORY / "results" / "validation")
    args = parser.parse_args()
    base = Scene.load(args.scene).replace("mesh", level=args.level)
    study = validity_study(base, on_row=lambda row: print(row, flush=True))
    write_json_atomic(args.out / "prom_validity.json", study | {"versions": software_versions()})
    lines = validity_table(study)
    write_text_atomic(args.out / "prom_validity.md", "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
