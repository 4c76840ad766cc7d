"""Mesh convergence of the FOM: per (degree, level) case four quantities, a Richardson reference.

Quantities of the reference fish (SPEC §2, §10): the swimming distance and tail amplitude of the
FOM run, the first natural frequency (head clamped), the static tail deflection with the
muscles at their peak (a_left = A, a_right = -A, head clamped, fully nonlinear) and the tail
station's static compliance under a unit x-force on it (head clamped, B_0 K_0⁻¹ B_0ᵀ: the
quantity a point force has no mesh limit of, SPEC §5).

The reference of each quantity is Richardson's extrapolation of the three finest cases of one
series (one element degree), with the mesh size h = (cells)^(-1/3) (levels are not refined by
a constant ratio):

    f_i = f* + C h_i^p,   i = 1, 2, 3 (coarse → fine),

solved for the observed order p, then f* = f_3 - C h_3^p. The estimated error of f* is
|f* - f_3|, the correction itself (conservative: the extrapolation is usually better than that).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.fem.linear_solver import mumps_solver
from aquarom_fenics.reduction.basis import clamped_stiffness, unit_tail_force, vibration_modes
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.dynamics.simulate import simulate_fom

QUANTITIES = ("distance", "tail_amplitude", "first_frequency", "static_tail_deflection", "tail_compliance")
"""Measured per case; units m, m, Hz, m, m/N."""

DEFAULT_TOLERANCE = 0.03
"""The default (degree, level) is the cheapest whose FOM distance is within 3% of the reference."""

ORDER_RANGE = (0.05, 12.0)
"""Observed orders searched for Richardson's extrapolation."""


@dataclass(frozen=True)
class MeshCase:
    degree: int
    level: int
    cells: int
    dofs: int
    distance: float                  # m
    tail_amplitude: float            # m
    first_frequency: float           # Hz
    static_tail_deflection: float    # m, tail y
    tail_compliance: float           # m/N, tail station x under a unit x-force on it
    wall_time: float                 # s, the FOM run (set-up and time integration)


def measure(scene: Scene, fish: Fish | None = None) -> MeshCase:
    """The four quantities of the scene's nominal fish on its mesh level and element degree."""
    fish = fish or load_fish(scene)
    started = time.perf_counter()
    run = simulate_fom(scene, fish=fish, progress=False, keep_model=True)
    wall_time = time.perf_counter() - started
    model = run.model
    try:
        if not run.completed:
            raise RuntimeError(f"FOM of degree {scene.mesh.degree}, level {scene.mesh.level} stopped: {run.error}")
        stiffness = clamped_stiffness(model)
        _, frequencies = vibration_modes(model, stiffness, 1)
        stiffness.destroy()
        peak = scene.actuation.amplitude
        deflection = model.spine_values(model.static_response(peak, -peak))[0, 1]
        compliance = tail_compliances(model)["station" if model.station_averages is not None else "node"]
    finally:
        model.destroy()
    return MeshCase(scene.mesh.degree, scene.mesh.level, run.n_cells, run.n_dofs, float(run.distance),
                    float(run.tail_amplitude), float(frequencies[0]), float(deflection), float(compliance),
                    wall_time)


def tail_compliances(model: FullOrderModel) -> dict[str, float]:
    """Static x-compliance [m/N] at rest, head clamped, under a unit x-force: ``node`` of the tail node
    (e_tail,xᵀ K_0⁻¹ e_tail,x) and, with stations, ``station`` of the tail station (B_0 K_0⁻¹ B_0ᵀ e_x)."""
    stiffness = clamped_stiffness(model)
    solver = mumps_solver(model.comm)
    solver.setOperators(stiffness)
    forces = {"node": unit_tail_force(model, nodal=True)}
    if model.station_averages is not None and model.thrust is not None:
        forces["station"] = unit_tail_force(model)
    try:
        compliances = {}
        for name, force in forces.items():
            force[model.clamped_dofs] = 0.0
            compliances[name] = model.dot(force, model.solve_with(solver, force))
    finally:
        solver.destroy()
        stiffness.destroy()
    return compliances


def richardson(cells, values) -> dict:
    """Reference value, observed order and estimated error from the three finest cases.

    ``cells`` and ``values`` per case of one series; h = cells^(-1/3). The order p solves
    (f_1 - f_2)/(f_2 - f_3) = (h_1^p - h_2^p)/(h_2^p - h_3^p) (bisection in ORDER_RANGE); when the
    differences change sign or no order in range fits, the finest value is returned with the
    last difference as its error and order None.
    """
    order = np.argsort(cells)[-3:]
    h = np.asarray(cells, dtype=float)[order] ** (-1.0 / 3.0)
    f = np.asarray(values, dtype=float)[order]
    fallback = {"value": float(f[-1]), "observed_order": None, "estimated_error": float(abs(f[-1] - f[-2])),
                "series_cells": [int(c) for c in np.asarray(cells)[order]]}
    if len(f) < 3 or (f[0] - f[1]) * (f[1] - f[2]) <= 0.0:
        return fallback
    ratio = (f[0] - f[1]) / (f[1] - f[2])

    def mismatch(p):
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - ratio

    low, high = ORDER_RANGE
    if mismatch(low) * mismatch(high) > 0.0:
        return fallback
    for _ in range(200):
        middle = 0.5 * (low + high)
        if mismatch(low) * mismatch(middle) <= 0.0:
            high = middle
        else:
            low = middle
    p = 0.5 * (low + high)
    constant = (f[1] - f[2]) / (h[1] ** p - h[2] ** p)
    value = f[2] - constant * h[2] ** p
    return {"value": float(value), "observed_order": float(p), "estimated_error": float(abs(value - f[2])),
            "series_cells": fallback["series_cells"]}


def reference_series(cases: list[MeshCase]) -> list[MeshCase]:
    """The series extrapolated: the highest degree with at least three levels."""
    for degree in sorted({case.degree for case in cases}, reverse=True):
        series = [case for case in cases if case.degree == degree]
        if len(series) >= 3:
            return series
    raise ValueError("mesh convergence needs at least three levels of one element degree")


def mesh_convergence(cases: list[MeshCase], tolerance: float = DEFAULT_TOLERANCE) -> dict:
    """``reference`` per quantity, ``rows`` per case with the relative distance error, ``default``."""
    series = reference_series(cases)
    reference = {name: richardson([case.cells for case in series], [getattr(case, name) for case in series])
                 | {"degree": series[0].degree} for name in QUANTITIES}
    rows = []
    for case in sorted(cases, key=lambda case: (case.degree, case.level)):
        row = asdict(case)
        for name in QUANTITIES:
            row[f"{name}_error"] = getattr(case, name) / reference[name]["value"] - 1.0
        row["relative_error_distance"] = row["distance_error"]
        rows.append(row)
    within = [row for row in rows if abs(row["relative_error_distance"]) <= tolerance]
    default = None
    if within:
        best = min(within, key=lambda row: row["wall_time"])
        default = {"degree": best["degree"], "level": best["level"],
                   "relative_error_distance": best["relative_error_distance"], "wall_time": best["wall_time"]}
    return {"reference": reference, "rows": rows, "default": default, "tolerance": tolerance}
