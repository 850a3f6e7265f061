"""Runs INSIDE Blender: register the add-on from the repository folder and time one import.

    .venv-blender/bin/python tests/blender/time_import.py CACHE.usdc
"""

import sys
import time
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "blender_addon"))
import taichi_frac_blender  # noqa: E402

bpy.ops.wm.read_factory_settings(use_empty=True)
taichi_frac_blender.register()
start = time.perf_counter()
bpy.ops.import_scene.taichi_frac(filepath=sys.argv[1])
elapsed = time.perf_counter() - start
objects = [o for o in bpy.data.objects if o.taichi_frac.prim_path]
keys = sum(len(fc.keyframe_points) for o in objects
           for fc in o.animation_data.action.layers[0].strips[0].channelbag(o.animation_data.action_slot).fcurves)
print(f"import: {len(objects)} objects, {keys} keyframes in {elapsed:.2f} s")
