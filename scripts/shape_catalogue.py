"""Pictures of the shape catalogue for the manual: one sheet per variation at ξ = -0.5, 0, +0.5.

    .venv/bin/python scripts/shape_catalogue.py            # writes docs/gallery/shapes/NAME.png

Each sheet is `aquarom shapes` of a scene with that single variation on mesh level 1 (a bound the
design check refuses shows the reason instead of a fish).
"""
import argparse
import shutil
import tempfile
from pathlib import Path

from aquarom_fenics.geometry.fish import load_fish
from aquarom_fenics.geometry.shapes import CATALOG
from aquarom_fenics.io.scene import scene_from_dict
from aquarom_fenics.viz.render import render_shape_sheet

GALLERY = Path(__file__).resolve().parents[1] / "docs" / "gallery" / "shapes"
BOUND = 0.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=GALLERY, help="folder of the pictures")
    parser.add_argument("names", nargs="*", default=list(CATALOG), help="variations (default: all)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.names:
        scene = scene_from_dict({"mesh": {"level": 1}, "shapes": {name: {"bounds": [-BOUND, BOUND]}}},
                                source=f"<catalogue {name}>")
        with tempfile.TemporaryDirectory() as folder:
            [sheet] = render_shape_sheet(load_fish(scene), scene, Path(folder))
            shutil.copyfile(sheet, args.out / f"{name}.png")
        print(f"wrote {args.out / f'{name}.png'}", flush=True)


if __name__ == "__main__":
    main()
