"""Mesh convergence of the FOM: per (degree, level) case four quantities, a Richardson reference.

Quantities of the reference fish (SPEC §2, §10): the swimming distance and tail amplitude of the
FOM run, the first natural frequency (head clamped), the static tail deflection with the
muscles at their peak (a_left = A, a_right = -A, head clamped, fully nonlinear) and the tail
station's static compliance under a unit x-force on it (head clamped, B_0 K_0⁻¹ B_0ᵀ: the
quantity a point force has no mesh limit of, SPEC §5).

The reference of each quantity is a Richardson extrapolation of one series (one element degree),
with the mesh size h = (cells)^(-1/3) (levels are not refined by a constant ratio), made safe in
the manner of Roache's grid-convergence index. Three consecutive cases

    f_i = f* + C h_i^p,   i = 1, 2, 3 (coarse → fine),

give the observed order p_obs; the extrapolation uses p = min(p_obs, p_formal), never an order
above the element's formal order for that quantity (FORMAL_ORDER), from the finer two:

    f* = f_3 + (f_3 - f_2)/(r^p - 1),   r = h_2/h_3,

with the error bar F_s |f* - f_3|, F_s = 1.25. The three finest cases are used when they show an
order; otherwise the next triple towards the coarse end, provided every finer case lies inside
its error bar (the finer cases check the estimate). A series in which no triple shows an order,
or whose finer cases fall outside the estimate, has no reference (value None, with the reason).
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
    static_tail_deflection: float    # m, the tail's observed y (the tail station's average)
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
        peak_activations = peak * model.muscle.law.patterns()[0]      # the pair: (A, -A)
        deflection = model.observables(model.static_response(*peak_activations))["tail_y"]
        compliance = tail_compliances(model)["station" if model.station_averages is not None else "node"]
    finally:
        model.destroy()
    return MeshCase(scene.mesh.degree, scene.mesh.level, run.n_cells, run.n_dofs, float(run.distance),
                    float(run.tail_amplitude), float(frequencies[0]), float(deflection), float(compliance),
                    wall_time)


def tail_compliances(model: FullOrderModel) -> dict[str, float]:
    """Static x-compliance [m/N] at rest, head clamped, under a unit x-force: ``node`` of the tail node
    (e_tail,xᵀ K_0⁻¹ e_tail,x; on a mesh with nodes on its axis) and, with stations, ``station`` of the tail station (B_0 K_0⁻¹ B_0ᵀ e_x)."""
    stiffness = clamped_stiffness(model)
    solver = mumps_solver(model.comm)
    solver.setOperators(stiffness)
    forces = {"node": unit_tail_force(model, nodal=True)} if model.fish.tags.has_spine else {}
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


SAFETY_FACTOR = 1.25
"""F_s of the error bar: three cases in the asymptotic range (an observed order)."""


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
    """Reference value, observed order, order used and error bar of one series (the module's docstring).

    ``cells`` and ``values`` per case; h = cells^(-1/3). ``value`` is None when the series shows no
    order that its finer cases confirm (``reason`` says why).
    """
    order = np.argsort(cells)
    h = np.asarray(cells, dtype=float)[order] ** (-1.0 / 3.0)
    f = np.asarray(values, dtype=float)[order]
    ordered_cells = [int(c) for c in np.asarray(cells)[order]]
    if len(f) < 3:
        raise ValueError("a convergence series needs at least three cases")
    for end in range(len(f), 2, -1):                  # the finest triple first
        observed = observed_order(h[end - 3:end], f[end - 3:end])
        if observed is None:
            continue
        used = min(observed, formal_order)
        correction = (f[end - 1] - f[end - 2]) / ((h[end - 2] / h[end - 1]) ** used - 1.0)
        value, error = f[end - 1] + correction, SAFETY_FACTOR * abs(correction)
        outside = [int(c) for c, x in zip(ordered_cells[end:], f[end:]) if abs(x - value) > error]
        if outside:
            return _no_reference(formal_order, ordered_cells,
                                 f"the estimate from {ordered_cells[end - 3:end]} cells, {value:.6g} ± {error:.2g}, "
                                 f"misses the finer cases {outside}")
        return {"value": float(value), "observed_order": float(observed), "order_used": float(used),
                "formal_order": float(formal_order), "safety_factor": SAFETY_FACTOR,
                "estimated_error": float(error), "series_cells": ordered_cells[end - 3:end],
                "checked_against_cells": ordered_cells[end:]}
    return _no_reference(formal_order, ordered_cells, "no three consecutive cases show an order (their differences "
                         "change sign, or shrink more slowly than any power of h)")


def _no_reference(formal_order: float, cells: list[int], reason: str) -> dict:
    return {"value": None, "observed_order": None, "order_used": None, "formal_order": float(formal_order),
            "safety_factor": None, "estimated_error": None, "series_cells": cells, "reason": reason}


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
            limit = reference[name]["value"]
            row[f"{name}_error"] = None if limit is None else getattr(case, name) / limit - 1.0
        row["relative_error_distance"] = row["distance_error"]
        rows.append(row)
    return {"reference": reference, "rows": rows, "default": cheapest_within(rows, tolerance),
            "cheapest_within_1_percent": cheapest_within(rows, 0.01), "tolerance": tolerance}


def cheapest_within(rows: list[dict], tolerance: float) -> dict | None:
    """(degree, level) of the fastest FOM whose distance is within ``tolerance`` of the reference, or None."""
    within = [row for row in rows if row["relative_error_distance"] is not None
              and abs(row["relative_error_distance"]) <= tolerance]
    if not within:
        return None
    best = min(within, key=lambda row: row["wall_time"])
    return {"degree": best["degree"], "level": best["level"],
            "relative_error_distance": best["relative_error_distance"], "wall_time": best["wall_time"]}
