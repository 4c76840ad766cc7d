"""The ``[gait]`` table of a scene: the gait's design variables, declared with bounds as ``[shapes]``.

    [gait]
    frequency = { bounds = [0.5, 2.0] }                 # f [Hz] of every muscle of the gait
    phase_lag = { bounds = [60.0, 180.0], start = 120.0 }   # λ [degrees] between consecutive pairs
    amplitude_1 = { bounds = [0.1, 0.3] }               # pair 1's amplitude A_1 = |s_j| A [-]

The gait's muscles are its pairs: the ``[[muscles]]`` of regions ``left_k`` and ``right_k``
(k = 1 … n, numbered from the tail, the regions of the block's ``[regions] muscle_pairs`` and of
the shipped fish), or, without ``[[muscles]]``, the pair ``[regions] muscles`` (k = 1). The pairs are
read from the regions' names, not from the rhythms (``scene_muscles.muscle_groups``): a group is
defined by the phases the variables change. In a pair both muscles have one phase and one frequency
and opposite scales of one size (the right in antiphase with the left); every driven muscle belongs
to a pair. The variables map onto the muscles' keys (:func:`apply_gait`):

    f_j = f for every muscle;  φ_j = (k - 1) λ for both muscles of pair k;
    s_j = ± A_k / A for both muscles of pair k (A = ``[actuation] amplitude``, the sign kept).

A variable's start is the scene's value unless given (f: the pairs' frequency; λ: φ_2 - φ_1, the
phases having to be (k - 1) λ; A_k: |s_j| A). The co-design's amplitude (``[cooptimization]``) is
the global A, the same variable: it is not declared here, and per-pair amplitudes are refused with
it (A would then scale nothing the pairs' A_k do not).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from aquarom_fenics.errors import InputError

GAIT_KEYS = ("bounds", "start")
"""The keys of a gait variable's table."""

PAIR_REGION = re.compile(r"(left|right)_([1-9][0-9]*)")


@dataclass(frozen=True)
class GaitVariable:
    """One design variable of the gait: its name, bounds and start (None: the scene's value, resolved
    by :func:`resolve_gait`)."""
    name: str
    lower: float
    upper: float
    start: float | None = None


@dataclass(frozen=True)
class GaitPair:
    """Pair k (from 1 at the tail): the indices of its two muscles in ``Scene.actuated_muscles``."""
    number: int
    muscles: tuple[int, int]


def _number(value, where: str) -> float:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    raise InputError(f"{where} must be a finite number, got {value!r}")


def gait_from_table(table: dict, where: str) -> tuple[GaitVariable, ...]:
    """The variables of a ``[gait]`` table, checked for their form (names, keys, bounds, start in bounds);
    what they mean for the scene's muscles is checked by :func:`resolve_gait`."""
    variables = []
    for name, spec in table.items():
        if name not in ("frequency", "phase_lag") and not re.fullmatch(r"amplitude_[1-9][0-9]*", name):
            raise InputError(f"{where}: unknown [gait] variable '{name}'; valid names: frequency, phase_lag, "
                             "amplitude_1 … amplitude_n (pair k's amplitude; the global amplitude is "
                             "[cooptimization]'s)")
        if not isinstance(spec, dict):
            raise InputError(f"{where}: [gait] {name} must be a table like {{ bounds = [0.5, 2.0], start = 1.0 }}")
        for key in spec:
            if key not in GAIT_KEYS:
                raise InputError(f"{where}: unknown key {key} of [gait] {name}; valid keys: {', '.join(GAIT_KEYS)}")
        bounds = spec.get("bounds")
        if not isinstance(bounds, (list, tuple)) or len(bounds) != 2:
            raise InputError(f"{where}: [gait] {name} needs bounds = [lower, upper], got {bounds!r}")
        lower, upper = (_number(value, f"{where}: [gait] {name} bounds") for value in bounds)
        if lower > upper:
            raise InputError(f"{where}: [gait] {name} bounds = [{lower:g}, {upper:g}]: lower bound above upper")
        if name != "phase_lag" and lower <= 0.0:
            raise InputError(f"{where}: [gait] {name} bounds = [{lower:g}, {upper:g}]: the lower bound must be > 0")
        start = _number(spec["start"], f"{where}: [gait] {name} start") if "start" in spec else None
        variables.append(GaitVariable(name, lower, upper, start))
    return tuple(variables)


