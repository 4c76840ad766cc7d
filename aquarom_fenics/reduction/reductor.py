"""Build a PROM from the FOM's forms (SPEC §7–§8): basis, then every reduced tensor.

The design ξ_c is pulled back to the nominal mesh (F_1 = I + ∇u_ξ with the exact shape fields at
the quadrature points, SPEC §4), so the ξ-derivatives of every form are UFL derivatives with
respect to the shape coefficients ∇u_ξ (and u_ξ for the skin) in the directions ∇U_k (U_k). Only
what the scene uses is built; the log says what was built, what was skipped and how long it took.
"""
from __future__ import annotations

import logging
import time

import numpy as np
from mpi4py import MPI

from aquarom_fenics import __version__
from aquarom_fenics.reduction.basis import ReductionBasis, build_basis
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.reduction.kept_model import KEPT_MODEL
from aquarom_fenics.physics.thrust_full_order import check_spine_is_not_moved
from aquarom_fenics.reduction.projection import Projector
from aquarom_fenics.reduction.prom import Observation, ReducedModel
from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")


def build_prom(scene: Scene, xi_center=None, fish: Fish | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
               parametric: bool = True, basis_from: ReducedModel | None = None, head_share: bool = False) -> ReducedModel:
    """The PROM of ``scene`` centred on ξ_c (a ROM, without ξ-terms, when ``parametric`` is False).

    Each force term of the FOM projects itself on the basis (``reduce``). With ``basis_from`` the
    basis is that PROM's (same scene and mesh), not built again: only a subspace is reused, every
    tensor and its ξ-derivatives are projected at ξ_c, so the PROM is exact for ξ_c on that subspace.
    With ``head_share`` the basis gets the head's static responses as it swims (``head_vectors``) and the
    head cells' share of the elastic tensors is projected too (``head_elastic``).
    """
    started = time.perf_counter()
    timings = {}
    fish = fish or load_fish(scene, comm)
    xi_center = fish.parameter_vector(xi_center)
    warning = material_law_warning(scene)
    if warning:
        log.warning("%s", warning)
    with KEPT_MODEL.model_at(scene, fish, xi_center, comm) as fom:
        timings["fom_setup"] = time.perf_counter() - started
        return _reduced_model(scene, fish, fom, xi_center, comm, parametric, basis_from, started, timings,
                              head_share)


def _reduced_model(scene: Scene, fish: Fish, fom: FullOrderModel, xi_center: np.ndarray, comm: MPI.Comm,
                   parametric: bool, basis_from: ReducedModel | None, started: float, timings: dict,
                   head_share: bool = False) -> ReducedModel:
    """The PROM of ``build_prom`` on the model ``fom`` at ξ_c."""
    p = len(fish.shape_names) if parametric else 0
    order = scene.reduction.taylor_order if p else 0
    if scene.fluid.thrust and scene.fluid.stations == "nodes":
        check_spine_is_not_moved(fish)

    basis = build_basis(fom, p) if basis_from is None else reused_basis(fom, basis_from)
    if head_share and basis_from is None:
        from aquarom_fenics.reduction.head_vectors import with_head_responses

        basis = with_head_responses(fom, basis)         # the head strains: its factor enters the tensors
    vectors = basis.vectors
    timings.update(basis.timings)
    projector = Projector(fom, vectors, p, order)
    mark = time.perf_counter()
    elastic = fom.elastic.reduce(projector)
    head_elastic = fom.elastic.reduce(projector, head_only=True) if head_share else None
    timings["internal_force_tensors"] = time.perf_counter() - mark

    mark = time.perf_counter()
    inertia = fom.inertia.reduce(projector)
    muscle = fom.muscle.reduce(projector)
    drag = fom.drag.reduce(projector) if fom.drag is not None else None
    thrust = fom.thrust.reduce(projector) if fom.thrust is not None else None
    built, skipped = ["mass", "internal force (cubic)", "centre of mass"], []
    optional = (("actuation", fom.muscle.on, "k or A is zero"), ("drag", drag is not None, "off in the scene"),
                ("thrust", thrust is not None, "off in the scene"))
    for name, present, reason in optional:
        if present:
            built.append(f"thrust (exact on the reduced {'spine' if scene.fluid.stations == 'nodes' else 'stations'})"
                         if name == "thrust" else name)
        else:
            skipped.append(f"{name} ({reason})")
    if not p:
        skipped.append("ξ-terms (no shape parameters)" if parametric else "ξ-terms (plain ROM)")
    timings["other_tensors"] = time.perf_counter() - mark

    head_x_row, tail_y_row, tail_x_row = fom.observation_rows(vectors)
    observation = Observation(head_x_row=head_x_row, tail_y_row=tail_y_row, tail_x_row=tail_x_row)
    timings["total"] = time.perf_counter() - started
    m = vectors.shape[1]
    if comm.rank == 0:
        origin = ("built" if basis_from is None else
                  f"reused from the PROM at {dict(zip(basis_from.shape_names, np.round(basis_from.xi_center, 6).tolist()))}")
        log.info("PROM: m = %d (%s), p = %d, Taylor order %d; basis %s; built %s; skipped %s; %.2f s (FOM set-up "
                 "%.2f s, basis %.2f s, internal force %.2f s, other tensors %.2f s)", m, ", ".join(basis.labels), p,
                 order, origin, ", ".join(built), ", ".join(skipped) or "nothing", timings["total"],
                 timings["fom_setup"], timings["basis_total"], timings["internal_force_tensors"],
                 timings["other_tensors"])
    prom = ReducedModel(
        scene_hash=scene.hash, prom_hash=scene.prom_hash, software_version=__version__, shape_names=list(fish.shape_names[:p]),
        design_point=dict(zip(fish.shape_names, map(float, xi_center))),
        xi_center=xi_center[:p], validity_radius=validity_radii(scene, elastic, inertia, p), labels=basis.labels,
        basis=np.stack([fom.nodal_displacement(vectors[:, j]) for j in range(m)], axis=-1), dropped=basis.dropped,
        frequencies=basis.frequencies, elastic=elastic, muscle=muscle, inertia=inertia, drag=drag, thrust=thrust,
        observation=observation, cells=fom.n_cells, dofs=fom.n_global_dofs, timings=timings,
        head_elastic=head_elastic)
    return prom


