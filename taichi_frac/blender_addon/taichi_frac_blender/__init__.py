"""taichi-frac for Blender (extension ``taichi_frac_blender``): simulate the objects the
artist marks, and import fracture caches (USD).

Pure Python: ``reader`` reads the USD cache with the pxr Blender bundles (no bpy), ``retime``
chooses the frames and maps them onto the scene's (no bpy), ``build`` makes or updates the
Blender data, ``materials`` the materials and the stress heat map, ``ui`` the sidebar panel;
``sim_properties``, ``export``, ``scene_toml``, ``runner``, ``simulate`` and ``sim_ui`` author a
simulation, write its scene file and run ``taichi-frac run`` in a separate process (never in
Blender's: the simulator is not even imported, so a Blender without taichi-frac imports caches
all the same); this module holds the import operator, menu entry and drag-and-drop handler.
"""

from __future__ import annotations

import glob
import os
import sys
import time
import traceback

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from . import properties, schema, sim_properties, sim_ui, simulate, ui


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


def import_cache(context, filepath: str, set_scene_settings: bool = True, **options):
    """Import (or re-import in place) a cache into ``context.scene``; returns its collection.
    ``options``: the fields of retime.ImportOptions. Raises reader.CacheError when the file
    cannot be read."""
    return run_import(context, filepath, set_scene_settings=set_scene_settings, **options).collection


def run_import(context, filepath: str, **options):
    """import_cache returning the whole build.ImportResult (counts, timing, warnings)."""
    ensure_pxr()
    from .build import build_scene
    from .reader import CacheError, layer_info, read_cache
    from .retime import ImportOptions

    if layer_info(filepath) is None:
        raise CacheError(f"{filepath} is not a taichi-frac cache (no '{schema.LAYER_DATA_KEY}' layer data): "
                         "import it with File > Import > Universal Scene Description")
    return build_scene(context, read_cache(filepath), ImportOptions(**options))


def is_taichi_frac_cache(filepath: str) -> bool:
    """False only for a readable USD file without taichi-frac layer data (another tool's);
    True when that cannot be told (unreadable file, no USD in this Blender), so that this
    importer reports why."""
    try:
        ensure_pxr()
    except ImportError:
        return True
    from .reader import CacheError, layer_info

    try:
        return layer_info(filepath) is not None
    except CacheError:
        return True


class IMPORT_SCENE_OT_taichi_frac(bpy.types.Operator, ImportHelper):
    """Import a taichi-frac fracture cache (USD): animated fragments with crack materials.
    Importing the same file again updates the pieces in place"""

    bl_idname = "import_scene.taichi_frac"
    bl_label = "Import taichi-frac Cache"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".usdc"
    filter_glob: StringProperty(default="*.usd;*.usdc;*.usda", options={"HIDDEN"})
    filepath: StringProperty(subtype="FILE_PATH", options={"SKIP_SAVE"})
    set_scene_settings: BoolProperty(
        name="Set Frame Range and FPS",
        description="Set the scene's frame rate to the cache's and its frame range to the imported frames "
                    "(off: keys are retimed to the scene's frame rate)",
        default=True,
    )
    frame_offset: FloatProperty(name="Frame Offset", default=0.0,
                                description="Scene frame where the cache's time 0 lands")
    use_frame_range: BoolProperty(name="Frame Range Only", default=False,
                                  description="Import only the cache frames from First to Last")
    frame_first: IntProperty(name="First", default=0, description="First cache frame to import")
    frame_last: IntProperty(name="Last", default=250, description="Last cache frame to import")
    skip_never_visible: BoolProperty(
        name="Skip Never-Visible Pieces", default=True,
        description="Leave out pieces born and broken between two frames (never seen)")
    missing: EnumProperty(
        name="Pieces Gone on Re-import",
        items=(("REMOVE", "Remove", "Delete the objects of pieces the cache no longer has"),
               ("HIDE", "Hide", "Keep them, hidden, marked stale")),
        default="REMOVE")
    update_existing: BoolProperty(name="Update Existing", default=True,
                                  description="Re-import into the collection made from the same file before")

    def invoke(self, context, event):
        if self.filepath:  # dropped on the viewport (FileHandler): no file browser
            if not is_taichi_frac_cache(self.filepath) and hasattr(bpy.ops.wm, "usd_import"):
                # Not ours: Blender's own USD importer takes it, with its own options.
                self.report({"INFO"}, f"taichi-frac: {os.path.basename(self.filepath)} is not a taichi-frac "
                                      "cache; passed to Blender's USD importer")
                return bpy.ops.wm.usd_import("INVOKE_DEFAULT", filepath=self.filepath)
            return self.execute(context)
        return ImportHelper.invoke(self, context, event)

    def execute(self, context):
        start = time.perf_counter()
        options = dict(
            set_scene_settings=self.set_scene_settings, frame_offset=self.frame_offset,
            frame_first=self.frame_first if self.use_frame_range else None,
            frame_last=self.frame_last if self.use_frame_range else None,
            skip_never_visible=self.skip_never_visible, missing=self.missing, update_existing=self.update_existing)
        try:
            result = run_import(context, self.filepath, **options)
        except (OSError, ImportError, ValueError) as exc:  # (reader.CacheError is a ValueError)
            self.report({"ERROR"}, f"taichi-frac: {exc}")
            return {"CANCELLED"}
        except Exception as exc:  # a bug of ours: say so in one line, the details go to the console
            traceback.print_exc()
            self.report({"ERROR"}, f"taichi-frac: import of {self.filepath} failed ({type(exc).__name__}: {exc}); "
                                   "details in the system console")
            return {"CANCELLED"}
        for warning in result.warnings:
            self.report({"WARNING"}, f"taichi-frac: {warning}")
        counts = [f"{result.created} new", f"{result.updated} updated"]
        counts += [f"{n} {what}" for n, what in ((result.removed, "removed"), (result.hidden, "hidden"),
                                                 (result.skipped, "never visible, skipped")) if n]
        self.report({"INFO"}, f"taichi-frac: {', '.join(counts)} fragments in {time.perf_counter() - start:.2f} s")
        return {"FINISHED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "set_scene_settings")
        layout.prop(self, "frame_offset")
        layout.prop(self, "use_frame_range")
        row = layout.row(align=True)
        row.enabled = self.use_frame_range
        row.prop(self, "frame_first")
        row.prop(self, "frame_last")
        layout.prop(self, "skip_never_visible")
        layout.prop(self, "update_existing")
        layout.prop(self, "missing")


class IMPORT_SCENE_FH_taichi_frac(bpy.types.FileHandler):
    """Drag and drop of a .usd/.usdc/.usda on the viewport. Blender offers every handler of the
    extension; a file that is not a taichi-frac cache goes on to Blender's USD importer."""

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
    properties.register()
    sim_properties.register()
    simulate.register()
    ui.register()
    sim_ui.register()
    for cls in _classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_func_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_func_import)
    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
    sim_ui.unregister()
    ui.unregister()
    simulate.unregister()
    sim_properties.unregister()
    properties.unregister()