def gait_pairs(muscles, regions) -> list[GaitPair]:
    """The pairs of a scene's muscles (``muscles`` = ``Scene.actuated_muscles``), from the tail: the
    regions ``left_k``/``right_k`` (k = 1 … n) or the ``[regions] muscles`` pair; [] when there are none."""
    names = [muscle.region for muscle in muscles]
    if tuple(names) == tuple(regions.muscles):
        return [GaitPair(1, (0, 1))]
    found = {}
    for index, name in enumerate(names):
        match = PAIR_REGION.fullmatch(name)
        if match:
            found[(match.group(1), int(match.group(2)))] = index
    pairs, number = [], 1
    while ("left", number) in found and ("right", number) in found:
        pairs.append(GaitPair(number, (found[("left", number)], found[("right", number)])))
        number += 1
    return pairs


def resolve_gait(variables, muscles, actuation, regions, cooptimization, time_step: float,
                 where: str) -> tuple[GaitVariable, ...]:
    """The variables with their starts filled in from the scene, after checking that they fit its
    muscles (pairs, phases, frequencies, scales), its time step and its co-design; InputError, one line."""
    if not variables:
        return ()
    pairs = gait_pairs(muscles, regions)
    if not pairs:
        raise InputError(f"{where}: [gait] {variables[0].name} needs muscle pairs: [[muscles]] of regions left_k and "
                         f"right_k (k = 1 … n from the tail) or the [regions] muscles pair; this scene drives "
                         f"{', '.join(m.region for m in muscles)}")
    paired = {index for pair in pairs for index in pair.muscles}
    loose = [m.region for i, m in enumerate(muscles) if i not in paired and m.scale != 0.0]
    if loose:
        raise InputError(f"{where}: [gait] needs every driven muscle in a pair left_k/right_k; '{loose[0]}' is in none "
                         f"(pairs 1 … {len(pairs)} found)")
    frequencies = {actuation.frequency if m.frequency is None else m.frequency for m in muscles}
    if len(frequencies) > 1:
        raise InputError(f"{where}: [gait] drives its muscles at one frequency; the scene's muscles have "
                         f"{', '.join(f'{f:g}' for f in sorted(frequencies))} Hz")
    for pair in pairs:
        left, right = (muscles[i] for i in pair.muscles)
        if (math.fmod(left.phase - right.phase, 360.0) != 0.0 or left.scale != -right.scale or left.scale == 0.0):
            raise InputError(f"{where}: [gait] pair {pair.number} ('{left.region}', '{right.region}') must have one "
                             f"phase and opposite scales of one size (the right in antiphase); got phases "
                             f"{left.phase:g}, {right.phase:g} and scales {left.scale:g}, {right.scale:g}")
    resolved = []
    for variable in variables:
        _check_variable(variable, pairs, actuation, cooptimization, time_step, where)
        start = variable.start
        if start is None:
            start = scene_gait_value(variable.name, pairs, muscles, actuation, where)
        if not variable.lower <= start <= variable.upper:
            raise InputError(f"{where}: [gait] {variable.name} start = {start:g} outside its bounds [{variable.lower:g}, "
                             f"{variable.upper:g}]" + ("" if variable.start is not None else
                                                      " (the start is the scene's value: give one)"))
        resolved.append(GaitVariable(variable.name, variable.lower, variable.upper, start))
    return tuple(resolved)


def pair_number(name: str) -> int | None:
    """k of ``amplitude_k``; None for the other variables."""
    return int(name.split("_")[1]) if name.startswith("amplitude_") else None


def scene_gait_value(name: str, pairs, muscles, actuation, where: str) -> float:
    """A variable's value in the scene as written: f, λ = φ_2 - φ_1 (the phases must be (k - 1) λ) or |s_j| A."""
    if name == "frequency":
        first = muscles[pairs[0].muscles[0]]
        return actuation.frequency if first.frequency is None else first.frequency
    if name == "phase_lag":
        phases = [muscles[pair.muscles[0]].phase for pair in pairs]
        lag = phases[1] - phases[0] if len(phases) > 1 else 0.0
        if any(not _same_angle(phase - phases[0], k * lag) for k, phase in enumerate(phases)):
            raise InputError(f"{where}: [gait] phase_lag without start needs the pairs' phases (k - 1) x lag; the "
                             f"scene has {', '.join(f'{p:g}' for p in phases)} degrees: give phase_lag a start")
        return math.fmod(lag, 360.0)
    return abs(muscles[pairs[pair_number(name) - 1].muscles[0]].scale) * actuation.amplitude


def _same_angle(first: float, second: float) -> bool:
    """Whether two angles in degrees agree modulo 360 (to 1e-9 degrees)."""
    difference = math.fmod(first - second, 360.0)
    return min(abs(difference), 360.0 - abs(difference)) < 1e-9


