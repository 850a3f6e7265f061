"""Scenes: what to simulate, from a TOML file or a built-in scene's name (:func:`load_scene`)
or built in Python.

See ``description.py`` for the fields and ``docs/reference/scene-file.md`` for the format.
"""

from .description import (
    Collider,
    OutputSettings,
    Scene,
    SceneObject,
    SimulationOptions,
    euler_deg_to_quaternion,
)
from .loader import BUILTIN_SCENE_DIR, apply_overrides, builtin_scenes, find_scene, load_scene, scene_from_dict

__all__ = [
    "BUILTIN_SCENE_DIR",
    "Collider",
    "apply_overrides",
    "builtin_scenes",
    "find_scene",
    "OutputSettings",
    "Scene",
    "SceneObject",
    "SimulationOptions",
    "euler_deg_to_quaternion",
    "load_scene",
    "scene_from_dict",
]
