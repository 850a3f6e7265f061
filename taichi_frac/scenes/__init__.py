"""Scenes: what to simulate, from a TOML file (:func:`load_scene`) or built in Python.

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
from .loader import apply_overrides, load_scene, scene_from_dict

__all__ = [
    "Collider",
    "apply_overrides",
    "OutputSettings",
    "Scene",
    "SceneObject",
    "SimulationOptions",
    "euler_deg_to_quaternion",
    "load_scene",
    "scene_from_dict",
]
