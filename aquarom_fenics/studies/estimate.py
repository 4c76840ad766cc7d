"""Time and memory estimates of the runs of a study, on the cells the mesh recipe gives each level.

The cells of a generated block's level are those of ``meshes/block.toml`` (through
:data:`aquarom_fenics.geometry.block.LEVEL_TARGET_CELLS`); an external mesh counts as the
reference mesh. Times come from the benchmark JSON files under results/bench/ when they exist
(power laws in the number of cells fitted to them), otherwise from the reference figures below,
measured on 2 cores. The dry-run plan (:mod:`aquarom_fenics.studies.plan`), the sweep's estimate
and the validation runner's order of cases (longest first) read them here.
"""
from __future__ import annotations

import json

import numpy as np

from aquarom_fenics.geometry.block import LEVEL_TARGET_CELLS
from aquarom_fenics.io.paths import bench_results
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.scene_muscles import planned_vibration_modes, stroke_amplitude
from aquarom_fenics.optimization.prom_builder import screens_tail
from aquarom_fenics.physics.muscle import ActivationLaw
from aquarom_fenics.reduction.basis import candidate_labels, response_labels, stroke_labels
from aquarom_fenics.verification.local_stability import tail_sample_steps

# The fallback cost law when no benchmark file exists: the FOM's seconds per 100 steps at
# REFERENCE_CELLS, growing as cells^REFERENCE_FOM_EXPONENT (the figures' origin: docs/devlog.md).
REFERENCE_CELLS = 7944
REFERENCE_FOM_SECONDS = 10.3
REFERENCE_FOM_EXPONENT = 1.1
QUADRATIC_COST_FACTOR = {1: 1.0, 2: 8.6}
"""Cost of a quadratic mesh against the linear one on the same cells."""
TAIL_SCREEN_SECONDS_PER_STATE = 0.33
"""Seconds of the tail screen per linearised state at the default mesh."""


def level_cells(level: int) -> int:
    """Cells of a generated block at mesh ``level``: the recipe's target (``meshes/block.toml``)."""
    return LEVEL_TARGET_CELLS[level]


def scene_cells(scene: Scene) -> int:
    """Cells the estimates take for a scene: its level's (:func:`level_cells`), or
    :data:`REFERENCE_CELLS` for an external mesh or a level the recipe lacks."""
    if scene.mesh.file or scene.mesh.level not in LEVEL_TARGET_CELLS:
        return REFERENCE_CELLS
    return level_cells(scene.mesh.level)


REDUCED_SOLVE_SECONDS = 0.2
"""One reduced solve with its sensitivities [s] (0.1 s without), at any mesh."""
TAYLOR_ORDER_2_FACTOR = 4.0
"""A PROM build with second-order Taylor terms in ξ against first order (the validation's measure)."""


def case_seconds(kind: str, scene: Scene, parametric: bool = False) -> float:
    """Estimated wall time [s] of a validation case of ``kind``: a FOM run (``fom``, ``mpi``, ``mesh``)
    or a reduced model (``reduced``: a build, the PROM's with ``parametric``, and its solves)."""
    cells = scene_cells(scene)
    degree = scene.mesh.degree
    if kind in ("fom", "mpi", "mesh"):
        return fom_seconds(cells, scene.n_steps, degree)
    p = len(scene.shapes) if parametric else 0
    order = TAYLOR_ORDER_2_FACTOR if p and scene.reduction.taylor_order == 2 else 1.0
    return order * prom_build_seconds(cells, p, degree) + REDUCED_SOLVE_SECONDS * scene.n_steps / 100.0




def power_law_fit(sizes, times) -> dict | None:
    """Least squares of log t = log c + e log n over the positive, finite pairs: exponent e, prefactor c
    and the number of points (None below two distinct sizes)."""
    sizes, times = np.asarray(sizes, dtype=float), np.asarray(times, dtype=float)
    keep = np.isfinite(sizes) & np.isfinite(times) & (sizes > 0) & (times > 0)
    if np.unique(sizes[keep]).size < 2:
        return None
    exponent, intercept = np.polyfit(np.log(sizes[keep]), np.log(times[keep]), 1)
    return {"exponent": float(exponent), "prefactor": float(np.exp(intercept)), "points": int(keep.sum())}


def tail_screen_seconds(scene: Scene) -> float:
    """Estimated time of one tail screen [s] (0 when the optimisers skip it): the states of the last
    stroke at the default mesh's cost per state, whatever the mesh."""
    return tail_sample_steps(scene).size * TAIL_SCREEN_SECONDS_PER_STATE if screens_tail(scene) else 0.0


