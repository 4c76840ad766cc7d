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
import ufl
from mpi4py import MPI

from aquarom_fenics import __version__
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.reduction.basis import build_basis
from aquarom_fenics.fem.cellwise import CellSampler, internal_force_taylor
from aquarom_fenics.errors import InputError
from aquarom_fenics.geometry.fish import Fish, load_fish
from aquarom_fenics.fem.fom import LEFT, RIGHT, FullOrderModel
from aquarom_fenics.reduction.prom import ReducedModel, Taylor
from aquarom_fenics.io.scene import Scene

log = logging.getLogger("aquarom")


class FormTaylor:
    """Taylor coefficients in ξ of a projected form: value, ∂/∂ξ_k and ∂²/∂ξ_k∂ξ_l at ξ_c."""

    def __init__(self, fom: FullOrderModel, form, order: int, shape_directions):
        self.fom = fom
        self.rank = len(form.arguments())
        self.forms = [fx.compile_form(form)]
        if order >= 1:
            first = fom.shape_derivative(form, shape_directions[0])
            self.forms.append(fx.compile_form(first))
        if order >= 2:
            self.forms.append(fx.compile_form(fom.shape_derivative(first, shape_directions[1])))
        self.matrix = fx.create_matrix(self.forms[0]) if self.rank == 2 else None
        self.vector = fx.create_vector(self.forms[0]) if self.rank == 1 else None

    def project(self, order: int, vectors: np.ndarray, lump: bool = False) -> np.ndarray:
        """Vᵀ A V, Vᵀ b or the scalar of the form's derivative of the given order (directions set)."""
        fom, form = self.fom, self.forms[order]
        if self.rank == 0:
            return np.array(fx.assemble_scalar(form, fom.comm))
        if self.rank == 1:
            return fom.comm.allreduce(vectors.T @ fx.assemble_vector_into(self.vector, form), op=MPI.SUM)
        matrix = fx.assemble_matrix_into(self.matrix, form)
        if lump:
            row_sums = matrix.getRowSum()
            matrix.zeroEntries()
            matrix.setDiagonal(row_sums)
            matrix.assemble()
        product = np.column_stack([fom.matvec(matrix, vectors[:, j]) for j in range(vectors.shape[1])])
        return fom.comm.allreduce(vectors.T @ product, op=MPI.SUM)


def taylor_of(form_taylor: FormTaylor, vectors, p, order, directions, **options) -> Taylor:
    """Evaluate a FormTaylor over all ``p`` parameters (and pairs) into a :class:`Taylor`."""
    constant = form_taylor.project(0, vectors, **options)
    first = second = None
    if order >= 1 and p:
        first = []
        for k in range(p):
            directions[0].set_parameter(k)
            first.append(form_taylor.project(1, vectors, **options))
        first = np.stack(first)
    if order >= 2 and p:
        second = np.empty((p, p) + np.shape(constant))
        for k in range(p):
            for l in range(k, p):
                directions[0].set_parameter(k)
                directions[1].set_parameter(l)
                second[k, l] = second[l, k] = form_taylor.project(2, vectors, **options)
    return Taylor(constant, first, second)


