"""The sidebar panel (View3D > Sidebar > taichi-frac) and its operators: what the selected
fragment is (generation, birth and death, impact, peak stress, parent), selecting pieces by
generation or birth frame, and the stress heat-map view."""

from __future__ import annotations

import math

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

from . import materials


def fragments_of(context, cache_path: str | None = None):
    """The scene's imported fragments (of one cache file when ``cache_path`` is given)."""
    return [o for o in context.scene.objects
            if o.taichi_frac.prim_path and (cache_path is None or o.taichi_frac.cache_path == cache_path)]


def _scope(context):
    """The fragments an operator acts on: those of the active fragment's cache, else all."""
    active = context.active_object
    cache = active.taichi_frac.cache_path if active is not None and active.taichi_frac.prim_path else None
    return fragments_of(context, cache)


class TAICHI_FRAC_OT_select_fragments(bpy.types.Operator):
    """Select the pieces of a generation, or born within a range of scene frames"""

    bl_idname = "taichi_frac.select_fragments"
    bl_label = "Select Fragments"
    bl_options = {"REGISTER", "UNDO"}

    by: EnumProperty(name="By", items=(("GENERATION", "Generation", "Pieces of one generation"),
                                        ("BIRTH", "Birth Frame", "Pieces born within a frame range")))
    generation: IntProperty(name="Generation", min=0)
    birth_min: FloatProperty(name="From", description="First scene frame of the range")
    birth_max: FloatProperty(name="To", default=1.0e6, description="Last scene frame of the range")
    extend: BoolProperty(name="Extend", description="Add to the selection instead of replacing it")

    def execute(self, context):
        candidates = _scope(context)
        if not candidates:
            self.report({"WARNING"}, "taichi-frac: no imported fragments in this scene")
            return {"CANCELLED"}
        if self.by == "GENERATION":
            matched = [o for o in candidates if o.taichi_frac.generation == self.generation]
            what = f"generation {self.generation}"
        else:
            matched = [o for o in candidates if self.birth_min <= o.taichi_frac.birth_frame <= self.birth_max]
            what = f"born in frames {self.birth_min:g}-{self.birth_max:g}"
        if not self.extend:
            for obj in context.view_layer.objects:
                obj.select_set(False)
        selected = 0
        for obj in matched:
            obj.select_set(True)
            selected += obj.select_get()  # (an object hidden at this frame cannot be selected)
        if selected:
            context.view_layer.objects.active = next(o for o in matched if o.select_get())
        hidden = len(matched) - selected
        note = f"; {hidden} more are hidden at frame {context.scene.frame_current}" if hidden else ""
        self.report({"INFO"}, f"taichi-frac: {selected} pieces {what} selected{note}")
        return {"FINISHED"}


class TAICHI_FRAC_OT_stress_view(bpy.types.Operator):
    """Show the fragments' per-face peak principal stress as a heat map (blue: none, red: the
    largest), or give back their own materials"""

    bl_idname = "taichi_frac.stress_view"
    bl_label = "Stress Heat Map"
    bl_options = {"REGISTER", "UNDO"}

    show: BoolProperty(name="Show", default=True, description="Show the heat map (off: the materials again)")
    stress_max: FloatProperty(name="Red at [Pa]", min=0.0, default=0.0,
                              description="Stress shown red (0: the largest face stress of these fragments)")

    def execute(self, context):
        objects = _scope(context)
        if not objects:
            self.report({"WARNING"}, "taichi-frac: no imported fragments in this scene")
            return {"CANCELLED"}
        if not self.show:
            count = materials.remove_stress_view(objects)
            self.report({"INFO"}, f"taichi-frac: materials restored on {count} fragments")
            return {"FINISHED"}
        stress_max = self.stress_max or largest_face_stress(objects)
        material = materials.stress_material("taichi-frac stress", stress_max)
        count = materials.apply_stress_view(objects, material)
        self.report({"INFO"}, f"taichi-frac: stress heat map on {count} fragments (red at {stress_max / 1e6:.3g} MPa)")
        return {"FINISHED"}


def largest_face_stress(objects) -> float:
    """The largest per-face peak principal stress [Pa] over the objects' meshes."""
    import numpy as np

    largest = 0.0
    for obj in objects:
        attribute = obj.data.attributes.get(materials.STRESS_ATTRIBUTE) if obj.type == "MESH" else None
        if attribute is None or not len(attribute.data):
            continue
        values = np.empty(len(attribute.data), dtype=np.float32)
        attribute.data.foreach_get("value", values)
        largest = max(largest, float(values.max()))
    return largest


class VIEW3D_PT_taichi_frac(bpy.types.Panel):
    bl_label = "taichi-frac"
    bl_idname = "VIEW3D_PT_taichi_frac"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "taichi-frac"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        props = obj.taichi_frac if obj is not None else None
        box = layout.box()
        if props is None or not props.prim_path:
            box.label(text="Select an imported fragment", icon="INFO")
        else:
            col = box.column(align=True)
            col.label(text=obj.name, icon="MESH_DATA")
            col.label(text=f"Generation {props.generation}")
            col.label(text=f"Born at frame {props.birth_frame:g} (cache {props.cache_birth_frame})")
            col.label(text="Never breaks" if props.death_frame < 0 else
                      f"Breaks at frame {props.death_frame:g} (cache {props.cache_death_frame})")
            col.label(text=f"Peak stress {props.peak_stress / 1e6:.3g} MPa")
            if props.has_impact:
                col.label(text=f"Impact force {math.hypot(*props.impact_force):.4g} N")
                col.prop(props, "impact_force", text="Force [N]")
                col.prop(props, "impact_point", text="Impact at")
            else:
                col.label(text="A body of the scene (no impact made it)")
            col.prop(props, "parent")
            if props.stale:
                col.label(text="No longer in the cache", icon="ERROR")
        select = context.scene.taichi_frac_select
        col = layout.column(align=True)
        col.label(text="Select Pieces")
        row = col.row(align=True)
        row.prop(select, "generation")
        op = row.operator(TAICHI_FRAC_OT_select_fragments.bl_idname, text="Select")
        op.by, op.generation = "GENERATION", select.generation
        row = col.row(align=True)
        row.prop(select, "birth_min")
        row.prop(select, "birth_max")
        op = row.operator(TAICHI_FRAC_OT_select_fragments.bl_idname, text="Select")
        op.by, op.birth_min, op.birth_max = "BIRTH", select.birth_min, select.birth_max
        col = layout.column(align=True)
        col.label(text="Stress View")
        row = col.row(align=True)
        row.operator(TAICHI_FRAC_OT_stress_view.bl_idname, text="Heat Map", icon="SHADING_RENDERED").show = True
        row.operator(TAICHI_FRAC_OT_stress_view.bl_idname, text="Materials", icon="MATERIAL").show = False
        heat = bpy.data.materials.get("taichi-frac stress")
        if heat is not None and heat.node_tree and "Normalise Stress" in heat.node_tree.nodes:
            col.prop(heat.node_tree.nodes["Normalise Stress"].inputs["From Max"], "default_value", text="Red at [Pa]")


classes = (TAICHI_FRAC_OT_select_fragments, TAICHI_FRAC_OT_stress_view, VIEW3D_PT_taichi_frac)


register, unregister = bpy.utils.register_classes_factory(classes)
