"""Data-free reduction basis (SPEC §7), built on the design the model is centred on.

With the head clamped in all directions:
  1. rigid x-translation (u_x = 1 at every node);
  2. vibration modes (K_0 - ω² M) φ = 0 (SLEPc, shift-invert at 0);
  3. static modal derivatives θ_ij = -K_0⁻¹ (∂K/∂u[φ_j]) φ_i, i ≤ j;
  4. static parameter sensitivities Ξ_ik = -K_0⁻¹ (∂K/∂ξ_k) φ_i;
  5. actuation modes ψ = K_0⁻¹ f_act,1 and θ_ψ = -K_0⁻¹ (∂K/∂u[ψ]) ψ (not in ``basis = "paper"``),
     one pair per independent activation pattern P_k of the muscles (``ActivationLaw.patterns``: the
     antagonist pair has one, (1, -1); muscles with phases two per frequency, the sin and cos parts),
     ``psi``, ``theta_psi`` for the first, ``psi_2``, ``theta_psi_2``, … for the others; with several
     patterns also θ_ψkψl = -K_0⁻¹ (∂K/∂u[ψ_k]) ψ_l (k < l, ``theta_psi_k_l``) and the inertia vectors
     K_0⁻¹ M ψ_k (``psi_mass_k``): the travelling wave's ROM needs them (docs/theory/basis.md);
  6. response vectors (``response_vectors``, not in ``basis = "paper"``):
     ψ_m = -K_0⁻¹ B_1 ψ, B_1 = ∂²Π_act,1/∂u² the muscles' stiffness at unit activation: with
     f_act = -a (b_1 + B_1 u) the static response to a is u = a ψ + a² (½ θ_ψ + ψ_m) + O(a³)
     (per pattern: ``psi_muscle``, ``psi_muscle_2``, …);
     τ = K_0⁻¹ e_tail,x, the static response to the thrust's tail force at rest (f_tail ∥ t = e_x),
     a point force that indents the tail node and so shortens the tail segment's t.
  7. stroke vectors (``stroke_amplitude`` A_s > 0, not in ``basis = "paper"``; docs/theory/basis.md,
     "Large strokes"): the FOM's static responses u_s(±A_s), f_int(u) = f_act(u) at the activations
     ±A_s P_1 (the pair: ±A_s (1, -1); every order of a, the large rotations of the tail included); the responses to the
     tail station's unit forces, τ_x = K_0⁻¹ B_0ᵀ e_x and τ_y = K_0⁻¹ B_0ᵀ e_y; the modal derivative
     θ_ψτ = -K_0⁻¹ (∂K/∂u[τ_x]) ψ; and the inertia (Ritz) vectors (K_0⁻¹ M)² ψ and K_0⁻¹ M τ_x;
     with ``stroke_sensitivities`` (PROMs) also ∂u_s(±A_s)/∂ξ_k, by a forward difference in ξ_k.
Each vector is normalised, then mass-orthonormalised; vectors whose remaining mass-norm falls
below the drop tolerance are dropped and reported.
"""
from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from slepc4py import SLEPc

from aquarom_fenics.errors import SolverError
from aquarom_fenics.fem import dolfinx_adapter as fx
from aquarom_fenics.fem.fom import FullOrderModel
from aquarom_fenics.fem.linear_solver import mumps_solver, upper_triangle_copy
from aquarom_fenics.io.scene_muscles import muscle_groups, scene_vibration_modes, stroke_amplitude
from aquarom_fenics.reduction.mode_count import candidate_count, choose_modes, lateral_shares
from aquarom_fenics.reduction.stroke_responses import stroke_response, stroke_sensitivity

log = logging.getLogger("aquarom")


@dataclass
class ReductionBasis:
    vectors: np.ndarray           # V, (n_owned_dofs, m), Vᵀ M V = I
    labels: list[str]
    dropped: list[str] = field(default_factory=list)
    frequencies: np.ndarray = field(default_factory=lambda: np.zeros(0))   # Hz, of the vibration modes
    timings: dict = field(default_factory=dict)


