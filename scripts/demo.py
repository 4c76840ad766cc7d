"""`make demo`: the main jobs on the built-in reference scenes, outputs under one folder.

Reports the reference mesh, renders the SO1 shape catalog and one design, and simulates the
nominal fish with the full-order model on the coarsest mesh and checks its ROM against it.
"""
import argparse
import sys
from pathlib import Path

from aquarom_fenics.cli import main as aquarom


def run(arguments: list[str]) -> None:
    print(f"\n$ aquarom {' '.join(arguments)}", flush=True)
    code = aquarom(arguments)
    if code != 0:
        sys.exit(code)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("results/demo"))
    out = parser.parse_args().out
    run(["mesh", "nominal"])
    run(["shapes", "so1", "--out", str(out / "so1-shapes")])
    run(["shapes", "so1", "--xi", "z_tail=-0.4", "--xi", "y_thin=0.1", "--out", str(out / "so1-design")])
    run(["simulate", "nominal", "--model", "fom", "--level", "1", "--out", str(out / "nominal-fom")])
    run(["compare", "nominal", "--model", "rom", "--level", "1", "--out", str(out / "nominal-compare")])
    print(f"\ndemo outputs in {out.resolve()}:")
    for path in sorted(out.rglob("*")):
        if path.is_file():
            print(f"  {path}")


if __name__ == "__main__":
    main()
