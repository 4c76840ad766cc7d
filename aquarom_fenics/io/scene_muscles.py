"""The ``[[muscles]]`` tables of a scene: any number of muscles, each with its region, fibre and activation.

    a_j(t) = A s_j r(t) sin(2π f_j t + φ_j)      (A, r(t) and the default f_j of [actuation])

A scene without ``[[muscles]]`` drives the pair ``[regions] muscles`` = [left, right] in antiphase:
left s = 1, right s = -1 (both φ = 0), exactly the forces of the scenes written before the tables.
"""
from __future__ import annotations

import math

from aquarom_fenics.errors import InputError
from aquarom_fenics.io.scene_sections import MuscleSpec, RegionsSection

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
    """A direction [m_x, m_y, m_z], normalised to unit length; a zero vector is refused."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise InputError(f"{where} must be a direction [m_x, m_y, m_z] of 3 numbers, got {value!r}")
    components = [_number(component, where) for component in value]
    norm = math.sqrt(sum(c * c for c in components))
    if not norm > 0.0 or not math.isfinite(norm):
        raise InputError(f"{where} = {value!r} has no direction (zero length); give e.g. [1, 0, 0] (the body axis)")
    if abs(norm - 1.0) <= 4 * _EPSILON:        # already unit: kept, so that a written scene reads back the same
        return tuple(components)
    return tuple(c / norm for c in components)


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