class _SecondVariations:
    """Vector forms d²f_int(0)[a, b] and ∂/∂ξ (d f_int(0)[a]) in the directions of two functions."""

    def __init__(self, fom: FullOrderModel):
        self.fom = fom
        self.direction_a = fx.new_function(fom.space, "direction_a")
        self.direction_b = fx.new_function(fom.space, "direction_b")
        self.shape_direction = fom.shape_direction("shape_direction")
        internal = fom.elastic.force_form
        first = ufl.derivative(internal, fom.displacement, self.direction_a)
        self.modal = fx.compile_form(ufl.derivative(first, fom.displacement, self.direction_b))
        self.shape = fx.compile_form(fom.shape_derivative(first, self.shape_direction))
        self.vector = fx.create_vector(self.modal)
        self.muscle = None
        if fom.muscle.on:
            muscle_stiffness = ufl.derivative(fom.muscle.negative_force_form, fom.displacement, self.direction_a)
            self.muscle = fx.compile_form(muscle_stiffness)

    def evaluate(self, compiled, a: np.ndarray, b: np.ndarray | None = None) -> np.ndarray:
        self.fom.set_displacement(np.zeros(self.fom.n_owned_dofs))
        fx.set_owned_values(self.direction_a, a)
        if b is not None:
            fx.set_owned_values(self.direction_b, b)
        return fx.assemble_vector_into(self.vector, compiled).copy()

    def shape_variation(self, a: np.ndarray, k: int) -> np.ndarray:
        """∂/∂ξ_k (d f_int(0)[a])."""
        self.shape_direction.set_parameter(k)
        return self.evaluate(self.shape, a)

    def muscle_stiffness(self, a: np.ndarray, pattern: np.ndarray) -> np.ndarray:
        """B_1 a = ∂²Π_act/∂u² (0)[a] with the activations at ``pattern`` (unit amplitude)."""
        self.fom.muscle.set_activations(pattern)
        return self.evaluate(self.muscle, a)


def clamped_stiffness(fom: FullOrderModel) -> PETSc.Mat:
    """K_0 of the design at rest with the head clamped (identity rows on the clamped dofs)."""
    matrix = fom.rest_stiffness.copy()
    matrix.zeroRowsColumns(fom.global_dofs(fom.clamped_dofs), diag=1.0)
    return matrix


