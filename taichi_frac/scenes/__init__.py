"""Scenes: what to simulate, from a TOML file (:func:`load_scene`) or built in Python.

See ``description.py`` for the fields and ``docs/readme/foundation.md`` for the format.
"""

from .description import (
    Collider,
    OutputSettings,
    Scene,
    SceneObject,
    SimulationSettings,
    euler_deg_to_quaternion,
)
from .loader import load_scene, scene_from_dict

__all__ = [
    "Collider",
    "OutputSettings",
    "Scene",
    "SceneObject",
    "SimulationSettings",
    "euler_deg_to_quaternion",
    "load_scene",
    "scene_from_dict",
]
