"""Your own swimmer from a gmsh script: a tapered body of elliptic cross-section, its head and two
muscles as volume physical groups, written as a .msh file that a scene names with [mesh] file.

    .venv/bin/python scripts/example_own_swimmer.py my_swimmer.msh
    .venv/bin/aquarom mesh my_swimmer.toml        # a scene with [mesh] file = "my_swimmer.msh"

Plain gmsh Python API (OpenCASCADE kernel), nothing of the toolkit: the steps any mesher must take
(docs/your_own_swimmer.md). The shipped fish (meshes/fish.toml) is made the same way, with exact
mirror symmetry added.
"""
import argparse
import math

import gmsh

LENGTH = 0.20            # m, along x; head face at x = 0, tail face at x = -LENGTH
HALF_WIDTH = 0.02        # m, largest semi-axis along y
HALF_HEIGHT = 0.05       # m, largest semi-axis along z
HEAD = 0.30              # the head: x >= -0.30 L
MUSCLES = (-0.90, -0.30) # the muscles: -0.90 L < x < -0.30 L, left y > 0, right y < 0
SIZE = 0.012             # m, element size


def semi_axes(s: float) -> tuple[float, float]:
    """(b, c) [m] of the ellipse at s = -x/L: a smooth taper, blunt at both ends (the head and tail
    faces must be faces, not points)."""
    thickness = math.sin(math.pi * (0.08 + 0.8 * s)) ** 0.6 * (1.0 - 0.5 * s)
    return HALF_WIDTH * thickness, HALF_HEIGHT * (0.45 + 0.55 * thickness)


def body(occ) -> list:
    """The lofted body, built along z (gmsh's ellipses lie in planes z = const with their major axis
    along x) and turned by -90° about y, so that (x, y, z) ← (-z, y, x): the head at x = 0."""
    wires = []
    for k in range(21):
        s = k / 20
        b, c = semi_axes(s)
        wires.append(occ.addWire([occ.addEllipse(0.0, 0.0, s * LENGTH, c, b)]))
    solid = occ.addThruSections(wires, makeSolid=True, makeRuled=False)
    occ.rotate(solid, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -math.pi / 2)
    return solid


def pieces(occ, solid) -> list:
    """The body cut into pieces by the planes y = 0 and z = 0 (so that the body axis and the skin's
    top line on y = 0 are lines of mesh edges) and by the region interfaces x = -0.30 L, -0.90 L
    (so that the mesh conforms to the regions): one intersection with a box per piece, then one
    fragment, which makes the pieces share their faces."""
    cuts = [-LENGTH, MUSCLES[0] * LENGTH, -HEAD * LENGTH, 0.0]
    reach = 1.0
    parts = []
    for rear, front in zip(cuts[:-1], cuts[1:]):
        for y0 in (-reach, 0.0):
            for z0 in (-reach, 0.0):
                box = occ.addBox(rear, y0, z0, front - rear, reach, reach)
                part, _ = occ.intersect(solid, [(3, box)], removeObject=False, removeTool=True)
                parts += part
    occ.remove(solid, recursive=True)
    parts, _ = occ.fragment(parts[:1], parts[1:])
    return parts


def region(x: float, y: float) -> str:
    """The region of a piece with centre of mass (x, y)."""
    if x > -HEAD * LENGTH:
        return "head"
    if MUSCLES[0] * LENGTH < x < MUSCLES[1] * LENGTH:
        return "left_muscle" if y > 0 else "right_muscle"
    return "body"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="the .msh file to write")
    args = parser.parse_args()
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("my_swimmer")
        occ = gmsh.model.occ
        parts = pieces(occ, body(occ))
        occ.synchronize()
        groups = {}
        for dim, tag in parts:
            x, y, _ = occ.getCenterOfMass(dim, tag)
            groups.setdefault(region(x, y), []).append(tag)
        for name, tags in groups.items():        # every piece in a volume group: gmsh saves only those
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, tags), name)
        gmsh.option.setNumber("Mesh.MeshSizeMin", SIZE)
        gmsh.option.setNumber("Mesh.MeshSizeMax", SIZE)
        gmsh.model.mesh.generate(3)              # first-order tetrahedra (Mesh.ElementOrder = 1)
        gmsh.write(args.out)
    finally:
        gmsh.finalize()
    print(f"wrote {args.out}: " + ", ".join(f"{name} ({len(tags)} volumes)" for name, tags in sorted(groups.items())))


if __name__ == "__main__":
    main()