def vibration_modes(fom: FullOrderModel, stiffness: PETSc.Mat, count: int,
                    factors: PETSc.KSP | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` lowest modes (owned dofs, columns) and their frequencies ω/2π [Hz], from
    (K - σ M)⁻¹ M x = x/(ω² - σ) at σ = 0. ``factors``, a direct solver of ``stiffness``, lends its
    factorisation of K to the shift-invert and keeps it for the caller's own solves."""
    mass = fom.mass_matrix.copy()
    mass.zeroRowsColumns(fom.global_dofs(fom.clamped_dofs), diag=0.0)
    solver = SLEPc.EPS().create(fom.comm)
    solver.setOperators(stiffness, mass)
    solver.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    solver.setDimensions(count, 2 * count + 6)     # a Krylov space of 8 for one mode: one restart, 8 solves
    solver.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    solver.setTarget(0.0)
    spectral = solver.getST()
    spectral.setType(SLEPc.ST.Type.SINVERT)
    spectral.setShift(0.0)
    if factors is not None:
        spectral.setMatMode(SLEPc.ST.MatMode.INPLACE)       # K - 0 M is K itself: no copy, no new factors
        spectral.setKSP(factors)
    else:
        inner = spectral.getKSP()
        inner.setType("preonly")
        inner.getPC().setType("lu")
        inner.getPC().setFactorSolverType("mumps")
    solver.setTolerances(1e-12, 200)
    solver.solve()
    if solver.getConverged() < count:
        raise RuntimeError(f"SLEPc converged {solver.getConverged()} of {count} vibration modes")
    vector = stiffness.createVecRight()
    modes, frequencies = [], []
    for index in range(count):
        eigenvalue = solver.getEigenpair(index, vector).real
        modes.append(vector.array.copy())
        frequencies.append(np.sqrt(max(eigenvalue, 0.0)) / (2 * np.pi))
    if factors is not None:     # the EPS would reset a KSP it still holds, factors included, when destroyed
        placeholder = PETSc.KSP().create(fom.comm)
        spectral.setKSP(placeholder)
        placeholder.destroy()
    for petsc_object in (solver, vector, mass):
        petsc_object.destroy()      # frees the factorisation and copies (not freed with the Python objects)
    return np.column_stack(modes), np.array(frequencies)


def basis_modes(fom: FullOrderModel, stiffness: PETSc.Mat, solver: PETSc.KSP) -> tuple[np.ndarray, np.ndarray]:
    """The basis's vibration modes and frequencies [Hz]: ``[reduction] vibration_modes`` of them, or for
    "auto" the lowest that hold the gait's muscle groups in the swimming plane (reduction/mode_count.py)."""
    count = scene_vibration_modes(fom.scene)
    if count is not None:
        return vibration_modes(fom, stiffness, count, factors=solver)
    modes, frequencies = vibration_modes(fom, stiffness, candidate_count(muscle_groups(fom.scene)), factors=solver)
    products = np.column_stack([fom.matvec(fom.mass_matrix, modes[:, i]) for i in range(modes.shape[1])])
    count = choose_modes(fom.scene, modes, frequencies, lateral_shares(modes, products, fom.comm))
    return modes[:, :count], frequencies[:count]


def pattern_suffixes(actuation_modes: int) -> list[str]:
    """"" for the first activation pattern, "_2", "_3", … for the others (``actuation_modes``: their
    number, True for one, False or 0 for none)."""
    return ["" if k == 0 else f"_{k + 1}" for k in range(int(actuation_modes))]


def candidate_labels(n_modes: int, modal_derivatives: bool, n_parameters: int, actuation_modes: int,
                     responses: tuple[str, ...] = ()) -> list[str]:
    """Names of the candidate vectors in the order of SPEC §7: rigid_x, mode_i, theta_i_j (i ≤ j),
    xi_i_k (mode i, parameter k, both from 1), psi and theta_psi (per activation pattern: psi_2,
    theta_psi_2, …; with several patterns then theta_psi_k_l (k < l) and psi_mass_k), then the
    ``responses`` (``psi_muscle``, ``tail_force``; see :func:`response_labels`)."""
    labels = ["rigid_x"] + [f"mode_{i + 1}" for i in range(n_modes)]
    if modal_derivatives:
        labels += [f"theta_{i + 1}_{j + 1}" for j in range(n_modes) for i in range(j + 1)]
    labels += [f"xi_{i + 1}_{k + 1}" for k in range(n_parameters) for i in range(n_modes)]
    for suffix in pattern_suffixes(actuation_modes):
        labels += ["psi" + suffix, "theta_psi" + suffix]
    if int(actuation_modes) > 1:
        labels += [f"theta_psi_{k + 1}_{l + 1}" for l in range(int(actuation_modes)) for k in range(l)]
        labels += [f"psi_mass_{k + 1}" for k in range(int(actuation_modes))]
    return labels + list(responses)


def response_labels(response_vectors: bool, actuation_modes: int, thrust: bool) -> tuple[str, ...]:
    """The response vectors of item 6 that apply: ψ_m (one per activation pattern) needs the actuation
    modes, τ the nodal thrust."""
    if not response_vectors:
        return ()
    return tuple("psi_muscle" + suffix for suffix in pattern_suffixes(actuation_modes)) + (("tail_force",) if thrust else ())


def stroke_labels(stroke: bool, actuation_modes: bool, thrust: bool, responses: tuple[str, ...] = (),
                  sensitivities: int = 0) -> tuple[str, ...]:
    """The stroke vectors of item 7 that apply (they need the actuation modes; the tail's, the thrust);
    τ_x once, when the response vectors hold it already; with ``sensitivities`` = p > 0 the stroke
    responses' ξ-sensitivities ``dstroke_plus_k``, ``dstroke_minus_k`` (k = 1 … p) last."""
    if not (stroke and actuation_modes):
        return ()
    labels = ("stroke_plus", "stroke_minus")
    if thrust:
        labels += (() if "tail_force" in responses else ("tail_force",)) + ("tail_lateral", "theta_psi_tail")
    labels += ("psi_inertia",)
    labels += ("tail_inertia",) if thrust else ()
    return labels + tuple(f"dstroke_{sign}_{k + 1}" for k in range(sensitivities) for sign in ("plus", "minus"))


class KeptFactors:
    """The last Cholesky factorisation of a clamped K_0 in this process, kept with its matrix.

    MUMPS spends a good part of a factorisation on its analysis (the ordering and the symbolic
    factorisation), which depends only on the sparsity pattern. The builds of one optimisation share the nominal mesh,
    hence the pattern: each build refills the kept matrix and refactorises numerically. The pattern
    is that of the dof map: the same cell-to-dof lists and ownership on the same communicator give
    the same matrix pattern. One factorisation is kept (a build's own memory); ``lock`` serialises
    the builds of threads that share the process.
    """

    def __init__(self):
        self.lock = threading.RLock()
        self.key = None
        self.matrix: PETSc.Mat | None = None
        self.solver: PETSc.KSP | None = None

    @staticmethod
    def pattern_key(fom: FullOrderModel) -> tuple:
        dofmap = fom.space.dofmap
        index_map = dofmap.index_map
        return (fom.comm, dofmap.list.array.copy(), tuple(index_map.local_range), index_map.ghosts.copy(),
                dofmap.index_map_bs)

    @staticmethod
    def _same(key, other) -> bool:
        return (key is not None and other is not None and MPI.Comm.Compare(key[0], other[0]) == MPI.IDENT
                and all(np.array_equal(a, b) for a, b in zip(key[1:], other[1:])))

    def factors(self, fom: FullOrderModel) -> tuple[PETSc.Mat, PETSc.KSP]:
        """(upper triangle of the clamped K_0, a direct solver of it) for ``fom``; call under ``lock``."""
        key = self.pattern_key(fom)
        reuse = fom.comm.allreduce(self._same(self.key, key), op=MPI.LAND)
        clamped = clamped_stiffness(fom)
        if reuse:
            upper_triangle_copy(clamped, self.matrix)       # same pattern: refilled, MUMPS keeps its analysis
            self.matrix.setOption(PETSc.Mat.Option.SPD, True)
            self.solver.setOperators(self.matrix)
            clamped.destroy()
            return self.matrix, self.solver
        self.release()
        self.matrix = upper_triangle_copy(clamped, None)
        self.matrix.setOption(PETSc.Mat.Option.SPD, True)
        clamped.destroy()
        self.solver = mumps_solver(fom.comm, symmetric=True)
        self.solver.setOperators(self.matrix)
        self.key = key
        return self.matrix, self.solver

    def release(self) -> None:
        """Free the kept factorisation and matrix (after a build of another thread has ended)."""
        with self.lock:
            for petsc_object in (self.solver, self.matrix):
                if petsc_object is not None:
                    petsc_object.destroy()
            self.key = self.matrix = self.solver = None


KEPT_FACTORS = KeptFactors()


def build_basis(fom: FullOrderModel, n_parameters: int) -> ReductionBasis:
    """Basis of SPEC §7 for the FOM's design, with sensitivities to the first ``n_parameters`` ξ_k."""
    with KEPT_FACTORS.lock:
        return _build_basis(fom, n_parameters)


def _build_basis(fom: FullOrderModel, n_parameters: int) -> ReductionBasis:
    settings = fom.scene.reduction
    timings = {}
    started = time.perf_counter()
    stiffness, solver = KEPT_FACTORS.factors(fom)
    clamped = fom.clamped_dofs

    def static_solve(rhs):
        rhs = rhs.copy()
        rhs[clamped] = 0.0
        return fom.solve_with(solver, rhs)

    rigid = np.zeros(fom.n_owned_dofs)
    rigid[0::3] = 1.0
    candidates = [rigid]
    modes, frequencies = basis_modes(fom, stiffness, solver)
    timings["vibration_modes"] = time.perf_counter() - started
    modes = [modes[:, i] / fom.norm(modes[:, i]) for i in range(modes.shape[1])]
    candidates += modes

    variations = fom.keep("second_variations", lambda: _SecondVariations(fom))
    if settings.modal_derivatives:
        for i, j in ((i, j) for j in range(len(modes)) for i in range(j + 1)):
            candidates.append(-static_solve(variations.evaluate(variations.modal, modes[i], modes[j])))
    for k in range(n_parameters):
        candidates += [-static_solve(variations.shape_variation(mode, k)) for mode in modes]
    patterns = fom.muscle.law.patterns() if settings.basis == "default" and fom.muscle.on else []
    actuation_modes = len(patterns)
    psis = [static_solve(unit_actuation_force(fom, pattern)) for pattern in patterns]
    for psi in psis:
        candidates += [psi, -static_solve(variations.evaluate(variations.modal, psi, psi))]
    if len(psis) > 1:        # several patterns (a travelling wave): their coupling and inertia (docs/theory/basis.md)
        candidates += [-static_solve(variations.evaluate(variations.modal, psis[k], psis[l]))
                       for l in range(len(psis)) for k in range(l)]
        candidates += [static_solve(fom.matvec(fom.mass_matrix, vector)) for vector in psis]
    psi = psis[0] if psis else None
    # τ follows the tail node's indentation under the nodal thrust; through the stations it is not needed
    # (degree 2, level 2: the ROM's distance and tail amplitude change by 0.002 % and 0.03 % without it)
    responses = response_labels(settings.basis == "default" and settings.response_vectors, actuation_modes,
                                fom.thrust is not None and fom.station_averages is None)
    if "psi_muscle" in responses:
        candidates += [-static_solve(variations.muscle_stiffness(vector, pattern)) for vector, pattern in zip(psis, patterns)]
    tail = static_solve(unit_tail_force(fom)) if "tail_force" in responses else None
    if tail is not None:
        candidates.append(tail)
    strokes = stroke_labels(settings.basis == "default" and stroke_amplitude(fom.scene) > 0, actuation_modes,
                            fom.thrust is not None, responses, n_parameters if settings.stroke_sensitivities else 0)
    if strokes:
        candidates += stroke_vectors(fom, strokes, static_solve, variations, psi, tail)
    timings["static_solves"] = time.perf_counter() - started - timings["vibration_modes"]
    labels = candidate_labels(len(modes), settings.modal_derivatives, n_parameters, actuation_modes,
                              responses + strokes)
    vectors, labels, dropped = mass_orthonormalise(fom, list(zip(labels, candidates)), settings.drop_tolerance)
    timings["basis_total"] = time.perf_counter() - started
    if dropped:
        log.info("basis: %s left out, a numerical combination of the other vectors (the PROM spans the "
                 "same motions with %d vectors; nothing to do)", ", ".join(dropped), len(labels))
    log.info("basis: %d vectors (%s), first frequency %.3f Hz, %.2f s", len(labels), ", ".join(labels),
             frequencies[0], timings["basis_total"])
    return ReductionBasis(vectors, labels, dropped, frequencies, timings)


def stroke_vectors(fom: FullOrderModel, labels: tuple[str, ...], static_solve, variations: _SecondVariations,
                   psi: np.ndarray, tail: np.ndarray | None) -> list[np.ndarray]:
    """The stroke vectors of item 7 named by ``labels`` (:func:`stroke_labels`), in their order."""
    amplitude = stroke_amplitude(fom.scene)
    try:
        plus, minus = stroke_response(fom, amplitude), stroke_response(fom, -amplitude)
    except SolverError as error:
        given = (" (\"auto\": the scene's amplitude, a body from a mesh file)"
                 if fom.scene.reduction.stroke_amplitude == "auto" else "")
        raise SolverError(f"[reduction] stroke_amplitude = {amplitude:g}{given}: {error}; a smaller stroke_amplitude "
                          "(the largest amplitude the model runs) may converge, 0 leaves the stroke vectors out") from None
    finally:
        fom.set_displacement(np.zeros(fom.n_owned_dofs))
        fom.muscle.set_activations(np.zeros(fom.muscle.law.size))
    if tail is None and "tail_force" in labels:
        tail = static_solve(unit_tail_force(fom))
    vectors = {"stroke_plus": plus, "stroke_minus": minus, "tail_force": tail}
    if "tail_lateral" in labels:
        vectors["tail_lateral"] = static_solve(unit_tail_force(fom, axis=1))
        vectors["theta_psi_tail"] = -static_solve(variations.evaluate(variations.modal, psi, tail))
        vectors["tail_inertia"] = static_solve(fom.matvec(fom.mass_matrix, tail))
    first = static_solve(fom.matvec(fom.mass_matrix, psi))
    vectors["psi_inertia"] = static_solve(fom.matvec(fom.mass_matrix, first))
    for k in sorted({int(label.rsplit("_", 1)[1]) - 1 for label in labels if label.startswith("dstroke_")}):
        vectors[f"dstroke_plus_{k + 1}"], vectors[f"dstroke_minus_{k + 1}"] = stroke_sensitivity(fom, k, plus, minus)
    return [vectors[label] for label in labels]


def unit_actuation_force(fom: FullOrderModel, pattern: np.ndarray | None = None) -> np.ndarray:
    """f_act at rest with the activations at ``pattern`` (default the first activation pattern; the
    pair's (1, -1): left contracting, right extending)."""
    fom.muscle.set_activations(fom.muscle.law.patterns()[0] if pattern is None else pattern)
    fom.set_displacement(np.zeros(fom.n_owned_dofs))
    return fom.muscle.force()


def unit_tail_force(fom: FullOrderModel, nodal: bool = False, axis: int = 0) -> np.ndarray:
    """A unit force [N] in x (``axis`` 0; y: 1) on the tail, in x the direction of f_tail = ½ m̃ (v·n)² t at
    rest: B_0ᵀ e_x on the tail station (e_tail,x on the tail node with ``stations = "nodes"`` or ``nodal``,
    and with the thrust off on a mesh that has a tail node)."""
    tags = fom.fish.tags
    if not nodal and fom.station_averages is not None and (fom.thrust is not None or not tags.has_spine):
        force = np.zeros((fom.layout.n_owned_blocks, 3))
        force[:, axis] = fom.station_averages.weights[0][:, fom.layout.owned_nodes].toarray().ravel()
        return force.ravel()
    if not tags.has_spine:
        raise ValueError(f"mesh {fom.fish.mesh.source} has no tail node (no nodes on its axis)")
    force = np.zeros(fom.n_owned_dofs)
    blocks, _ = fom.owned_positions(np.array([tags.tail_node]))
    force[3 * blocks + axis] = 1.0
    return force


def mass_orthonormalise(fom: FullOrderModel, candidates, tolerance: float):
    """Gram-Schmidt in ⟨a, b⟩_M (twice), after normalising each candidate.

    A candidate is dropped when its mass-norm is zero or below ``tolerance`` times the largest of
    its family (θ, Ξ, ...), or when less than ``tolerance`` of it remains after orthogonalisation.
    Each vector carries its product with M, updated with it (M(v - c b) = Mv - c Mb): one product
    with M per candidate.
    """
    products = [fom.matvec(fom.mass_matrix, vector) for _, vector in candidates]
    norms = [np.sqrt(_dot(fom, vector, product)) for (_, vector), product in zip(candidates, products)]
    family_scale = {}
    for (label, _), norm in zip(candidates, norms):
        family = label.split("_")[0]
        family_scale[family] = max(family_scale.get(family, 0.0), norm)
    accepted, labels, dropped = [], [], []
    for (label, vector), product, norm in zip(candidates, products, norms):
        if not np.isfinite(norm) or norm <= tolerance * family_scale[label.split("_")[0]]:
            dropped.append(label)
            continue
        vector, product = vector / norm, product / norm
        for _ in range(2):
            for basis_vector, basis_product in accepted:
                coefficient = _dot(fom, basis_vector, product)
                vector = vector - coefficient * basis_vector
                product = product - coefficient * basis_product
        remaining = np.sqrt(max(_dot(fom, vector, product), 0.0))
        if remaining < tolerance:
            dropped.append(label)
            continue
        accepted.append((vector / remaining, product / remaining))
        labels.append(label)
    return np.column_stack([vector for vector, _ in accepted]), labels, dropped


def _dot(fom: FullOrderModel, a: np.ndarray, b: np.ndarray) -> float:
    """aᵀ b over all ranks (owned dofs)."""
    return float(fom.comm.allreduce(float(a @ b), op=MPI.SUM))


def mass_inner(fom: FullOrderModel, a: np.ndarray, b: np.ndarray) -> float:
    """aᵀ M b over all ranks."""
    return float(fom.comm.allreduce(float(a @ fom.matvec(fom.mass_matrix, b)), op=MPI.SUM))
