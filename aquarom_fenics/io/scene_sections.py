"""The sections of a scene file: one frozen dataclass per TOML table (SPEC §1).

Every field carries its SPEC default, an optional validity check and its unit or meaning
(``metadata["doc"]``, used by the scene documentation); ``SECTIONS`` maps table names to classes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any


MAX_VIBRATION_MODES = 50
"""Most vibration modes of a basis (with modal derivatives 50 modes make 1326 vectors, whose cubic
tensor alone would take 25 TB; the plan check refuses far fewer with its memory estimate)."""


def _positive(value) -> str | None:
    return None if value > 0 else "must be > 0"


def _non_negative(value) -> str | None:
    return None if value >= 0 else "must be >= 0"


def _one_of(*choices):
    def check(value) -> str | None:
        return None if value in choices else f"must be one of {', '.join(map(repr, choices))}"
    return check


NO_LEGACY = object()
"""The ``legacy`` of a key that scenes had from the start."""


def _spec(default, check=None, doc="", variable_length=False, coerce=None, legacy=NO_LEGACY):
    """A scene field: its default, an optional validity check and a unit/meaning for the docs;
    ``coerce(value, where)`` replaces the type check by the default's type where a key takes
    values of more than one type. ``legacy``: for a key added after scenes were hashed, the value
    that reproduces what they computed before; at that value the key is left out of ``Scene.hash``,
    so the caches, checkpoints and resumable studies made before it existed stay valid for it."""
    return field(default=default, metadata={"check": check, "doc": doc, "variable_length": variable_length,
                                            "coerce": coerce, "legacy": legacy})


@dataclass(frozen=True)
class LegacyValues:
    """The ``legacy`` of a key at which several values reproduce what scenes computed before it."""

    values: tuple


def legacy_values(section) -> dict[str, Any]:
    """{key: value} of a section's keys that ``Scene.hash`` leaves out at that value (``legacy``)."""
    return {f.name: f.metadata["legacy"] for f in fields(section) if f.metadata.get("legacy", NO_LEGACY) is not NO_LEGACY}


def at_legacy(value, legacy) -> bool:
    """Whether a key's ``value`` is its ``legacy`` value (one of them, for ``LegacyValues``)."""
    return value in legacy.values if isinstance(legacy, LegacyValues) else value == legacy


def _station_count(value, where):
    """An integer N_s ≥ 2 or the string "nodes"."""
    from aquarom_fenics.errors import InputError

    if value == "nodes" or (isinstance(value, int) and not isinstance(value, bool) and 2 <= value <= 2000):
        return value
    raise InputError(f"{where} must be an integer number of station intervals in [2, 2000] or \"nodes\", got {value!r}")


def _start_ramp(value, where):
    """A time τ ≥ 0 [s] (a finite number) or the string "auto"."""
    from aquarom_fenics.errors import InputError

    if value == "auto":
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value >= 0:
        return float(value)
    raise InputError(f"{where} must be a time >= 0 [s] or \"auto\" (a smooth start where a muscle would "
                     f"start at a_j(0) != 0), got {value!r}")


def _mode_count(value, where):
    """An integer n_vm in [1, MAX_VIBRATION_MODES] or the string "auto"."""
    from aquarom_fenics.errors import InputError

    if value == "auto" or (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= MAX_VIBRATION_MODES):
        return value
    raise InputError(f"{where} must be in [1, {MAX_VIBRATION_MODES}] or \"auto\" (the basis follows the gait), got {value!r}")


def _stroke(value, where):
    """An amplitude A_s in [0, 10] (0: off) or the string "auto"."""
    from aquarom_fenics.errors import InputError

    if value == "auto":
        return value
    if isinstance(value, (int, float)) and not isinstance(value, bool) and 0 <= value <= 10:
        return float(value)
    raise InputError(f"{where} must be in [0, 10] (0: off) or \"auto\" (on for a body from a mesh file), got {value!r}")