def fom_seconds(cells: int, steps: int, degree: int = 1) -> float:
    """Estimated FOM wall time [s] for ``steps`` Newmark steps."""
    runs = _bench_runs("fom.json", lambda r: r.get("ranks") == 1 and "failed" not in r
                       and r.get("degree", 1) == degree)
    fit = power_law_fit([r["cells"] for r in runs], [r["time_integration"] for r in runs])
    if fit:
        return fit["prefactor"] * cells ** fit["exponent"] * steps / 100
    return (QUADRATIC_COST_FACTOR[degree] * REFERENCE_FOM_SECONDS * (cells / REFERENCE_CELLS) ** REFERENCE_FOM_EXPONENT
            * steps / 100)


def prom_build_seconds(cells: int, parameters: int, degree: int = 1) -> float:
    runs = _bench_runs("prom.json", lambda r: r["parameters"] == parameters and r.get("degree", 1) == degree)
    fit = power_law_fit([r["cells"] for r in runs], [r["build_time"] for r in runs])
    if fit:
        return fit["prefactor"] * cells ** fit["exponent"]
    return QUADRATIC_COST_FACTOR[degree] * (0.5 + 0.33 * parameters) * cells / REFERENCE_CELLS


EIGEN_SECONDS_PER_MODE = 0.02
"""SLEPc's generalised eigensolve per vibration mode at level 1, degree 1 (1232 cells: 0.019 s for one)."""
STATIC_SOLVE_SECONDS = 0.01
"""One static solve of a modal derivative at level 1, degree 1 (1232 cells)."""
TENSOR_SECONDS = 0.1
"""The internal-force tensors of an 8-vector basis at level 1, degree 1; they grow as m⁴ and with the cells."""
LEVEL_1_CELLS = 1232


def basis_seconds(scene: Scene, cells: float, parametric: bool) -> float:
    """Estimated time [s] of the steps of a PROM build that grow with the basis: the eigensolve of the
    n_vm vibration modes (∝ n_vm × cells), the static solves of the modal derivatives (∝ their
    count × cells) and the cubic internal-force tensors (∝ m⁴ × cells), all from level-1 figures."""
    modes = planned_vibration_modes(scene)
    size = len(expected_basis(scene, parametric))
    derivatives = modes * (modes + 1) // 2 if scene.reduction.modal_derivatives else 0
    scale = QUADRATIC_COST_FACTOR[scene.mesh.degree] * cells / LEVEL_1_CELLS
    return scale * (EIGEN_SECONDS_PER_MODE * modes + STATIC_SOLVE_SECONDS * derivatives
                    + TENSOR_SECONDS * (size / 8) ** 4)


def _bench_runs(name: str, keep) -> list[dict]:
    folder = bench_results()
    path = folder / name if folder else None
    if path is None or not path.exists():
        return []
    try:
        return [r for r in json.loads(path.read_text())["runs"] if keep(r)]
    except (json.JSONDecodeError, KeyError):
        return []


def actuation_modes(scene: Scene) -> int:
    """Number of actuation modes of the basis: the independent activation patterns of the muscles
    (``ActivationLaw.patterns``: one per frequency, two where its phases are not all 0° or 180°);
    0 with basis = 'paper' or without actuation."""
    reduction = scene.reduction
    actuated = reduction.basis == "default" and scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0
    return len(ActivationLaw.of(scene).patterns()) if actuated else 0


def expected_basis(scene: Scene, parametric: bool, modes: int | None = None) -> list[str]:
    """Candidate basis vectors (SPEC §7); dependent ones are dropped at build time. ``modes``: that
    many actuation modes instead of the scene's."""
    reduction = scene.reduction
    count = actuation_modes(scene) if modes is None else modes
    responses = response_labels(reduction.basis == "default" and reduction.response_vectors, count,
                                scene.fluid.thrust)
    responses += stroke_labels(reduction.basis == "default" and stroke_amplitude(scene) > 0, count,
                               scene.fluid.thrust, responses,
                               len(scene.shapes) if parametric and reduction.stroke_sensitivities else 0)
    return candidate_labels(planned_vibration_modes(scene), reduction.modal_derivatives,
                            len(scene.shapes) if parametric else 0, count, responses)


def reduced_tensor_bytes(scene: Scene, parametric: bool = True, modes: int | None = None) -> float:
    """Memory of the reduced internal-force tensor [bytes]: 8 m⁴ for its cubic part, times 1 + p
    for its first ξ-derivatives (and + p² at Taylor order 2), m the candidate basis size (with
    ``modes`` actuation modes instead of the scene's)."""
    size = len(expected_basis(scene, parametric, modes))
    p = len(scene.shapes) if parametric else 0
    return 8.0 * size ** 4 * (1 + p + (p * p if scene.reduction.taylor_order == 2 else 0))
