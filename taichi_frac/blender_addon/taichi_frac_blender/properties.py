"""What the add-on keeps on each imported fragment (``Object.taichi_frac``): where it came
from in the cache, its lineage as an object pointer (survives renames), and the physics the
sidebar panel shows. Frames are the scene's (after offset and retiming); the cache's own
frame numbers are kept beside them."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, FloatProperty, FloatVectorProperty, IntProperty, PointerProperty, StringProperty


class TaichiFracFragment(bpy.types.PropertyGroup):
    prim_path: StringProperty(name="Prim Path", description="The fragment's Mesh prim in the cache")
    cache_path: StringProperty(name="Cache", description="The cache file it was imported from", subtype="FILE_PATH")
    source: StringProperty(name="Source Body", description="Prim path of the scene body it broke from")
    parent: PointerProperty(name="Parent", type=bpy.types.Object,
                            description="The fragment this one broke from (None for a body of the scene)")
    generation: IntProperty(name="Generation", description="Fractures between the scene's body and this piece")
    birth_frame: FloatProperty(name="Birth Frame", description="First scene frame it is visible")
    death_frame: FloatProperty(name="Death Frame", default=-1.0,
                               description="Scene frame it breaks into children (-1: never)")
    cache_birth_frame: IntProperty(name="Cache Birth Frame")
    cache_death_frame: IntProperty(name="Cache Death Frame", default=-1)
    has_impact: BoolProperty(name="Has Impact", description="Whether an impact made it (False for scene bodies)")
    impact_point: FloatVectorProperty(name="Impact Point", subtype="TRANSLATION", unit="LENGTH", size=3,
                                      description="Where the impact that made it struck (world)")
    impact_force: FloatVectorProperty(name="Impact Force [N]", size=3,
                                      description="Force of that impact [N] (world)")
    peak_stress: FloatProperty(name="Peak Stress [Pa]",
                               description="Largest principal stress over the fragment at its birth [Pa]")
    stale: BoolProperty(name="Stale", description="The cache no longer has this piece (hidden by re-import)")
    stress_view: BoolProperty(name="Stress View", description="Showing the stress heat-map material")


class TaichiFracSelect(bpy.types.PropertyGroup):
    """The panel's selection settings (``Scene.taichi_frac_select``)."""

    generation: IntProperty(name="Generation", min=0, description="Generation to select")
    birth_min: FloatProperty(name="From", description="Select pieces born at or after this scene frame")
    birth_max: FloatProperty(name="To", default=1.0e6, description="... and at or before this one")


classes = (TaichiFracFragment, TaichiFracSelect)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Object.taichi_frac = PointerProperty(type=TaichiFracFragment)
    bpy.types.Scene.taichi_frac_select = PointerProperty(type=TaichiFracSelect)


def unregister():
    del bpy.types.Scene.taichi_frac_select
    del bpy.types.Object.taichi_frac
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
