"""The ``[[muscles]]`` tables of a scene: any number of muscles, each with its region, fibre and activation.

    a_j(t) = A s_j r(t) sin(2π f_j t + φ_j)      (A, r(t) and the default f_j of [actuation])

A muscle whose phase is not a multiple of 180° would start with a jump, a_j(0) = A s_j sin φ_j ≠ 0:
``[actuation] start_ramp = "auto"`` (the default) then gives the whole gait the smooth start r(t)
of :func:`start_ramp_time`; with every phase 0° or 180° it keeps SPEC §5's law, r = 1.

A scene without ``[[muscles]]`` drives the pair ``[regions] muscles`` = [left, right] in antiphase:
left s = 1, right s = -1 (both φ = 0), exactly the forces of the scenes written before the tables.
"""
from __future__ import annotations

import logging
import math

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene_sections import ActuationSection, MuscleSpec, RegionsSection

MUSCLE_KEYS = ("region", "fibre", "scale", "phase", "frequency")
"""The keys of a ``[[muscles]]`` table."""

_EPSILON = 2.0 ** -52

AXIAL_FIBRE = (1.0, 0.0, 0.0)
"""The default fibre m: along the body axis (x, from tail to head)."""


def default_muscles(regions: RegionsSection) -> tuple[MuscleSpec, ...]:
    """The antagonist pair of ``[regions] muscles``: a_left = A r sin(2π f t), a_right = -a_left."""
    left, right = regions.muscles
    return MuscleSpec(left), MuscleSpec(right, scale=-1.0)


def _number(value, where: str) -> float:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    raise InputError(f"{where} must be a finite number, got {value!r}")


def _fibre(value, where: str) -> tuple[float, float, float]:
    """A direction [m_x, m_y, m_z], normalised to unit length; a zero vector is refused.

    The norm is taken of the components divided by the largest |m_i| first, so that no square
    overflows (1e200) or underflows (1e-200): any finite non-zero vector has its direction."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError(f"{where} must be a direction [m_x, m_y, m_z] of 3 numbers, got {value!r}")
    components = [_number(component, where) for component in value]
    largest = max(abs(c) for c in components)
    if largest == 0.0:
        raise InputError(f"{where} = {value!r} has no direction (zero length); give e.g. [1, 0, 0] (the body axis)")
    norm = math.sqrt(sum(c * c for c in components))
    if abs(norm - 1.0) <= 4 * _EPSILON:        # already unit: kept, so that a written scene reads back the same
        return tuple(components)
    scaled = [c / largest for c in components]
    norm = math.sqrt(sum(c * c for c in scaled))
    return tuple(c / norm for c in scaled)


def muscle_from_table(item, where: str) -> MuscleSpec:
    """One checked ``[[muscles]]`` table (``where``: 'scene F: [[muscles]] 2')."""
    if not isinstance(item, dict):
        raise InputError(f"{where} must be a table with region and optionally fibre, scale, phase, frequency")
    for key in item:
        if key not in MUSCLE_KEYS:
            raise InputError(f"{where}: unknown key '{key}'; valid keys: {', '.join(MUSCLE_KEYS)}")
    region = item.get("region")
    if not isinstance(region, str) or not region.strip():
        raise InputError(f"{where}: region must be the name of a region of the mesh (a non-empty string), "
                         f"got {region!r}")
    frequency = None
    if "frequency" in item:
        frequency = _number(item["frequency"], f"{where}: frequency")
        if not frequency > 0:
            raise InputError(f"{where}: frequency = {frequency!r} must be > 0 [Hz] (leave it out for [actuation] frequency)")
    return MuscleSpec(region=region,
                      fibre=_fibre(item["fibre"], f"{where}: fibre") if "fibre" in item else AXIAL_FIBRE,
                      scale=_number(item.get("scale", 1.0), f"{where}: scale"),
                      phase=_number(item.get("phase", 0.0), f"{where}: phase"),
                      frequency=frequency)


def muscles_from_list(items, regions: RegionsSection, where: str) -> tuple[MuscleSpec, ...]:
    """The scene's ``[[muscles]]`` (empty when it has none), checked: each a table, every region once,
    and ``[regions] muscles`` left at its default beside them (it names the pair they replace)."""
    if not isinstance(items, list) or not items:
        raise InputError(f"{where}: muscles must be an array of tables ([[muscles]] with region = ...), "
                         f"at least one, got {items!r}")
    muscles = tuple(muscle_from_table(item, f"{where}: [[muscles]] {number}") for number, item in enumerate(items, 1))
    seen = {}
    for number, muscle in enumerate(muscles, start=1):
        if muscle.region in seen:
            raise InputError(f"{where}: [[muscles]] {seen[muscle.region]} and {number} both name region "
                             f"'{muscle.region}'; muscles must be disjoint regions")
        seen[muscle.region] = number
    default_pair = RegionsSection().muscles
    if regions.muscles != default_pair:
        raise InputError(f"{where}: [regions] muscles = {list(regions.muscles)!r} and [[muscles]] both name the "
                         "muscles; give the regions in the [[muscles]] tables only")
    return muscles


MIN_STEPS_PER_PERIOD = 10
"""Fewest time steps h per activation period 1/f_j: below, the steps sample sin(2π f_j t) too
coarsely, and far below they alias it (f = 1e9 Hz at h = 0.02 s drives a slow wave of another
frequency)."""

YOUNG_MODULUS_RANGE = (1e3, 1e9)
"""Plausible Young's modulus of a soft swimmer [Pa]: 1 kPa (gel) to 1 GPa (stiff plastic)."""

