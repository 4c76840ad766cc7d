"""The start of a gait, measured from FOM runs: wall time, cut steps, Newton iterations per step,
distance and tail amplitude of each run, with the smallest det F and the largest principal
Green–Lagrange strain over the body against time.

The strains are estimated from the vertex displacements the run writes (``displacement.npz``):
F = I + ∇u of the linear interpolant on each tetrahedron, E = ½(FᵀF - I), its largest eigenvalue.
On quadratic elements this is the strain of the vertex values, not of the quadrature points.

Usage (each folder an ``aquarom simulate ... --model fom --out DIR`` run)::

    python scripts/gait_start.py LABEL=DIR [LABEL=DIR ...] [--json results/gait_start.json]

e.g. for the shipped fish wave before and after the automatic start, and the fish's antagonist pair::

    aquarom simulate fish_wave --model fom --set actuation.start_ramp=0 --out results/gait/abrupt
    aquarom simulate fish_wave --model fom --out results/gait/auto
    aquarom simulate fish --model fom --out results/gait/pair
    python scripts/gait_start.py abrupt=results/gait/abrupt auto=results/gait/auto pair=results/gait/pair
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

SUMMARY_KEYS = ("distance", "tail_amplitude", "wall_time", "cut_steps", "mean_newton_iterations", "steps",
                "completed", "stop_reason")


def deformation_gradients(points: np.ndarray, cells: np.ndarray, displacement: np.ndarray) -> np.ndarray:
    """F = I + ∇u of the linear interpolant on each tetrahedron, (cells, 3, 3)."""
    corners = points[cells]                                     # (c, 4, 3)
    edges = (corners[:, 1:] - corners[:, :1]).transpose(0, 2, 1)     # dX: columns are the edges
    moved = displacement[cells]
    du = (moved[:, 1:] - moved[:, :1]).transpose(0, 2, 1)
    return np.eye(3) + du @ np.linalg.inv(edges)


def start_measures(folder: Path) -> dict:
    """The run's summary values and, per saved time, min det F and max principal strain."""
    summary = json.loads((folder / "summary.json").read_text())
    record = {key: summary.get(key) for key in SUMMARY_KEYS}
    record["start_ramp"] = summary.get("scene_values", {}).get("actuation", {}).get("start_ramp")
    data = np.load(folder / "displacement.npz")
    points, cells = data["points"], data["cells"]
    min_det, max_strain = [], []
    for u in data["displacement"]:
        f = deformation_gradients(points, cells, u)
        green = 0.5 * (np.transpose(f, (0, 2, 1)) @ f - np.eye(3))
        min_det.append(float(np.linalg.det(f).min()))
        max_strain.append(float(np.linalg.eigvalsh(green)[:, -1].max()))
    record["time"] = data["time"].tolist()
    record["min_det_f"], record["max_principal_strain"] = min_det, max_strain
    return record


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", metavar="LABEL=DIR")
    parser.add_argument("--json", default="results/gait_start.json")
    args = parser.parse_args(argv)
    runs = {}
    for item in args.runs:
        label, sep, folder = item.partition("=")
        if not sep or not (Path(folder) / "summary.json").is_file():
            print(f"gait_start: {item!r} must be LABEL=DIR of an `aquarom simulate` output folder", file=sys.stderr)
            return 2
        runs[label] = start_measures(Path(folder))
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(runs, indent=1) + "\n")
    for label, run in runs.items():
        t = np.array(run["time"])
        early = t <= 0.5
        print(f"{label}: start_ramp {run['start_ramp']}, distance {100 * run['distance']:.3f} cm, tail amplitude "
              f"{100 * run['tail_amplitude']:.3f} cm, {run['wall_time']:.1f} s, {run['cut_steps']} cut steps, "
              f"{run['mean_newton_iterations']:.2f} Newton/step; min det F {min(run['min_det_f']):.4f} "
              f"(t <= 0.5 s: {min(np.array(run['min_det_f'])[early]):.4f}), max principal strain "
              f"{max(run['max_principal_strain']):.4f} (t <= 0.5 s: "
              f"{max(np.array(run['max_principal_strain'])[early]):.4f})")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