def _region_name(value, where):
    """A non-empty region name (a physical group or element set of the mesh)."""
    from aquarom_fenics.errors import InputError

    if isinstance(value, str) and value.strip():
        return value
    raise InputError(f"{where} must be the name of a region of the mesh (a non-empty string), got {value!r}")


def _muscle_pair(value, where):
    """Two different region names: the muscle driven by +a(t) and the one driven by -a(t)."""
    from aquarom_fenics.errors import InputError

    if (isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(name, str) and name.strip()
                                                                      for name in value) and value[0] != value[1]):
        return tuple(value)
    raise InputError(f"{where} must name two different regions of the mesh, [left, right] (driven in antiphase: "
                     f"a_left = A sin(2π f t), a_right = -a_left), got {value!r}")


def _interval_within(low, high):
    def check(value) -> str | None:
        lower, upper = value
        return None if low <= lower < upper <= high else f"must be [lower, upper] with {low} <= lower < upper <= {high}"
    return check


@dataclass(frozen=True)
class MeshSection:
    level: int = _spec(3, _one_of(1, 2, 3, 4, 5), "refinement level of the built-in block (1: ~1.3k … 5: ~25k cells)")
    degree: int = _spec(1, _one_of(1, 2), "Lagrange degree of the displacement (1: linear, 2: quadratic tetrahedra)")
    file: str = _spec("", None, "external mesh (gmsh .msh, Abaqus .inp, .vtu, .med or Exodus .e/.exo of first-order tetrahedra), relative to the scene file; its volume physical groups or element sets are the regions named in [regions]; no nodes on the body axis needed (but with [fluid] stations = \"nodes\"); replaces the block (--level is refused with it)")
    scale: float = _spec(1.0, _positive, "factor applied to the file's coordinates (to metres)")
    translate: tuple[float, float, float] = _spec((0.0, 0.0, 0.0), None, "shift after scaling [m]")
    length: float = _spec(0.20, _positive, "block length L along x [m]")
    width: float = _spec(0.04, _positive, "block width W along y [m]")
    height: float = _spec(0.10, _positive, "block height H along z [m]")
    axis: str = _spec("x", _one_of("x", "y", "z"), "the axis the body lies along in the mesh file (its swimming direction); \"y\" and \"z\" turn the mesh a quarter turn (about z, or about y) so that the body lies along x; the block lies along x", legacy="x")
    head_end: str = _spec("", _one_of("", "+x", "-x", "+y", "-y", "+z", "-z"), "where the head lies along [mesh] axis: \"+x\" (at the largest x, as the block) or \"-x\" (the mesh is then mirrored in x, so that it swims towards +x); \"+y\", \"-y\", \"+z\", \"-z\" with axis = \"y\" or \"z\". Left out (\"\"): the end the head region reaches, said in one line, refused without a head region. Declared or not, a head region must reach exactly one end along the axis (refused when it reaches both ends or neither), and a declared end must be that one", legacy=LegacyValues(("", "+x")))


@dataclass(frozen=True)
class MaterialSection:
    young_modulus: float = _spec(260e3, _positive, "E [Pa]")
    poisson_ratio: float = _spec(0.4, lambda v: None if -1 < v < 0.5 else "must be in (-1, 0.5)", "ν")
    density: float = _spec(1070.0, _positive, "ρ [kg/m³]")
    head_stiffness_factor: float = _spec(100.0, _positive, "head E = factor × E")
    rayleigh_alpha: float = _spec(3.1, _non_negative, "α_R [1/s] in C = α_R M + β_R K_0")
    rayleigh_beta: float = _spec(6.3e-6, _non_negative, "β_R [s]")
    mass: str = _spec("consistent", _one_of("consistent", "lumped"), "mass matrix")
    law: str = _spec("svk", _one_of("svk", "neo-hookean"), "the elastic energy ψ: \"svk\" (Saint Venant-Kirchhoff, ψ = ½ λ (tr E)² + μ E:E, SPEC §5) or \"neo-hookean\" (compressible, ψ = μ/2 (I₁ - 3) - μ ln J + λ/2 (ln J)², the same λ, μ); the FOM uses the law, a ROM or PROM its small-strain (SVK) expansion, which is exact for \"svk\" only (docs/theory/material-law.md)", legacy="svk")