FULL_ACTIVATION = 1.0
"""An amplitude A up to this is taken as a plausible activation level: a peak muscle stress too
large at such an A blames [actuation] stiffness (or E outside :data:`YOUNG_MODULUS_RANGE`), above
it [actuation] amplitude."""


def fibre_modulus(material) -> float:
    """M = λ + 2μ = E (1 - ν) / ((1 + ν)(1 - 2ν)) [Pa]: the body's small-strain stiffness along a
    fibre held laterally by the tissue around it (E for a free fibre, ν = 0)."""
    nu = material.poisson_ratio
    return material.young_modulus * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))


def activation_ratio(stiffness: float, amplitude: float, scale: float, modulus: float) -> float:
    """Peak muscle stress over a modulus, k A |s| / modulus (0 when a factor is 0; inf on overflow).

    Along its fibres a muscle at activation a has the stiffness M + k a (the energy ½ k a |F m|²
    adds k a): the muscle driven at a = -A |s| (every muscle of an antagonist pair, half of each
    period) has none left at k A |s| = M. Measured on the level-1 block (k A = 12 kPa): E = 8 kPa
    (k A / M = 0.7) swims to the end, E = 6 kPa (0.93) stops the PROM near t = 0.96 s."""
    if stiffness == 0.0 or amplitude == 0.0 or scale == 0.0:
        return 0.0
    return stiffness / modulus * amplitude * abs(scale)


def scales(largest: float) -> str:
    """' (largest muscle |scale| s)' when it is not 1, for messages."""
    return "" if largest == 1.0 else f" (largest muscle |scale| {largest:g})"



def _activation_key(number: int | None, muscle) -> str:
    """The key that sets a muscle's frequency: its own, or [actuation] frequency."""
    if muscle.frequency is not None:
        return f"[[muscles]] {number} (region '{muscle.region}') frequency"
    return "[actuation] frequency" + (f" (of [[muscles]] {number}, region '{muscle.region}')" if number else "")


def driven_muscles(scene) -> list[tuple[int | None, MuscleSpec]]:
    """(table number or None for the [regions] pair, muscle) of each muscle the scene drives: none
    when k or A is zero, and never a muscle of scale 0."""
    if not (scene.actuation.stiffness > 0 and scene.actuation.amplitude > 0):
        return []
    numbered = enumerate(scene.muscles, start=1) if scene.muscles else ((None, m) for m in scene.actuated_muscles)
    return [(number, muscle) for number, muscle in numbered if muscle.scale != 0.0]


