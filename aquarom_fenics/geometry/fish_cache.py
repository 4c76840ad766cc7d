"""The fish of a scene, loaded once per process: the sweep's tasks and the validation's cases that
share a mesh, its regions and the shape set share one :class:`~aquarom_fenics.geometry.fish.Fish`."""
from __future__ import annotations

import json

from aquarom_fenics.io.scene import Scene

_FISH: dict = {}
"""Fish by :func:`fish_key`, kept for the life of the process (a worker's designs after its first)."""


def fish_key(scene: Scene) -> str:
    """What a fish is made of: the scene's [mesh] and [regions] sections, its muscles' regions and its
    shape names (with the registration of those registered in this process)."""
    from aquarom_fenics.geometry.shape_registry import registered_identity

    data = scene.to_dict()
    muscles = [muscle.region for muscle in scene.actuated_muscles]
    return json.dumps([data["mesh"], data["regions"], muscles, scene.shape_names,
                       registered_identity(scene.shape_names)], sort_keys=True)


def shared_fish(scene: Scene):
    """``load_fish(scene)``, loaded once per :func:`fish_key` in this process."""
    from aquarom_fenics.geometry.fish import load_fish

    key = fish_key(scene)
    if key not in _FISH:
        _FISH[key] = load_fish(scene)
    return _FISH[key]