@dataclass(frozen=True)
class RegionsSection:
    head_fraction: float = _spec(0.35, lambda v: None if 0 < v < 1 else "must be in (0, 1)", "head x ≥ -fraction·L: the block's head region, and on a mesh without regions the cells whose centroid lies there")
    muscle_range: tuple[float, float] = _spec((-0.95, -0.35), _interval_within(-1.0, 0.0), "muscles -a·L < x < -b·L, as [-a, -b]: the block's muscle regions, and on a mesh without regions the cells whose centroid lies there")
    head: str = _spec("head", None, "the region (gmsh volume physical group, Abaqus element set) that is the stiff head; head_fraction and muscle_range place the block's regions, and choose the cells of a mesh without regions", coerce=_region_name, legacy="head")
    muscles: tuple[str, str] = _spec(("left_muscle", "right_muscle"), None, "the two muscle regions [left, right], driven in antiphase (a_left = A sin(2π f t), a_right = -a_left), when the scene has no [[muscles]] tables", coerce=_muscle_pair, legacy=("left_muscle", "right_muscle"))
    muscle_pairs: int = _spec(1, lambda v: None if 1 <= v <= 20 else "must be in [1, 20]", "the block's muscle range split along x into this many conforming segments, regions left_1 … left_n and right_1 … right_n from tail to head (left_muscle and right_muscle stay their unions); name them in [[muscles]] tables", legacy=1)


@dataclass(frozen=True)
class MuscleSpec:
    """One ``[[muscles]]`` table: the muscle's region, its unit fibre direction m_j and its activation

        a_j(t) = A s_j r(t) sin(2π f_j t + φ_j),   A and r(t) of [actuation],

    with the scale s_j, the phase φ_j in degrees and the frequency f_j [Hz] (None: [actuation] frequency)."""
    region: str
    fibre: tuple[float, float, float] = (1.0, 0.0, 0.0)
    scale: float = 1.0
    phase: float = 0.0
    frequency: float | None = None


@dataclass(frozen=True)
class ActuationSection:
    stiffness: float = _spec(6e4, _non_negative, "muscle stiffness k [Pa]")
    amplitude: float = _spec(0.2, _non_negative, "A in a_left = A sin(2π f t), a_right = -a_left")
    frequency: float = _spec(1.0, _positive, "f [Hz]")
    start_ramp: float | str = _spec("auto", None, "τ [s] of a smooth start a(t) sin²(π t / 2τ) for t < τ; 0: SPEC's A sin(2π f t) from t = 0; \"auto\": 0 when every driven muscle starts at a_j(0) = 0 (phases 0° or 180°, SPEC's law), else a quarter of the slowest muscle's period 1/(4 f) (0.25 s at 1 Hz), applied to the whole gait", coerce=_start_ramp)
    muscle_volume: str = _spec("shape", _one_of("shape", "nominal"), "muscle energy over the shape-varied (SPEC default) or nominal volume")