def _check_variable(variable, pairs, actuation, cooptimization, time_step, where) -> None:
    """InputError when a variable does not fit the scene's pairs, time step or co-design."""
    name, upper = variable.name, variable.upper
    if name == "phase_lag" and len(pairs) < 2:
        raise InputError(f"{where}: [gait] phase_lag needs at least two muscle pairs; the scene has one")
    if name == "frequency" and upper * time_step * 10 > 1.0 + 1e-9:
        raise InputError(f"{where}: [gait] frequency upper bound {upper:g} Hz has a period of fewer than 10 time "
                         f"steps of [solver] time_step = {time_step:g} s; give at most {0.1 / time_step:.4g} Hz")
    number = pair_number(name)
    if number is None:
        return
    if number > len(pairs):
        raise InputError(f"{where}: [gait] {name}: the scene has {len(pairs)} muscle pair(s), numbered from the tail")
    if cooptimization.enabled:
        raise InputError(f"{where}: [gait] {name} with [cooptimization] enabled: the co-design's amplitude A and a "
                         "pair's amplitude would both set that pair; give per-pair amplitudes or the co-design")
    if actuation.amplitude <= 0.0:
        raise InputError(f"{where}: [gait] {name} needs [actuation] amplitude > 0 (a pair's scale is A_k / A)")


def gait_values(variables, z) -> dict[str, float]:
    """{name: value} of the gait's variables in design-vector order."""
    return {variable.name: float(value) for variable, value in zip(variables, z)}


def apply_gait(scene, values: dict[str, float]):
    """The scene driven by the gait ``values`` ({variable name: value}, names of its ``[gait]``; the others
    keep their start): the muscles' frequency, phases and scales as in the module's law, validated as a
    scene (a frequency whose period spans too few steps, a pair's stress above the fibre stiffness)."""
    import dataclasses

    unknown = [name for name in values if name not in {v.name for v in scene.gait}]
    if unknown:
        raise ValueError(f"{unknown[0]} is not a gait variable of scene {scene.name}")
    gait = {variable.name: variable.start for variable in scene.gait} | dict(values)
    muscles = list(scene.actuated_muscles)
    pairs = gait_pairs(muscles, scene.regions)
    actuation = scene.actuation
    if "frequency" in gait:
        actuation = dataclasses.replace(actuation, frequency=gait["frequency"])
        muscles = [m if m.frequency is None else dataclasses.replace(m, frequency=gait["frequency"]) for m in muscles]
    if not scene.muscles:          # the [regions] pair: s = ±1, so its amplitude A_1 is A itself
        if "amplitude_1" in gait:
            actuation = dataclasses.replace(actuation, amplitude=gait["amplitude_1"])
        return dataclasses.replace(scene, actuation=actuation)
    for pair in pairs:
        for index in pair.muscles:
            muscle, changes = muscles[index], {}
            if "phase_lag" in gait:
                changes["phase"] = float((pair.number - 1) * gait["phase_lag"])
            if f"amplitude_{pair.number}" in gait:
                changes["scale"] = math.copysign(gait[f"amplitude_{pair.number}"] / scene.actuation.amplitude,
                                                 muscle.scale)
            muscles[index] = dataclasses.replace(muscle, **changes)
    return dataclasses.replace(scene, actuation=actuation, muscles=tuple(muscles))


def check_gait_bounds(scene) -> None:
    """InputError, one line, when the scene driven at a variable's bound (the others at their start)
    is refused (``Scene.__post_init__``: a period of too few steps, a pair's stress above the fibre stiffness)."""
    for variable in scene.gait:
        for side, value in (("lower", variable.lower), ("upper", variable.upper)):
            try:
                apply_gait(scene, {variable.name: value})
            except InputError as error:
                reason = str(error).split(": ", 1)[-1]
                raise InputError(f"scene {scene.source}: [gait] {variable.name} at its {side} bound {value:g}: "
                                 f"{reason}") from None


def pair_patterns(scene) -> tuple[tuple[float, ...], ...]:
    """Each pair's activation pattern (its muscles at sign(s_j), the others 0), from the tail, when the
    scene's phase lag or a pair's amplitude is a design variable (they move a(t) out of the span of the
    scene's own patterns; ``ActivationLaw.patterns``); () otherwise."""
    if not any(variable.name != "frequency" for variable in scene.gait):
        return ()
    muscles = scene.actuated_muscles
    patterns = []
    for pair in gait_pairs(muscles, scene.regions):
        pattern = [0.0] * len(muscles)
        for index in pair.muscles:
            pattern[index] = math.copysign(1.0, muscles[index].scale)
        patterns.append(tuple(pattern))
    return tuple(patterns)
