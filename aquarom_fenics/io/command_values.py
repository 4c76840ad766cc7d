"""Values given on the command line: a number, and ``--xi name=value`` design assignments checked
against a scene's shapes (InputError in one line naming the option otherwise)."""
from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

from aquarom_fenics.errors import InputError

if TYPE_CHECKING:
    from aquarom_fenics.io.scene import Scene


def parse_number(text: str, where: str) -> float:
    """A finite float from a command-line or file value; InputError naming ``where`` otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: '{text.strip()}' is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: '{text.strip()}' is not a finite number")
    return value


def parse_xi_assignments(assignments: list[str] | None, scene: Scene) -> dict[str, float]:
    """``["z_tail=0.1", …]`` → ``{"z_tail": 0.1}``; names must be shapes of the scene, each given once.

    A value outside the scene's bounds is accepted (any design can be simulated) with a warning.
    """
    values = {}
    for text in assignments or []:
        name, sep, number = text.partition("=")
        if not sep:
            raise InputError(f"--xi {text}: expected name=value, e.g. --xi y_thin=0.05")
        name = name.strip()
        if name not in scene.shape_names:
            valid = ", ".join(scene.shape_names) or "none: the scene has no [shapes]"
            raise InputError(f"--xi {text}: '{name}' is not a shape variation of scene {scene.name} (valid: {valid})")
        value = parse_number(number, f"--xi {text}")
        if name in values:
            raise InputError(f"--xi {text}: {name} is given twice (first {name}={values[name]:g}); give it once")
        shape = next(s for s in scene.shapes if s.name == name)
        if not shape.lower <= value <= shape.upper:
            logging.getLogger("aquarom").warning("warning: --xi %s is outside the scene's bounds [%g, %g] of %s "
                                                 "(simulated anyway; optimize starts only inside them)",
                                                 text, shape.lower, shape.upper, name)
        values[name] = value
    return values