@dataclass(frozen=True)
class FluidSection:
    density: float = _spec(1000.0, _positive, "ρ_w [kg/m³]")
    thrust: bool = _spec(True, None, "Lighthill reactive thrust, through the stations")
    stations: int | str = _spec(40, None, "N_s: the thrust acts through N_s + 1 cross-section stations (averages over slabs of L/N_s; no nodes on the body axis needed); \"nodes\": on the spine nodes (the source's model, no mesh limit; needs nodes on the body axis y = z = 0 from tail to head face and skin nodes on y = 0 above it)", coerce=_station_count)
    drag: bool = _spec(True, None, "form drag on the skin")
    thrust_factor: float = _spec(1.0, _positive, "c_T, dimensionless: multiplies Lighthill's virtual mass m̃ = c_T (π/4) ρ_w d² and so the whole thrust (1: SPEC's law); calibrated against water tests", legacy=1.0)
    drag_factor: float = _spec(1.0, _positive, "c_D, dimensionless: multiplies the skin drag coefficient C_d = 2 c_D (n·e_x)² and so the drag force (1: SPEC's law); calibrated against water tests", legacy=1.0)
    tail_station: str = _spec("face", _one_of("face", "slab"), "the tail station's kinematics: the average over the end face x = -L ('face', within 3 % of the station-converged distance at N_s = 40; on a body without an end face, a tapering tail, the last slab's, with a log line) or the half-hat average over the last slab ('slab', SPEC §5's first definition, -4 % at N_s = 40)")
    spine_force: str = _spec("source", _one_of("source", "lagrangian"), "spine force -d/dt(∂T_a/∂v) ('source') or with +∂T_a/∂x ('lagrangian', exchanges no energy by itself)")
    spine_rule: str = _spec("trapezoid", _one_of("trapezoid", "rear"), "quadrature of the spine force along the body: shared by each segment's two stations ('trapezoid', second order in 1/N_s: 0.1 % from the station-converged distance at N_s = 40) or on its rear station ('rear', SPEC §5, first order: +2 %); stations = \"nodes\" is the source's model and always 'rear'", legacy="rear")


@dataclass(frozen=True)
class ShapeSpec:
    name: str
    lower: float
    upper: float
    start: float = 0.0
    radius: float | None = None     # PROM validity radius; None: [reduction] validity_fraction × max |bound|


@dataclass(frozen=True)
class LinearConstraint:
    """lower ≤ Σ_k coefficients[k] ξ_k ≤ upper (either bound may be infinite)."""
    coefficients: tuple[tuple[str, float], ...]
    lower: float = -math.inf
    upper: float = math.inf


@dataclass(frozen=True)
class SolverSection:
    time_step: float = _spec(0.02, lambda v: "must be > 0" if not v > 0 else None if 1e-9 <= v <= 10.0 else "must be > 0 and in [1e-9, 10] s", "time step h [s]")
    duration: float = _spec(2.0, lambda v: None if 0.1 <= v <= 1e5 else "must be in [0.1, 1e5] s (the distance averages the last 0.1 s)", "horizon T [s]")
    integrator: str = _spec("generalized-alpha", _one_of("generalized-alpha", "newmark"), "time scheme (SPEC §6)")
    rho_infinity: float = _spec(0.8, lambda v: None if 0 <= v <= 1 else "must be in [0, 1]", "ρ∞ of generalized-α: spectral radius at h ω → ∞ (docs/theory/time-scheme.md: how it was chosen)")
    # SPEC §6 gives α_N = 0.005 for the source's Newmark; with it a high-frequency oscillation of the
    # spine nodes grows under the Lighthill forces on finer meshes (levels 4-5) and on thin optimal
    # designs, and the FOM stops near t = 1.9 s. α_N = 0.02 damps it (nominal distance -2 %).
    newmark_alpha: float = _spec(0.02, lambda v: None if 0 <= v < 0.5 else "must be in [0, 0.5)", "α_N of integrator = \"newmark\": γ = ½ + α_N, β = (1 + α_N)²/4 (SPEC: 0.005)")
    min_time_step: float = _spec(1e-3, _positive, "a step whose Newton fails is retried with h/2, h/4, … down to this [s]")
    tolerance: float = _spec(1e-6, _positive, "relative Newton tolerance")
    max_iterations: int = _spec(30, _positive, "Newton iterations per step")
    newton_coupling: str = _spec("lumped", _one_of("lumped", "krylov"), "FOM with stations: the Newton matrix holds the sparse part and a lumped added mass; 'lumped' solves with its factors (modified Newton), 'krylov' solves the exact coupled system by GMRES preconditioned by them")


