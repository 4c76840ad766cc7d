"""Regenerate the shipped fish meshes meshes/fish_l<level>.msh from their recipe meshes/fish.toml.

    .venv/bin/python scripts/fish_meshes.py              # every level
    .venv/bin/python scripts/fish_meshes.py 1 2          # levels 1 and 2
    .venv/bin/python scripts/fish_meshes.py --check      # exit 1 if a shipped file differs from its recipe

Each file is gmsh format 4.1 (ASCII) with the volume physical groups head, left_1 … left_n,
right_1 … right_n (numbered from the tail, as the block's: left_1/right_1 the rearmost pair, left_n/right_n
on the head side), body, and the unions left_muscle and right_muscle. The recipe's number of cells
per level is checked against what gmsh made (a different gmsh may mesh differently).
"""
from __future__ import annotations

import argparse
import filecmp
import sys
import tempfile
from pathlib import Path

from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish_recipe import (FISH_LEVELS, FISH_RECIPE, fish_atoms, fish_regions, fish_unions,
                                                 generate_fish, shipped_fish_path, write_msh)


def write_level(level: int, path: Path) -> int:
    """Generate a level and write it to ``path``; its number of cells."""
    mesh = generate_fish(level)
    regions = fish_regions()
    write_msh(mesh, path, fish_atoms(regions), fish_unions(regions))
    return len(mesh.cells)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("levels", nargs="*", type=int, default=list(FISH_LEVELS), help="levels (default: all)")
    parser.add_argument("--check", action="store_true", help="compare with the shipped files, write nothing")
    args = parser.parse_args(argv)
    differing = 0
    try:
        for level in args.levels:
            target = shipped_fish_path(level)
            with tempfile.TemporaryDirectory() as folder:
                fresh = Path(folder) / target.name
                cells = write_level(level, fresh)
                expected = FISH_RECIPE["levels"][str(level)]["cells"]
                note = "" if cells == expected else f" (the recipe says {expected}: update meshes/fish.toml)"
                if args.check:
                    same = target.is_file() and filecmp.cmp(fresh, target, shallow=False)
                    differing += not same
                    print(f"level {level}: {cells} cells, {target.name} {'matches' if same else 'DIFFERS'}{note}")
                else:
                    target.write_bytes(fresh.read_bytes())
                    print(f"level {level}: {cells} cells, wrote {target}{note}")
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
