"""Runs INSIDE Blender (.venv-blender/bin/python, bpy 5.0): install the add-on zip, import
one cache through its operator and write, for each listed frame, every imported object's
world matrix and render visibility to a JSON file (the main environment compares them with
what pxr reads from the same cache: tests/test_blender_real_cache.py).

    .venv-blender/bin/python tests/blender/dump_import.py ADDON.zip CACHE.usdc OUT.json FRAME [FRAME ...]
"""

from __future__ import annotations

import json
import sys

import bpy


def main(argv):
    addon_zip, cache, out, *frames = argv
    result = bpy.ops.extensions.package_install_files(filepath=addon_zip, repo="user_default",
                                                      enable_on_install=True)
    assert result == {"FINISHED"}, result
    before = set(bpy.data.collections)
    # (every prim, the never-visible too: the test compares them all with pxr)
    assert bpy.ops.import_scene.taichi_frac(filepath=cache, skip_never_visible=False) == {"FINISHED"}
    (collection,) = [c for c in bpy.data.collections if c not in before and c.get("taichi_frac_cache")]
    scene = bpy.context.scene
    dump = {"objects": len(collection.all_objects), "frames": {}}
    for frame in map(int, frames):
        scene.frame_set(frame)
        dump["frames"][str(frame)] = {
            obj.taichi_frac.prim_path: dict(matrix=[list(row) for row in obj.matrix_world],
                                            visible=not obj.hide_render)
            for obj in collection.all_objects
        }
    with open(out, "w") as fh:
        json.dump(dump, fh)
    print(f"dumped {len(collection.all_objects)} objects at {len(frames)} frames")


if __name__ == "__main__":
    main(sys.argv[1:])