ATLAS_SCALE = 0.7
"""The default of ``[reduction] atlas_scale`` (``atlas_cover.RADIUS_SCALE``)."""


@dataclass(frozen=True)
class ReductionSection:
    basis: str = _spec("default", _one_of("default", "paper"), "'paper' drops the actuation modes ψ, θ_ψ")
    vibration_modes: int | str = _spec("auto", None, f"number of vibration modes n_vm, in [1, {MAX_VIBRATION_MODES}]; \"auto\": 1 (SPEC §7) when the driven muscles move in one rhythm (the antagonist pair), else the lowest modes of the clamped body that hold as many modes in the swimming plane as the gait has muscle groups (a travelling wave over three pairs: 3, on the shipped block and fish n_vm = 4; docs/theory/basis.md)", coerce=_mode_count)
    modal_derivatives: bool = _spec(True, None, "static modal derivatives θ_ij")
    response_vectors: bool = _spec(True, None, "with basis = 'default': the static responses ψ_m to the muscles' stiffness on ψ and, with stations = \"nodes\", τ to the thrust's tail-node force")
    stroke_amplitude: float | str = _spec("auto", None, "with basis = 'default': > 0 adds the stroke vectors (docs/theory/basis.md, \"Large strokes\"): the FOM's static responses at the activations ±A_s (this A_s, e.g. the largest amplitude the model will run), the tail station's force responses and their inertia and modal-derivative terms; 0: off; \"auto\": off on the built-in block (SPEC §7's basis, which follows its strokes), on a body from a mesh file A_s = the largest amplitude the scene runs ([actuation] amplitude, or the upper amplitude bound of [cooptimization])", coerce=_stroke, legacy=0.0)
    stroke_sensitivities: bool = _spec(False, None, "with stroke_amplitude > 0 and a PROM: also the stroke responses' sensitivities ∂u_s(±A_s)/∂ξ_k (a forward difference of the FOM's static responses, step 1 % of the parameter's range towards the box's middle), so that the PROM's ξ-gradient follows how the large stroke changes with the shape (docs/theory/basis.md, \"The PROM's ξ-gradient with the stroke vectors\")", legacy=False)
    taylor_order: int = _spec(1, _one_of(1, 2), "order of the PROM's Taylor expansion in ξ")
    drop_tolerance: float = _spec(1e-8, _positive, "basis vectors whose remaining mass-norm is below this are dropped")
    validity_fraction: float = _spec(0.25, _positive, "PROM validity radius of a parameter as a fraction of its largest |bound| (a shape's own `radius` overrides it)")
    validity_change: float = _spec(0.0, lambda v: None if 0 <= v <= 1 else "must be in [0, 1] (0: off)", "> 0 caps each PROM's validity radius at the built design: r_k ≤ this / s_k, s_k = the largest relative ξ_k-derivative ‖∂T/∂ξ_k‖/‖T‖ of its internal force and mass tensors T, so that to first order no tensor changes by more than this fraction across the radius (docs/theory/basis.md, \"The validity radius at thin designs\"); 0: off, the radius of validity_fraction or the shape's own", legacy=0.0)
    atlas_scale: float = _spec(ATLAS_SCALE, lambda v: None if 0 < v <= 1 else "must be in (0, 1] (a fraction of the validity radius)", "s: the PROM atlas's cells (`sweep --model prom`, the multi-start screen, [optimizer] atlas) have half-width h_k ≤ s r_k, r_k the validity radius (capped radii: h_k ≤ s R_k); smaller s, smaller cells and more PROM builds. The default 0.7 keeps the PROM within 3 % of the FOM at every cell's corners on SO1's box (and CO's), not on SO2's, SO3's or SO7-SO9's (+21 to +47 % at a cell's corner); around their optima 0.2 erred +4.5 to +13.1 % unless atlas_change divides the cells there; the shipped studies set what their checks held at: check your scene with scripts/validate_atlas.py --start-corners, around the designs you care about, before trusting the atlas, or set atlas_check to let the atlas check its own cells (docs/user/sweep.rst)", legacy=ATLAS_SCALE)
    atlas_change: float = _spec(0.0, lambda v: None if 0 <= v <= 1 else "must be in [0, 1] (0: off)", "> 0: the PROM atlas's cells divided where the tensors change fast, as validity_change divides them, but for the atlas only: each cell's PROM answers within s R_k, R_k ≤ this / s_k (s_k its tensors' largest relative ξ_k-derivative), the optimisers' radii left as they are; 0: off (docs/user/sweep.rst, \"Capped radii\")", legacy=0.0)
    atlas_check: float = _spec(0.0, lambda v: None if 0 <= v < 1 else "must be in [0, 1) (a relative distance gap; 0: off)", "> 0: the PROM atlas checks its own cells: each cell's PROM against the PROMs built at two of its corners (along the signs of its distance gradient); a cell whose relative distance gap exceeds this (e.g. 0.03) is halved in every shape and its halves checked again, at most 6 halvings per shape; about two more PROM builds per cell; 0: off, the cells as atlas_scale and atlas_change cut them (docs/user/sweep.rst, \"The atlas's own check\")", legacy=0.0)


