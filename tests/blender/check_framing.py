"""Runs INSIDE Blender: import a cache through the add-on and print, as JSON, the box
render_cache.framed_box frames at the given frames (tests/test_blender_render.py)."""

import json
import sys
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "blender_addon"))
import render_cache  # noqa: E402
import taichi_frac_blender  # noqa: E402

cache, frames = sys.argv[1], [int(f) for f in sys.argv[2].split(",")]
bpy.ops.wm.read_factory_settings(use_empty=True)
taichi_frac_blender.register()
collection = taichi_frac_blender.import_cache(bpy.context, cache)
low, high = render_cache.framed_box(list(collection.objects), frames)
print("BOX " + json.dumps({"low": list(low), "high": list(high)}))