def check_actuation(scene) -> None:
    """InputError naming the key at fault: a muscle that is the head region, a driven muscle whose
    period 1/f_j spans fewer than :data:`MIN_STEPS_PER_PERIOD` time steps, or a peak muscle stress
    k A |s_j| of the body's fibre stiffness M or more (:func:`activation_ratio`; of [actuation]
    amplitude or stiffness, a muscle's scale, [material] young_modulus, [cooptimization]
    amplitude_bounds or [reduction] stroke_amplitude)."""
    where = f"scene {scene.source}"
    if not scene.muscles and scene.regions.head in scene.regions.muscles:
        raise InputError(f"{where}: [regions] muscles = {list(scene.regions.muscles)!r} names the stiff head "
                         f"([regions] head = '{scene.regions.head}'); the muscles must be regions other than the head")
    for number, muscle in enumerate(scene.muscles, start=1):
        if muscle.region == scene.regions.head:
            raise InputError(f"{where}: [[muscles]] {number} names region '{muscle.region}', the stiff head "
                             f"([regions] head); a muscle must be a region of the body other than the head")
    _check_periods(scene, where)
    _check_activation_strain(scene, where)


def _check_periods(scene, where: str) -> None:
    step = scene.solver.time_step
    largest = 1.0 / (MIN_STEPS_PER_PERIOD * step)
    for number, muscle in driven_muscles(scene):
        frequency = scene.actuation.frequency if muscle.frequency is None else muscle.frequency
        if frequency * step * MIN_STEPS_PER_PERIOD > 1.0 + 1e-9:
            raise InputError(f"{where}: {_activation_key(number, muscle)} = {frequency:g} Hz has a period of "
                             f"{1.0 / frequency:.3g} s, fewer than {MIN_STEPS_PER_PERIOD} time steps of [solver] "
                             f"time_step = {step:g} s (the steps would alias the activation); give frequency <= "
                             f"{largest:.4g} Hz or time_step <= {1.0 / (MIN_STEPS_PER_PERIOD * frequency):.3g} s")


def _check_activation_strain(scene, where: str) -> None:
    actuation, modulus = scene.actuation, fibre_modulus(scene.material)
    driven = driven_muscles(scene)
    largest_scale = max((abs(muscle.scale) for _, muscle in driven), default=1.0)
    over = [(number, muscle) for number, muscle in driven
            if activation_ratio(actuation.stiffness, actuation.amplitude, muscle.scale, modulus) >= 1.0]
    if over:
        raise InputError(f"{where}: {_strain_problem(scene, *over[0], largest_scale)}")
    for key, value, on in (("[cooptimization] amplitude_bounds upper bound", scene.cooptimization.amplitude_bounds[1],
                            scene.cooptimization.enabled),
                           ("[reduction] stroke_amplitude", stroke_amplitude(scene), True)):
        if on and activation_ratio(actuation.stiffness, value, largest_scale, modulus) >= 1.0:
            raise InputError(f"{where}: {key} = {value:g}{scales(largest_scale)} with [actuation] stiffness k = "
                             f"{actuation.stiffness:g} Pa: {_limit(scene)} at that amplitude; give a value below "
                             f"{modulus / actuation.stiffness / largest_scale:.3g}")


def _limit(scene) -> str:
    material = scene.material
    return (f"the peak muscle stress k A |s_j| must stay below the body's fibre stiffness M = E (1 - ν) / "
            f"((1 + ν)(1 - 2ν)) = {fibre_modulus(material):.3g} Pa (E = {material.young_modulus:g} Pa, "
            f"ν = {material.poisson_ratio:g}), or the muscle driven at a = -A |s_j| has no stiffness left")


