"""Hints that make a failure explain itself: suspicious scene values and Newton-failure advice.

Every hint is one line of text. ``scene_warnings`` looks at the scene alone (units that are
probably wrong); ``newton_failure_hints`` adds what to try after a time step failed, and, given
the FOM, compares its first natural frequency with the actuation frequency.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from aquarom_fenics.geometry.body import LENGTH_RANGE
from aquarom_fenics.io.scene import Scene
from aquarom_fenics.io.scene_muscles import FULL_ACTIVATION, YOUNG_MODULUS_RANGE, activation_ratio, driven_muscles

if TYPE_CHECKING:
    from aquarom_fenics.geometry.fish import Fish
    from aquarom_fenics.fem.fom import FullOrderModel

DENSITY_RANGE = (100.0, 20000.0)
"""Plausible density of a body or a fluid [kg/m³]."""

BODY_LENGTH_RANGE = LENGTH_RANGE
"""Plausible body length [m]: the range outside which a mesh is refused (``geometry.body``)."""

MUSCLE_STRESS_LIMIT = 0.2
"""Peak muscle stress k·A above this fraction of E makes the soft body buckle (reference fish: 0.046)."""

RESONANCE_BAND = 0.3
"""Actuation within this relative distance of the first natural frequency counts as resonant."""


def scene_warnings(scene: Scene, fish: "Fish | None" = None) -> list[str]:
    """Values whose units look wrong: E [Pa], densities [kg/m³], body length [m].

    The body length is the built-in block's ``[mesh] length``, or, given the ``fish``, the
    length of its mesh (needed for a mesh file, whose size the scene does not know).
    """
    material, fluid = scene.material, scene.fluid
    warnings = []
    low, high = YOUNG_MODULUS_RANGE
    if not low <= material.young_modulus <= high:
        warnings.append(f"[material] young_modulus = {material.young_modulus:g} Pa is outside "
                        f"{low:g}-{high:g} Pa: E is in pascals (260 kPa = 260e3)")
    low, high = DENSITY_RANGE
    for key, value in (("[material] density", material.density), ("[fluid] density", fluid.density)):
        if not low <= value <= high:
            warnings.append(f"{key} = {value:g} kg/m³ is outside {low:g}-{high:g} kg/m³: "
                            f"densities are in kg/m³ (water: 1000)")
    length = body_length(scene, fish)
    low, high = BODY_LENGTH_RANGE
    if length is not None and not low <= length <= high:
        question = "did you give the mesh in millimetres?" if length > high else "is the mesh scaled twice?"
        warnings.append(f"body length {length:g} m is outside {low:g}-{high:g} m: {question} "
                        f"{_length_remedy(scene)}")
    return warnings


def body_length(scene: Scene, fish: "Fish | None" = None) -> float | None:
    """Length of the fish along x [m]; None for a mesh file when the fish is not given."""
    if fish is not None:
        return fish.tags.box.length
    if scene.mesh.file:
        return None
    return scene.mesh.length


def _length_remedy(scene: Scene) -> str:
    """Where lengths [m] are set: the file's scale factor or the block's dimensions."""
    if scene.mesh.file:
        return "use [mesh] scale (0.001 for millimetres)"
    return "[mesh] length, width and height are in metres"


def newton_failure_hints(scene: Scene, model: "FullOrderModel | None" = None) -> list[str]:
    """What to try after a time step failed, likeliest cause first: suspicious units, softer
    muscles, a smaller step, and the model's first natural frequency [Hz] against the
    actuation's (only with the FOM)."""
    hints = scene_warnings(scene, model.fish if model is not None else None)
    hints += [muscle_stiffness_hint(scene), time_step_hint(scene)]
    if model is not None:
        hints.append(natural_frequency_hint(scene, model))
    return [hint for hint in hints if hint]


def time_step_hint(scene: Scene) -> str:
    """Halve h [s]: the horizon stays a whole number of steps."""
    step = scene.solver.time_step
    return f"try a smaller time step, [solver] time_step = {step / 2:g} (h/2 of {step:g} s)"


def muscle_stiffness_hint(scene: Scene) -> str | None:
    """Weaker muscles when the peak muscle stress k A |s_j| [Pa] is large against E [Pa]: a lower
    [actuation] amplitude when A is above full activation (1), else a lower stiffness k."""
    actuation, young_modulus = scene.actuation, scene.material.young_modulus
    scale = max((abs(muscle.scale) for _, muscle in driven_muscles(scene)), default=0.0)
    ratio = activation_ratio(actuation.stiffness, actuation.amplitude, scale, young_modulus)
    if ratio <= MUSCLE_STRESS_LIMIT:
        return None
    stress = (f"the peak muscle stress k·A{'' if scale == 1.0 else '·|s|'} = {ratio * young_modulus:.3g} Pa is "
              f"{100 * ratio:.0f}% of E = {young_modulus:.3g} Pa")
    if actuation.amplitude > FULL_ACTIVATION:
        limit = MUSCLE_STRESS_LIMIT * young_modulus / (actuation.stiffness * scale)
        return f"{stress}: try a lower amplitude, [actuation] amplitude <= {limit:.3g}"
    limit = MUSCLE_STRESS_LIMIT * young_modulus / (actuation.amplitude * scale)
    return f"{stress}: try a lower muscle stiffness, [actuation] stiffness <= {limit:.3g}"


def natural_frequency_hint(scene: Scene, model: "FullOrderModel") -> str | None:
    """First clamped-head natural frequency [Hz] against the actuation frequency [Hz]."""
    natural = first_natural_frequency(model)
    if natural is None:
        return None
    actuation = scene.actuation.frequency
    steps_per_period = 1.0 / (natural * scene.solver.time_step)
    text = (f"first natural frequency (head clamped) {natural:.3g} Hz against the actuation's {actuation:g} Hz, "
            f"{steps_per_period:.1f} time steps per natural period")
    if abs(actuation / natural - 1.0) < RESONANCE_BAND:
        text += ": the muscles drive the fish near resonance, change [actuation] frequency"
    elif actuation > natural:
        text += ": the muscles drive the fish faster than its first mode"
    return text


def first_natural_frequency(model: "FullOrderModel") -> float | None:
    """ω₁/2π [Hz] of the design at rest with the head clamped; None if the eigensolver fails."""
    from petsc4py import PETSc

    from aquarom_fenics.reduction.basis import clamped_stiffness, vibration_modes

    stiffness = clamped_stiffness(model)
    try:
        _, frequencies = vibration_modes(model, stiffness, 1)
    except (RuntimeError, PETSc.Error):
        return None
    finally:
        stiffness.destroy()
    return float(frequencies[0])
