"""``aquarom export``: the design's body as closed STL surfaces (one, or one per region) or a tagged
volume mesh (.msh, .vtu), checked before anything is written (``geometry.export``)."""
from __future__ import annotations

from pathlib import Path

from mpi4py import MPI

from aquarom_fenics.cli.inputs import checked, design_values, load_scene, run_design, say
from aquarom_fenics.cli.outputs import claim_output, claim_output_file, shown
from aquarom_fenics.errors import InputError


def export_inputs(args):
    """``export``: the scene, the --xi design, --out (a .stl, .msh or .vtu file; a folder with
    --regions) and --units."""
    from aquarom_fenics.geometry.export import SUFFIXES

    scene = load_scene(args)
    xi = design_values(args, scene)
    if args.out is None:
        raise InputError("--out is required: a .stl, .msh or .vtu file (a folder with --regions)")
    suffix = args.out.suffix.lower()
    if args.regions and suffix:
        raise InputError(f"--out {args.out}: with --regions the output is a folder of one STL per region; "
                         "give a folder name without a suffix")
    if not args.regions and suffix not in SUFFIXES:
        raise InputError(f"--out {args.out}: give a file ending in {', '.join(SUFFIXES)} "
                         "(or a folder with --regions)")
    return scene, xi


@checked(export_inputs)
def run_export(args, scene, xi) -> int:
    from aquarom_fenics.geometry.export import checked_surface, design_body, region_file_names, stl_bytes
    from aquarom_fenics.geometry.fish import load_fish

    fish = load_fish(scene)
    body = design_body(scene, fish, run_design(scene, xi))
    surface = checked_surface(body.points, body.cells, "body")          # checked whatever the target
    if args.regions:
        if not body.regions:
            raise InputError(f"--regions: the mesh of scene {scene.source} has no tagged regions "
                             f"({scene.regions.head} and the muscles); nothing to split")
        names = region_file_names(body.regions)
        surfaces = {name: checked_surface(body.points, body.cells[cells], f"region {name}")
                    for name, cells in body.regions.items()}
        out = claim_output(args, args.out)
        for name, part in surfaces.items():
            write_file(out / names[name], stl_bytes(part, args.units))
        summarise(args, surface, args.units, {name: part.volume for name, part in surfaces.items()})
        say(f"wrote {len(surfaces)} surfaces in {shown(args, out)}/ ({', '.join(names.values())})")
        return 0
    data = target_bytes(args, body, surface)
    from aquarom_fenics.geometry.export import is_export_file

    claim_output_file(args, args.out, is_export_file, "body.stl")
    write_file(args.out, data)
    summarise(args, surface, args.units)
    say(f"wrote {args.out}")
    return 0


def target_bytes(args, body, surface) -> bytes:
    """The file's content for the suffix of --out: an STL surface or a tagged volume mesh."""
    from aquarom_fenics.geometry.export import stl_bytes, volume_mesh_bytes

    suffix = args.out.suffix.lower()
    if suffix == ".stl":
        return stl_bytes(surface, args.units)
    return volume_mesh_bytes(body, args.units, suffix)


def write_file(path: Path, data: bytes) -> None:
    """Write ``data`` atomically on rank 0."""
    from aquarom_fenics.io.persistence import write_bytes_atomic

    if MPI.COMM_WORLD.rank == 0:
        write_bytes_atomic(path, data)
    MPI.COMM_WORLD.barrier()


def summarise(args, surface, units: str, regions: dict[str, float] | None = None) -> None:
    """Print the enclosed volume and bounding box in ``units`` (and each region's volume)."""
    from aquarom_fenics.geometry.export import UNITS, bounding_box

    factor = UNITS[units]
    lower, upper = bounding_box(surface.points * factor)
    say(f"body: {len(surface.triangles)} triangles, closed, manifold, outward, no self-intersection; "
        f"volume {surface.volume * factor ** 3:.6e} {units}³")
    say("bounding box: " + ", ".join(f"{axis} {low:.6g} to {high:.6g}" for axis, low, high in zip("xyz", lower, upper))
        + f" {units}")
    for name, volume in (regions or {}).items():
        say(f"  {name:<14} volume {volume * factor ** 3:.6e} {units}³")
    if regions:
        total = sum(regions.values())
        say(f"  regions' sum   volume {total * factor ** 3:.6e} {units}³ "
            f"({abs(total / surface.volume - 1):.1e} relative to the body)")