def build_prom(scene: Scene, xi_center=None, fish: Fish | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
               parametric: bool = True) -> ReducedModel:
    """The PROM of ``scene`` centred on ξ_c (a ROM, without ξ-terms, when ``parametric`` is False)."""
    started = time.perf_counter()
    timings = {}
    fish = fish or load_fish(scene, comm)
    xi_center = fish.parameter_vector(xi_center)
    fom = FullOrderModel(scene, fish, xi_center, comm=comm)
    timings["fom_setup"] = time.perf_counter() - started
    p = len(fish.shape_names) if parametric else 0
    order = scene.reduction.taylor_order if p else 0
    _check_spine_is_not_moved(fish)

    basis = build_basis(fom, p)
    vectors = basis.vectors
    timings.update(basis.timings)
    mark = time.perf_counter()
    sampler = CellSampler(fom, order)
    internal = internal_force_taylor(sampler, vectors, p, order, comm)
    timings["internal_force_tensors"] = time.perf_counter() - mark

    mark = time.perf_counter()
    directions = sampler.shape_directions
    forms = fom.ufl_forms
    built, skipped = ["mass", "internal force (cubic)", "centre of mass"], []

    def taylor(form, **options):
        return taylor_of(FormTaylor(fom, form, order, directions), vectors, p, order, directions, **options)

    mass = taylor(forms["mass"], lump=scene.material.mass == "lumped")
    moment = taylor(forms["mass_moment_x"])
    total_mass = taylor(forms["total_mass"])
    m = vectors.shape[1]
    if fom.actuation_on:
        negative_actuation = forms["negative_actuation_force"]
        hessian = ufl.derivative(negative_actuation, fom.displacement, ufl.TrialFunction(fom.space))
        constant_parts, linear_parts = [], []
        fx.set_owned_values(fom.displacement, np.zeros(fom.n_owned_dofs))
        for muscle in (LEFT, RIGHT):
            fom.activations[LEFT].value = 1.0 if muscle == LEFT else 0.0
            fom.activations[RIGHT].value = 1.0 if muscle == RIGHT else 0.0
            constant_parts.append(taylor(negative_actuation))
            linear_parts.append(taylor(hessian))
        actuation_constant = _stack_taylor(constant_parts)
        actuation_linear = _stack_taylor(linear_parts)
        built.append("actuation")
    else:
        actuation_constant, actuation_linear = Taylor(np.zeros((2, m))), Taylor(np.zeros((2, m, m)))
        skipped.append("actuation (k or A is zero)")
    if scene.fluid.drag:
        drag = taylor(forms["drag_direction"])
        built.append("drag")
    else:
        drag = Taylor(np.zeros(m))
        skipped.append("drag (off in the scene)")
    if scene.fluid.thrust:
        built.append("thrust (exact on the reduced spine)")
    else:
        skipped.append("thrust (off in the scene)")
    if not p:
        skipped.append("ξ-terms (no shape parameters)" if parametric else "ξ-terms (plain ROM)")
    timings["other_tensors"] = time.perf_counter() - mark

    tags = fish.tags
    spine_rows = np.stack([_gathered_rows(fom, vectors, node) for node in tags.spine_nodes])[:, :2]
    head = _gathered_rows(fom, vectors, tags.head_spine_node)
    tail = _gathered_rows(fom, vectors, tags.tail_node)
    rest = fom.rest_points
    dorsal_z = rest[tags.dorsal_nodes, 2] - tags.box.z_axis
    dorsal_gradient = nodal_rows(fish)[tags.dorsal_nodes, 2, :p]
    timings["total"] = time.perf_counter() - started
    names = list(fish.shape_names[:p])
    radius = np.array(scene.validity_radii()[:p])
    if comm.rank == 0:
        log.info("PROM: m = %d (%s), p = %d, Taylor order %d; built %s; skipped %s; %.2f s (basis %.2f s, "
                 "internal force %.2f s, other tensors %.2f s)", m, ", ".join(basis.labels), p, order,
                 ", ".join(built), ", ".join(skipped) or "nothing", timings["total"], timings["basis_total"],
                 timings["internal_force_tensors"], timings["other_tensors"])
    return ReducedModel(
        scene_hash=scene.hash, software_version=__version__, shape_names=names,
        design_point=dict(zip(fish.shape_names, map(float, xi_center))),
        xi_center=xi_center[:p], validity_radius=radius, labels=basis.labels,
        basis=np.stack([fom.nodal_displacement(vectors[:, j]) for j in range(m)], axis=-1), dropped=basis.dropped,
        frequencies=basis.frequencies, mass=mass,
        stiffness_linear=Taylor(*(t[0] if t is not None else None for t in _pad(internal))),
        stiffness_quadratic=Taylor(*(t[1] if t is not None else None for t in _pad(internal))),
        stiffness_cubic=Taylor(*(t[2] if t is not None else None for t in _pad(internal))),
        actuation_constant=actuation_constant, actuation_linear=actuation_linear, drag=drag,
        mass_moment_x=moment, total_mass=total_mass, spine_rows=spine_rows,
        spine_rest_xy=rest[tags.spine_nodes, :2], dorsal_z=dorsal_z, dorsal_z_gradient=dorsal_gradient,
        head_x_row=head[0], tail_y_row=tail[1],
        rayleigh=(scene.material.rayleigh_alpha, scene.material.rayleigh_beta),
        fluid_density=scene.fluid.density, thrust=scene.fluid.thrust, drag_on=scene.fluid.drag,
        cells=fom.n_cells, dofs=fom.n_global_dofs, timings=timings)


def _pad(taylor_list):
    return list(taylor_list) + [None] * (3 - len(taylor_list))


def _stack_taylor(parts: list[Taylor]) -> Taylor:
    def stacked(name):
        values = [getattr(part, name) for part in parts]
        return None if values[0] is None else np.stack(values, axis=-np.ndim(parts[0].constant) - 1)
    return Taylor(np.stack([part.constant for part in parts]), stacked("first"), stacked("second"))


def _gathered_rows(fom: FullOrderModel, vectors: np.ndarray, node: int) -> np.ndarray:
    """(3, m): the rows of V at one input node, on every rank."""
    blocks, _ = fom.owned_positions(np.array([node]))
    rows = np.zeros((3, vectors.shape[1]))
    if blocks.size:
        rows = vectors[3 * blocks[0]: 3 * blocks[0] + 3]
    return fom.comm.allreduce(rows, op=MPI.SUM)


def nodal_rows(fish: Fish) -> np.ndarray:
    """U as (n_nodes, 3, p)."""
    return fish.shape_matrix.reshape(fish.nodes.points.shape[0], 3, -1)


def _check_spine_is_not_moved(fish: Fish) -> None:
    """The reduced thrust keeps the spine's rest x-y; no catalog shape moves it (all vanish on the axis)."""
    spine_rows = nodal_rows(fish)[fish.tags.spine_nodes, :2]
    moving = np.flatnonzero(np.abs(spine_rows).max(axis=(0, 1)) > 1e-12 * max(fish.tags.box.length, 1.0))
    if moving.size:
        names = ", ".join(fish.shape_names[k] for k in moving)
        raise InputError(f"shape variations {names} move the spine in x-y; the PROM supports shape "
                         "variations that vanish on the body axis")