MAX_SCREEN = 100_000
"""Most designs of a multi-start screen (``[optimizer] screen``), as the most designs of one sweep."""


@dataclass(frozen=True)
class OptimizerSection:
    method: str = _spec("paper", _one_of("paper", "trust-region"), "optimisation algorithm")
    max_iterations: int = _spec(100, _positive, "iterations (a safeguard: the optimisers stop on optimality_tolerance)")
    step_size: float = _spec(0.05, _positive, "γ in ξ ← ξ - γ W ∇L; W starts at 1/‖∇L_0‖_∞, so γ is the first step (paper)")
    barrier_weight: float = _spec(1e-3, _positive, "log-barrier weight (paper)")
    rebuild_threshold: float = _spec(0.15, _positive, "rebuild the PROM when any |ξ - ξ_c| exceeds this (paper)")
    n_rebuild: int = _spec(5, _positive, "rebuild the PROM every n iterations, unless the design is inside the last PROM's validity radius (then that PROM re-linearises; paper)")
    step_tolerance: float = _spec(1e-3, _positive, "stop (stalled before optimality) when ‖Δξ‖ falls below")
    cost_tolerance: float = _spec(1e-4, _positive, "stop (stalled before optimality) when the predicted relative cost reduction falls below (trust-region)")
    initial_radius: float = _spec(1.0, lambda v: None if 0 < v <= 1 else "must be in (0, 1]", "trust radius as a fraction of the PROM validity radius (trust-region)")
    accept_ratio: float = _spec(0.1, lambda v: None if 0 <= v < 1 else "must be in [0, 1)", "accept a step when actual/predicted reduction exceeds this")
    expand_ratio: float = _spec(0.75, lambda v: None if 0.25 < v < 1 else "must be in (0.25, 1)", "trust region: expand the radius after a step whose actual/predicted reduction ρ exceeds this (below 1/4 it is halved)", legacy=0.75)
    expand_factor: float = _spec(2.0, lambda v: None if 1 < v <= 16 else "must be in (1, 16]", "trust region: the factor the radius grows by after a step with ρ > expand_ratio (at most the validity box)", legacy=2.0)
    optimality_tolerance: float = _spec(1e-2, _positive, "stop when the first-order measure ‖D r‖_∞ / |L| (KKT residual r, D the parameter ranges) falls below")
    active_tolerance: float = _spec(1e-2, _positive, "a bound or linear constraint is active when its slack is below this fraction of its range")
    starts: int = _spec(1, _positive, "optimisations from the start point and starts - 1 Latin-hypercube feasible points")
    seed: int = _spec(0, _non_negative, "seed of the Latin-hypercube starts")
    screen: int = _spec(0, lambda v: None if 0 <= v <= MAX_SCREEN else f"must be 0 (off) or a number of designs in [starts, {MAX_SCREEN}]", "multi-start screen: 0 off; N ≥ starts: the starts are the `starts` designs of least cost L among N (the start point and N - 1 seeded Latin-hypercube feasible designs), L from the PROM of the atlas cell holding each (as `sweep --model prom`: built on demand through the PROM cache, one batched reduced run per cell; docs/theory/optimisers.md)", legacy=0)
    atlas: bool = _spec(False, None, "each PROM build at a design takes the PROM at the centre of the atlas cell holding it (`sweep --model prom`'s cells, bisected where [reduction] validity_change caps a PROM's radius below its cell, through the PROM cache, keyed by what a build reads: a warm atlas of the scene, whatever its [optimizer], leaves only reduced solves), evaluated at the design; paper method: a new one when the iterate leaves the cell; trust region: the surrogate's box also inside its PROM's validity radius, the candidate's PROM its cell's; false: PROMs built at the designs (docs/theory/optimisers.md)", legacy=False)
    tail_screen: bool = _spec(False, None, "refuse designs whose tail region the thrust destabilises: the FOM linearised at the PROM's last-stroke states (a FOM linearisation and a dense eigenvalue problem per screened state at each PROM build, shared by the ranks under mpirun)")
    tail_growth_limit: float = _spec(100.0, _positive, "tail screen: largest growth rate Re λ of the tail region's modes accepted [1/s]")
    tail_region_radius: float = _spec(0.015, _positive, "tail screen: the region is the free nodes within this distance of the tail station (its rest position) [m]")

    @property
    def multistart(self) -> bool:
        """Whether ``optimize`` runs the multi-start (in ``start_<k>/`` folders): starts > 1, or a screen."""
        return self.starts > 1 or self.screen > 0

    def key_conflict(self) -> str | None:
        """Why keys of the section do not go together, or None: ``screen`` below ``starts`` (a screen chooses
        the starts among its designs)."""
        if 0 < self.screen < self.starts:
            return f"[optimizer] screen = {self.screen} is below starts = {self.starts}: 0 (off) or at least starts"
        return None


