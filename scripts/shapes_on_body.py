"""What each catalogue field does on a body that is not a box: the table of the shape page.

    .venv/bin/python scripts/shapes_on_body.py          # prints the table of docs/user/05-shapes.rst

The body is a tapered ellipsoid meshed with gmsh: a unit ball scaled to the semi-axes
(L/2, W/2, H/2) = (0.1, 0.02, 0.05) m, then its cross-sections scaled by 1 - TAPER (x_head - x)/L
(full size at the head end, half at the tail end). The fields are evaluated as the FOM evaluates
them, on coordinates relative to the body's bounding box; the built-in block (level 1, 0.2 × 0.04
× 0.1 m) is the reference. Per field: the share of the body's volume where U ≠ 0 (at the cells'
centroids) and the largest |U| per unit ξ over the nodes, with where it lies (x/L from the head).
"""
from __future__ import annotations

import argparse

import numpy as np

from aquarom_fenics.geometry.block import block_mesh
from aquarom_fenics.geometry.gmsh_session import GMSH_TETRAHEDRON, gmsh_model, points_and_cells_from_gmsh
from aquarom_fenics.geometry.mesh import signed_cell_volumes
from aquarom_fenics.geometry.shapes import CATALOG, shape_displacement
from aquarom_fenics.geometry.tags import FishBox

SEMI_AXES = (0.1, 0.02, 0.05)      # m
TAPER = 0.5
BALL_SIZE = 0.1                    # element size on the unit ball


def tapered_ellipsoid(size: float = BALL_SIZE, taper: float = TAPER) -> tuple[np.ndarray, np.ndarray]:
    """(points [m], cells) of the tapered ellipsoid, head at +x."""
    with gmsh_model("ellipsoid", {"General.Terminal": 0, "General.NumThreads": 1,
                                  "Mesh.CharacteristicLengthMax": size}) as gmsh:
        gmsh.model.occ.addSphere(0.0, 0.0, 0.0, 1.0)
        gmsh.model.occ.synchronize()
        gmsh.model.mesh.generate(3)
        node_tags, coordinates, _ = gmsh.model.mesh.getNodes()
        _, element_nodes = gmsh.model.mesh.getElementsByType(GMSH_TETRAHEDRON)
        points, cells = points_and_cells_from_gmsh(node_tags, coordinates, np.asarray(element_nodes).reshape(-1, 4))
    points = points * np.array(SEMI_AXES)
    length = 2 * SEMI_AXES[0]
    section = 1.0 - taper * (SEMI_AXES[0] - points[:, 0]) / length       # 1 at the head, 1 - taper at the tail
    return points * np.stack([np.ones_like(section), section, section], axis=1), cells


def field_rows(points: np.ndarray, cells: np.ndarray) -> dict[str, tuple[float, float, float]]:
    """{name: (share of the volume where U ≠ 0, largest |U| per unit ξ [m], its x/L)} of every field."""
    box = FishBox.of(points)
    relative = box.relative(points)
    centroids = box.relative(points[cells].mean(axis=1))
    volumes = np.abs(signed_cell_volumes(points, cells))
    rows = {}
    for name in CATALOG:
        moving = np.linalg.norm(shape_displacement(name, centroids, box), axis=1) > 0.0
        size = np.linalg.norm(shape_displacement(name, relative, box), axis=1)
        largest = int(np.argmax(size))
        rows[name] = (volumes[moving].sum() / volumes.sum(), size[largest], relative[largest, 0] / box.length)
    return rows


def table(size: float = BALL_SIZE) -> str:
    """The RST table of the shape page: the tapered ellipsoid against the block."""
    body = field_rows(*tapered_ellipsoid(size))
    block = block_mesh(1)
    reference = field_rows(block.points, block.cells)
    lines = [".. list-table::", "   :header-rows: 1", "",
             "   * - field", "     - volume moved, ellipsoid (block)", "     - largest \\|U\\| [mm], ellipsoid (block)",
             "     - where, x/L"]
    for name in CATALOG:
        share, largest, where = body[name]
        block_share, block_largest, _ = reference[name]
        lines += [f"   * - ``{name}``", f"     - {100 * share:.0f} % ({100 * block_share:.0f} %)",
                  f"     - {1e3 * largest:.1f} ({1e3 * block_largest:.1f})", f"     - {where:.2f}"]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=float, default=BALL_SIZE, help="element size on the unit ball")
    print(table(parser.parse_args().size), end="")


if __name__ == "__main__":
    main()
