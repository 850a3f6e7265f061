"""taichi-frac fracture cache importer (Blender extension ``taichi_frac_blender``).

Pure Python: ``reader`` reads the USD cache with the pxr Blender bundles (no bpy),
``build`` makes the Blender data, this module holds the thin operator, menu entry and
drag-and-drop handler. Nothing here simulates: the cache is computed outside Blender.
"""

from __future__ import annotations

import glob
import os
import sys
import time

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper


def ensure_pxr() -> None:
    """Make Blender's bundled USD Python bindings importable. The Blender application has them
    on sys.path; Blender as a Python module (the bpy wheel) keeps them in its resource folder."""
    try:
        import pxr  # noqa: F401
        return
    except ImportError:
        pass
    base = bpy.utils.resource_path("LOCAL")
    for pattern in ("python/lib/python3*/site-packages", "python/lib/site-packages"):
        for path in glob.glob(os.path.join(base, pattern)):
            if os.path.isdir(os.path.join(path, "pxr")) and path not in sys.path:
                sys.path.append(path)
    import pxr  # noqa: F401  (raises a clear ImportError when Blender has no USD)


def import_cache(context, filepath: str, set_scene_settings: bool = True):
    """Import a cache into ``context.scene``; returns the new collection."""
    ensure_pxr()
    from .build import build_scene
    from .reader import read_cache

    return build_scene(context, read_cache(filepath), set_scene_settings=set_scene_settings)


class IMPORT_SCENE_OT_taichi_frac(bpy.types.Operator, ImportHelper):
    """Import a taichi-frac fracture cache (USD): animated fragments with crack materials"""

    bl_idname = "import_scene.taichi_frac"
    bl_label = "Import taichi-frac Cache"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".usdc"
    filter_glob: StringProperty(default="*.usd;*.usdc;*.usda", options={"HIDDEN"})
    filepath: StringProperty(subtype="FILE_PATH", options={"SKIP_SAVE"})
    set_scene_settings: BoolProperty(
        name="Set Frame Range and FPS",
        description="Set the scene's frame range and frame rate to the cache's",
        default=True,
    )

    def invoke(self, context, event):
        if self.filepath:  # dropped on the viewport (FileHandler): no file browser
            return self.execute(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        start = time.perf_counter()
        try:
            collection = import_cache(context, self.filepath, self.set_scene_settings)
        except (OSError, ImportError, ValueError) as exc:
            self.report({"ERROR"}, f"taichi-frac: cannot import {self.filepath}: {exc}")
            return {"CANCELLED"}
        self.report(
            {"INFO"},
            f"taichi-frac: {len(collection.objects)} fragments in {time.perf_counter() - start:.2f} s",
        )
        return {"FINISHED"}


class IMPORT_SCENE_FH_taichi_frac(bpy.types.FileHandler):
    bl_idname = "IMPORT_SCENE_FH_taichi_frac"
    bl_label = "taichi-frac cache"
    bl_import_operator = "import_scene.taichi_frac"
    bl_file_extensions = ".usd;.usdc;.usda"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def menu_func_import(self, context):
    self.layout.operator(IMPORT_SCENE_OT_taichi_frac.bl_idname, text="taichi-frac Cache (.usd/.usdc/.usda)")


_classes = (IMPORT_SCENE_OT_taichi_frac, IMPORT_SCENE_FH_taichi_frac)


def register():
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_func_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_func_import)
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
