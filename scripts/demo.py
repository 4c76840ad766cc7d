"""`make demo`: the main job on the built-in reference scenes, outputs under one folder.

Reports the reference mesh, renders the SO1 shape catalog, simulates the nominal fish with the
full-order model and checks its ROM against it, then optimises SO1 end to end with PROM
sensitivities, verifies the optimum with the FOM and animates the optimal fish swimming (all on
the coarsest mesh, a few minutes).
"""
import argparse
import json
import shutil
import sys
from pathlib import Path

from aquarom_fenics.cli import main as aquarom


def run(arguments: list[str]) -> None:
    """One CLI call; outputs of an earlier demo are replaced (--force)."""
    if arguments[0] in ("shapes", "simulate", "compare", "optimize"):
        arguments = arguments + ["--force"]
    print(f"\n$ aquarom {' '.join(arguments)}", flush=True)
    code = aquarom(arguments)
    if code != 0:
        sys.exit(code)


GALLERY = Path(__file__).resolve().parents[1] / "docs" / "gallery"
GALLERY_FILES = {"so1-shapes/shapes.png": "so1_shapes.png", "nominal-fom/trajectory.png": "nominal_trajectory.png",
                 "nominal-compare/compare.png": "nominal_rom_vs_fom.png", "so1-optimize/cost.png": "so1_cost.png",
                 "so1-optimize/start_vs_optimal.png": "so1_start_vs_optimal.png",
                 "so1-optimal-fom/animation.gif": "so1_optimal_swimming.gif"}


def refresh_gallery(out: Path) -> None:
    """Copy the pictures the manual's gallery (docs/gallery.md) shows from this demo run."""
    GALLERY.mkdir(parents=True, exist_ok=True)
    for source, name in GALLERY_FILES.items():
        shutil.copyfile(out / source, GALLERY / name)


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("results/demo"))
    out = parser.parse_args().out
    run(["mesh", "nominal"])
    run(["shapes", "so1", "--out", str(out / "so1-shapes")])
    run(["simulate", "nominal", "--model", "fom", "--level", "1", "--out", str(out / "nominal-fom")])
    run(["compare", "nominal", "--model", "rom", "--level", "1", "--out", str(out / "nominal-compare"),
         "--no-progress"])
    run(["optimize", "so1", "--level", "1", "--out", str(out / "so1-optimize")])
    optimum = json.loads((out / "so1-optimize" / "summary.json").read_text())["optimum"]
    design = [argument for name, value in optimum.items() for argument in ("--xi", f"{name}={value}")]
    run(["simulate", "so1", "--level", "1", *design, "--out", str(out / "so1-optimal-fom"), "--no-progress"])
    run(["animate", str(out / "so1-optimal-fom")])
    refresh_gallery(out)
    print(f"\ndemo outputs in {out.resolve()}:")
    for path in sorted(out.rglob("*")):
        if path.is_file():
            print(f"  {path}")


if __name__ == "__main__":
    main()
