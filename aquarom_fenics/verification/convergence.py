"""Mesh convergence of the FOM: per (degree, level) case four quantities, a Richardson reference.

Quantities of the reference fish (SPEC §2, §10): the swimming distance and tail amplitude of the
FOM run, the first natural frequency (head clamped), the static tail deflection with the
muscles at their peak (a_left = A, a_right = -A, head clamped, fully nonlinear) and the tail
station's static compliance under a unit x-force on it (head clamped, B_0 K_0⁻¹ B_0ᵀ: the
quantity a point force has no mesh limit of, SPEC §5).

The reference of each quantity is a Richardson extrapolation of the three finest cases of one
series (one element degree), with the mesh size h = (cells)^(-1/3) (levels are not refined by
a constant ratio), made safe in the manner of Roache's grid-convergence index:

    f_i = f* + C h_i^p,   i = 1, 2, 3 (coarse → fine),

is solved for the observed order p_obs; the extrapolation uses p = min(p_obs, p_formal), never an
order above the element's formal order for that quantity (FORMAL_ORDER), from the two finest cases:

    f* = f_3 + (f_3 - f_2)/(r^p - 1),   r = h_2/h_3,

and its error bar is F_s |f* - f_3| with the safety factor F_s = 1.25, or F_s = 3 with p = p_formal
when no order is observed (differences changing sign, or no order in ORDER_RANGE fits).
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


SAFETY_FACTOR = {"observed": 1.25, "formal": 3.0}
"""F_s of the error bar: with an observed order (three cases in the asymptotic range), without one."""


def formal_orders(degree: int) -> dict[str, float]:
    """Formal convergence order in h of each quantity for Lagrange elements of ``degree`` k: k + 1 for
    displacement values (distance, tail amplitude, static deflection), 2k for the eigenvalue-like and
    energy-like ones (first frequency, compliance f^T K^-1 f)."""
    displacement, energy = degree + 1.0, 2.0 * degree
    return {"distance": displacement, "tail_amplitude": displacement, "static_tail_deflection": displacement,
            "first_frequency": energy, "tail_compliance": energy}


def observed_order(h, f) -> float | None:
    """p solving (f_1 - f_2)/(f_2 - f_3) = (h_1^p - h_2^p)/(h_2^p - h_3^p) by bisection in ORDER_RANGE;
    None when the differences change sign or vanish, or no order in range fits."""
    if (f[0] - f[1]) * (f[1] - f[2]) <= 0.0:
        return None
    ratio = (f[0] - f[1]) / (f[1] - f[2])

    def mismatch(p):
        return (h[0] ** p - h[1] ** p) / (h[1] ** p - h[2] ** p) - ratio

    low, high = ORDER_RANGE
    if mismatch(low) * mismatch(high) > 0.0:
        return None
    for _ in range(200):
        middle = 0.5 * (low + high)
        if mismatch(low) * mismatch(middle) <= 0.0:
            high = middle
        else:
            low = middle
    return 0.5 * (low + high)


def richardson(cells, values, formal_order: float) -> dict:
    """Reference value, observed order, order used and error bar from the three finest cases.

    ``cells`` and ``values`` per case of one series; h = cells^(-1/3). The order used is
    min(observed, ``formal_order``), or ``formal_order`` when none is observed; the error bar is
    F_s × |f* - f_finest| (SAFETY_FACTOR, see the module's docstring).
    """
    order = np.argsort(cells)[-3:]
    h = np.asarray(cells, dtype=float)[order] ** (-1.0 / 3.0)
    f = np.asarray(values, dtype=float)[order]
    series_cells = [int(c) for c in np.asarray(cells)[order]]
    if len(f) < 2:
        raise ValueError("a convergence series needs at least two cases")
    observed = observed_order(h, f) if len(f) >= 3 else None
    used = formal_order if observed is None else min(observed, formal_order)
    safety = SAFETY_FACTOR["formal" if observed is None else "observed"]
    correction = (f[-1] - f[-2]) / ((h[-2] / h[-1]) ** used - 1.0)
    return {"value": float(f[-1] + correction), "observed_order": None if observed is None else float(observed),
            "order_used": float(used), "formal_order": float(formal_order), "safety_factor": safety,
            "estimated_error": float(safety * abs(correction)), "series_cells": series_cells}


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
    formal = formal_orders(series[0].degree)
    reference = {name: richardson([case.cells for case in series], [getattr(case, name) for case in series],
                                  formal[name]) | {"degree": series[0].degree} for name in QUANTITIES}
    rows = []
    for case in sorted(cases, key=lambda case: (case.degree, case.level)):
        row = asdict(case)
        for name in QUANTITIES:
            row[f"{name}_error"] = getattr(case, name) / reference[name]["value"] - 1.0
        row["relative_error_distance"] = row["distance_error"]
        rows.append(row)
    return {"reference": reference, "rows": rows, "default": cheapest_within(rows, tolerance),
            "cheapest_within_1_percent": cheapest_within(rows, 0.01), "tolerance": tolerance}


def cheapest_within(rows: list[dict], tolerance: float) -> dict | None:
    """(degree, level) of the fastest FOM whose distance is within ``tolerance`` of the reference, or None."""
    within = [row for row in rows if abs(row["relative_error_distance"]) <= tolerance]
    if not within:
        return None
    best = min(within, key=lambda row: row["wall_time"])
    return {"degree": best["degree"], "level": best["level"],
            "relative_error_distance": best["relative_error_distance"], "wall_time": best["wall_time"]}
