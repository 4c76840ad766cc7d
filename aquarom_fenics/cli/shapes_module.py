"""``--shapes-module``: the Python module that registers the scene's shape fields of one's own
(``register_shape_field``), imported before the scene is read; a scene file never imports code.

Every MPI rank imports it (each reads the scene). Worker processes started afresh do not: a scene
with such a field runs its tasks in this process (:func:`require_in_process`).
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from aquarom_fenics.errors import InputError

_IMPORTED: dict[str, tuple[str, ...]] = {}
"""The fields each module (by resolved path or name) registered when it was last imported here."""


def module_spec(given: str):
    """(spec, key) of a module file (``*.py``, or any existing file) or a dotted module name on
    ``sys.path``; InputError naming what is missing."""
    path = Path(given)
    if given.endswith(".py") or path.exists():
        if not path.is_file():
            raise InputError(f"--shapes-module {given}: no such file (give a Python file that registers "
                             "shape fields, or the name of such a module on the Python path)")
        stem = path.stem if path.stem.isidentifier() else "shapes"
        return importlib.util.spec_from_file_location(f"aquarom_shapes_module_{stem}", path), str(path.resolve())
    if not all(part.isidentifier() for part in given.split(".")):
        raise InputError(f"--shapes-module {given}: neither a file nor a module name (a.b.c)")
    try:
        spec = importlib.util.find_spec(given)
    except (ImportError, ValueError):          # a parent package that is missing
        spec = None
    if spec is None:
        raise InputError(f"--shapes-module {given}: no such module on the Python path (give a file path ending "
                         "in .py, or add its folder to PYTHONPATH)")
    return spec, f"module {given}"


def failure(error: BaseException) -> str:
    """One line for an exception raised while the module ran."""
    if isinstance(error, SyntaxError):
        return f"SyntaxError: {error.msg} (line {error.lineno})"
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


def import_shapes_module(given: str) -> tuple[str, ...]:
    """Run the module ``given`` afresh (the fields it registered at an earlier import in this process
    are unregistered first) and return the names of the shape fields it registered; InputError (one
    line) for a module that cannot be found or run, or that registers none."""
    from aquarom_fenics.geometry import fish  # noqa: F401 — the hash of a scene with such a field reads its mesh
    from aquarom_fenics.geometry.shape_registry import registered_fields, unregister_shape_field

    spec, key = module_spec(given)
    for name in _IMPORTED.pop(key, ()):
        if name in registered_fields():
            unregister_shape_field(name)
    before = set(registered_fields())
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as error:  # noqa: BLE001 — the user's code: any failure is one line
        for name in set(registered_fields()) - before:
            unregister_shape_field(name)
        sys.modules.pop(spec.name, None)
        detail = str(error) if isinstance(error, InputError) else f"importing it failed: {failure(error)}"
        raise InputError(f"--shapes-module {given}: {detail}") from None
    registered = tuple(name for name in registered_fields() if name not in before)
    if not registered:
        raise InputError(f"--shapes-module {given}: it registers no shape field (call "
                         "aquarom_fenics.api.register_shape_field(name, value, gradient) in it)")
    _IMPORTED[key] = registered
    return registered


def require_used(given: str, registered: tuple[str, ...], scene) -> None:
    """InputError unless the scene uses one of the fields the module registered."""
    if not set(registered) & set(scene.shape_names):
        raise InputError(f"--shapes-module {given} registers {', '.join(registered)}; scene {scene.source} uses "
                         f"none of them ([shapes]: {', '.join(scene.shape_names) or 'none'})")


def require_in_process(args, scene, workers: int, distributed: bool) -> None:
    """InputError when tasks of a scene with a field registered here would go to other processes."""
    from aquarom_fenics.geometry.shape_registry import uses_registered

    if uses_registered(scene.shape_names) and (workers > 1 or distributed):
        raise InputError(f"scene {scene.source} uses shape fields registered by --shapes-module, which worker "
                         f"processes started afresh do not import: run its {args.command} tasks in this process "
                         "(--workers 1, and no --scheduler or [cluster] scheduler)")