@dataclass(frozen=True)
class CooptimizationSection:
    enabled: bool = _spec(False, None, "optimise the actuation amplitude A too")
    amplitude_bounds: tuple[float, float] = _spec((0.05, 0.4), _interval_within(0.0, math.inf), "bounds of A")
    weights: tuple[float, ...] = _spec((0.2, 0.3, 0.4, 0.5, 0.7, 0.9, 0.98), lambda v: None if v and all(0 <= w <= 1 for w in v) else "must be a non-empty list of numbers in [0, 1]", "w_1 sweep, w_2 = 1 - w_1", variable_length=True)
    energy_weight: float = _spec(1.0, _non_negative, "α in L = w_1 (-d) + w_2 α E, E the effort")
    effort: str = _spec("amplitude", _one_of("amplitude", "power"), "the effort E of the cost: \"amplitude\": A² (SPEC §10); \"power\": the muscles' mean positive power over the last activation period [W], P̄ = mean max(0, f_act · u̇), which counts what a gait's frequency and lag cost (through the single reduced run, with its gradient)", legacy="amplitude")


@dataclass(frozen=True)
class OutputSection:
    xdmf: bool = _spec(False, None, "write displacement time series as XDMF")
    render: bool = _spec(True, None, "render PNG pictures with pyvista")
    plots: bool = _spec(True, None, "write matplotlib PNG plots")


SECTIONS = {
    "mesh": MeshSection,
    "material": MaterialSection,
    "regions": RegionsSection,
    "actuation": ActuationSection,
    "fluid": FluidSection,
    "solver": SolverSection,
    "reduction": ReductionSection,
    "optimizer": OptimizerSection,
    "cooptimization": CooptimizationSection,
    "output": OutputSection,
}
