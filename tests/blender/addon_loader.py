"""Import the add-on's bpy-free modules (reader, schema) in plain Python: the package's
__init__ imports bpy, so the package is stood up as a bare module with its __path__."""

from __future__ import annotations

import importlib
import sys
import types
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[2] / "blender_addon" / "taichi_frac_blender"


def addon_module(name: str):
    if "taichi_frac_blender" not in sys.modules:
        package = types.ModuleType("taichi_frac_blender")
        package.__path__ = [str(PACKAGE_DIR)]
        sys.modules["taichi_frac_blender"] = package
    return importlib.import_module(f"taichi_frac_blender.{name}")