def _strain_problem(scene, number, muscle, largest_scale: float) -> str:
    """What is at fault when a driven muscle's stress k A |s_j| reaches M: its scale when A and k are
    fine at s = 1; else E when outside :data:`YOUNG_MODULUS_RANGE`, k when A is a plausible
    activation level (<= 1), else A."""
    actuation, material = scene.actuation, scene.material
    modulus, limit = fibre_modulus(material), _limit(scene)
    stress = f"[actuation] stiffness k = {actuation.stiffness:g} Pa and amplitude A = {actuation.amplitude:g}"
    if activation_ratio(actuation.stiffness, actuation.amplitude, 1.0, modulus) < 1.0:
        return (f"[[muscles]] {number} (region '{muscle.region}') scale = {muscle.scale:g} with {stress}: {limit}; "
                f"give |scale| < {modulus / actuation.stiffness / actuation.amplitude:.3g}")
    low, high = YOUNG_MODULUS_RANGE
    if not low <= material.young_modulus <= high:
        return (f"[material] young_modulus = {material.young_modulus:g} Pa with {stress}{scales(largest_scale)}: "
                f"{limit}; E is in pascals (260 kPa = 260e3), plausible {low:g}-{high:g} Pa")
    if actuation.amplitude <= FULL_ACTIVATION:
        ceiling = modulus / actuation.amplitude / largest_scale
        return (f"[actuation] stiffness = {actuation.stiffness:g} Pa with amplitude A = {actuation.amplitude:g}"
                f"{scales(largest_scale)}: {limit}; give stiffness in [0, {ceiling:.3g}) Pa (default "
                f"{ActuationSection().stiffness:g})")
    ceiling = modulus / actuation.stiffness / largest_scale
    return (f"[actuation] amplitude = {actuation.amplitude:g}{scales(largest_scale)} with stiffness k = "
            f"{actuation.stiffness:g} Pa: {limit}; give amplitude in [0, {ceiling:.3g}) (default "
            f"{ActuationSection().amplitude:g})")


START_RAMP_PERIODS = 0.25
"""The automatic smooth start lasts this many periods of the slowest driven muscle: τ = 1/(4 f),
0.25 s at 1 Hz. r(t) = sin²(π t / 2τ) then rises at most at π/(2τ) = 2π f per second, as fast as
sin(2π f t) itself, so that the envelope loads the body no faster than the gait it starts. Measured
on the shipped fish wave (level 1, 2 s): docs/devlog.md, "a gait that starts smoothly"."""

JUMP_TOLERANCE = 1e-9
"""A muscle starts with a jump when |sin φ_j| exceeds this (sin 180° is 1.2e-16 in floating point)."""


def start_activation(muscle, amplitude: float) -> float:
    """a_j(0) = A s_j sin φ_j of a muscle without smooth start (φ_j in degrees, reduced exactly first)."""
    return amplitude * muscle.scale * math.sin(math.radians(math.fmod(muscle.phase, 360.0)))


def abrupt_muscles(scene) -> list[tuple[int | None, MuscleSpec, float]]:
    """(table number, muscle, a_j(0)) of each driven muscle whose activation would jump at t = 0:
    a_j(0) = A s_j sin φ_j with |sin φ_j| > :data:`JUMP_TOLERANCE` (a phase other than 0° or 180°)."""
    amplitude = scene.actuation.amplitude
    return [(number, muscle, start_activation(muscle, amplitude)) for number, muscle in driven_muscles(scene)
            if abs(math.sin(math.radians(math.fmod(muscle.phase, 360.0)))) > JUMP_TOLERANCE]


def start_ramp_time(scene) -> float:
    """τ [s] of the gait's smooth start r(t): ``[actuation] start_ramp`` when given; for "auto" 0 (SPEC
    §5's law) when no driven muscle jumps at t = 0 (:func:`abrupt_muscles`), else
    :data:`START_RAMP_PERIODS` periods of the slowest driven muscle, for every muscle of the gait (one
    envelope keeps the wave's shape while it grows, and a(t) = A r(t) Σ_k c_k(t) P_k). With a ``[gait]``
    phase_lag variable "auto" ramps at every lag, 0° and 180° too, so that τ does not jump across the
    design space."""
    ramp = scene.actuation.start_ramp
    if ramp != "auto":
        return ramp
    lag_varies = any(variable.name == "phase_lag" for variable in getattr(scene, "gait", ()))
    return _quarter_period(scene) if abrupt_muscles(scene) or (lag_varies and driven_muscles(scene)) else 0.0