def material_law_warning(scene: Scene) -> str | None:
    """One line for a reduced model of a law its polynomial tensors do not represent exactly: the
    internal force is sampled from the law's small-strain expansion (``fem/cellwise.py``), which is the
    law itself for SVK only; on Neo-Hookean scenes the reduced models were measured more than 3 % from
    the FOM's distance (docs/theory/material-law.md). None for SVK."""
    if scene.material.law == "svk":
        return None
    return (f"[material] law = \"{scene.material.law}\": the reduced model's internal force is the law's small-strain "
            "(SVK) expansion, exact for SVK only; on Neo-Hookean it was measured more than 3 % off the FOM's "
            "distance at the SO1-SO3 optima (docs/theory/material-law.md): check its results with the FOM "
            "(aquarom compare)")


def validity_radii(scene: Scene, elastic, inertia, p: int, change: float | None = None) -> np.ndarray:
    """The PROM's validity radius per parameter [1]: the scene's r_k (``validity_fraction`` or the shape's
    own ``radius``), with c = ``change`` (default ``[reduction] validity_change``) > 0 capped at the design it
    is built on,

        r_k ≤ c / s_k,   s_k = max_T ‖∂T/∂ξ_k‖_F / ‖T‖_F,   T ∈ {K1, K2, K3 of f_int,r; M_r},

    so that to first order no internal-force or mass tensor changes by more than the fraction c across
    the radius. The tensors depend on ξ through F_1⁻¹ and det F_1; where a design thins a region they vary
    like powers of its local thickness and s_k, with the error of the Taylor in ξ, grows (CO scene:
    s_k ≤ 1.1 at ξ = 0, up to 8 at the corner, where det F_1 falls to 0.10 at the tail's edges)."""
    radius = np.array(scene.validity_radii()[:p], dtype=float)
    change = scene.reduction.validity_change if change is None else change
    if change <= 0 or p == 0:
        return radius
    rates = np.zeros(p)
    for taylor in (elastic.linear, elastic.quadratic, elastic.cubic, inertia.mass):
        scale = np.linalg.norm(taylor.constant)
        if taylor.first is None or scale == 0:
            continue
        rates = np.maximum(rates, np.linalg.norm(taylor.first.reshape(p, -1), axis=1) / scale)
    capped = np.minimum(radius, np.divide(change, rates, out=np.full(p, np.inf), where=rates > 0))
    if np.any(capped < radius):
        log.info("PROM: validity radius %s, capped where the tensors change fast (relative ξ-derivatives %s, "
                 "change = %g)", np.round(capped, 4).tolist(), np.round(rates, 2).tolist(), change)
    return capped


def reused_basis(fom: FullOrderModel, prom: ReducedModel) -> ReductionBasis:
    """The basis of ``prom`` on the owned dofs of ``fom`` (same mesh); its vectors are Vᵀ M V = I for
    the PROM's own centre, not for the FOM's design (the projected mass M_r carries the difference)."""
    started = time.perf_counter()
    if prom.basis.shape[0] != fom.fish.nodes.points.shape[0] or prom.cells != fom.n_cells:
        raise ValueError(f"the basis to reuse is on a mesh of {prom.basis.shape[0]} nodes, {prom.cells} cells; "
                         f"this model has {fom.fish.nodes.points.shape[0]} nodes, {fom.n_cells} cells")
    vectors = np.column_stack([fom.owned_values(prom.basis[:, :, j]) for j in range(prom.size)])
    return ReductionBasis(vectors, list(prom.labels), list(prom.dropped), np.asarray(prom.frequencies),
                          {"basis_total": time.perf_counter() - started})