def _quarter_period(scene) -> float:
    """:data:`START_RAMP_PERIODS` periods 1/f_j of the slowest driven muscle [s]."""
    slowest = min(scene.actuation.frequency if muscle.frequency is None else muscle.frequency
                  for _, muscle in driven_muscles(scene))
    return START_RAMP_PERIODS / slowest


def warn_abrupt_start(scene) -> None:
    """One warning line when the scene asks ``start_ramp = 0`` and a driven muscle jumps at t = 0 (the
    first such muscle and its a_j(0)): the jump rings the body's stiff modes and the solver cuts its
    steps (the shipped fish wave, level 1: 41 cut steps, 16.5 Newton iterations per step, against none
    and 5.08 with the automatic start; docs/devlog.md)."""
    abrupt = abrupt_muscles(scene) if scene.actuation.start_ramp == 0.0 else []
    if not abrupt:
        return
    number, muscle, value = abrupt[0]
    more = f" and {len(abrupt) - 1} more muscle(s)" if len(abrupt) > 1 else ""
    logging.getLogger("aquarom").warning(
        "warning: scene %s: [actuation] start_ramp = 0 and [[muscles]] %s (region '%s', phase %g°) starts with "
        "a jump a_j(0) = %.3g%s; leave start_ramp out (\"auto\": %g s) for a smooth start",
        scene.source, number, muscle.region, muscle.phase, value, more,
        _quarter_period(scene))


MAX_AUTO_MODES = 8
"""The most vibration modes "auto" takes (n_vm² / 2 modal derivatives follow them; a gait of more muscle
groups gets this many, with a warning, or a number of its own in [reduction] vibration_modes)."""
PHASE_DIGITS = 6
"""Phases (degrees, modulo 180°) equal to this many decimals make one muscle group."""


def muscle_groups(scene) -> int:
    """G: the number of distinct activation rhythms of the driven muscles, a muscle's rhythm being its
    frequency and its phase modulo 180° (a muscle in antiphase, or of scale -1, moves with its
    partner); 0 without actuation."""
    keys = set()
    for _, muscle in driven_muscles(scene):
        frequency = scene.actuation.frequency if muscle.frequency is None else muscle.frequency
        keys.add((frequency, round(math.fmod(math.fmod(muscle.phase, 180.0) + 180.0, 180.0), PHASE_DIGITS) % 180.0))
    return len(keys)


def scene_vibration_modes(scene) -> int | None:
    """n_vm as the scene alone decides it: the number given, 1 for "auto" with at most one muscle
    group; None when "auto" is decided by the modes of the body (reduction/mode_count.py)."""
    value = scene.reduction.vibration_modes
    if value != "auto":
        return int(value)
    return 1 if muscle_groups(scene) <= 1 else None


def planned_vibration_modes(scene) -> int:
    """n_vm for cost estimates before any mode is computed: the scene's own, else G + 1 (the G
    lateral modes and one out-of-plane mode among them, as on the shipped block and fish), at most
    :data:`MAX_AUTO_MODES`."""
    known = scene_vibration_modes(scene)
    return known if known is not None else min(muscle_groups(scene) + 1, MAX_AUTO_MODES)


def stroke_amplitude(scene) -> float:
    """A_s of the stroke vectors: ``[reduction] stroke_amplitude`` when given; for "auto" 0 (off) on the
    built-in block, whose SPEC §7 basis follows its strokes (the nominal ROM -0.06 % without them at
    A = 0.2), and on a body from a mesh file the largest amplitude the scene runs, [actuation]
    amplitude or with co-optimisation the upper bound of A (the fish's ROM +1.84 % without them and
    +0.13 % with, the example swimmer of docs/your_own_swimmer.md -5.05 % and -0.24 %)."""
    value = scene.reduction.stroke_amplitude
    if value != "auto":
        return value
    if scene.mesh_file is None:
        return 0.0
    return scene.cooptimization.amplitude_bounds[1] if scene.cooptimization.enabled else scene.actuation.amplitude
