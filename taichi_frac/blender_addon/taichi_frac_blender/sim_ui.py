"""The sidebar's Simulation panel (View3D > Sidebar > taichi-frac > Simulation): the active
object's role, material, fracture controls and initial velocity, the scene's run settings,
the Simulate button, and what the last run found (it broke, or why it did not)."""

from __future__ import annotations

import bpy

from . import export
from .sim_properties import MATERIAL_PRESETS


def _mpa(value: float) -> str:
    return f"{value / 1e6:.3g} MPa"


def draw_object(layout, obj) -> None:
    props = obj.taichi_frac_sim
    layout.prop(props, "role")
    if props.role == "NONE":
        return
    if props.role == "STATIC":
        layout.label(text="Collides as its bounding box (oriented", icon="INFO")
        layout.label(text="with the object): the engine's static colliders")
        layout.prop(props, "friction")
        layout.prop(props, "restitution")
        return
    col = layout.column(align=True)
    col.prop(props, "material")
    if props.material == "custom":
        for name in ("density", "young_modulus", "poisson_ratio", "tensile_strength", "fracture_toughness", "look"):
            col.prop(props, name)
    else:
        density, young, poisson, strength = MATERIAL_PRESETS[props.material]
        col.label(text=f"{density:g} kg/m³, E {young / 1e9:g} GPa, ν {poisson:g}, strength {_mpa(strength)}")
        col.prop(props, "strength_override")
    col = layout.column(align=True)
    col.prop(props, "friction")
    col.prop(props, "restitution")
    if props.role == "BREAKABLE":
        box = layout.box()
        box.label(text="Fracture")
        row = box.row(align=True)
        row.prop(props, "crack_count_auto", text="Auto")
        sub = row.row(align=True)
        sub.enabled = not props.crack_count_auto
        sub.prop(props, "crack_count")
        if props.crack_count_auto:
            box.prop(props, "crack_scale")
        for name in ("seed", "crack_length", "impact_force_threshold", "min_fragment_particles", "refracture",
                     "stress_model", "crack_roughness"):
            box.prop(props, name)
    box = layout.box()
    box.prop(props, "velocity_source")
    if props.velocity_source == "MANUAL":
        box.prop(props, "linear_velocity")
        box.prop(props, "angular_velocity")
    else:
        box.label(text="The keyframed motion's slope at the start frame")
    if props.role == "BREAKABLE":
        draw_result(layout, props)


def draw_result(layout, props) -> None:
    if props.result_state == "NONE":
        return
    box = layout.box()
    if props.result_state == "BROKE":
        box.label(text="Broke in the last run", icon="CHECKMARK")
        return
    box.label(text="Did not break in the last run", icon="ERROR")
    col = box.column(align=True)
    if props.result_frame < 0:
        col.label(text=props.result_note or "no impact was analysed")
        return
    col.label(text=f"Peak stress {_mpa(props.result_peak_stress)} of strength {_mpa(props.result_strength)}")
    col.label(text=f"at frame {props.result_frame:g}, impact speed {props.result_impact_speed:.3g} m/s")
    col.prop(props, "result_point", text="At")
    if props.result_break_speed > 0:
        col.label(text=f"Breaks at about {props.result_break_speed:.3g} m/s impact speed")
    col.label(text=f"or a strength below {_mpa(props.result_peak_stress)}")


class VIEW3D_PT_taichi_frac_simulation(bpy.types.Panel):
    bl_label = "Simulation"
    bl_idname = "VIEW3D_PT_taichi_frac_simulation"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "taichi-frac"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.active_object
        if obj is None or obj.taichi_frac.prim_path:
            layout.label(text="Select an object to give it a role", icon="INFO")
        else:
            draw_object(layout, obj)
        settings = context.scene.taichi_frac_sim
        box = layout.box()
        box.label(text="Scene")
        row = box.row(align=True)
        row.prop(settings, "ground")
        sub = row.row(align=True)
        sub.enabled = settings.ground
        sub.prop(settings, "ground_height")
        box.prop(settings, "particles")
        box.prop(settings, "substeps")
        box.prop(settings, "draft")
        box.prop(settings, "cache_path")
        scene = context.scene
        try:
            box.label(text=f"Cache: {export.cache_path(scene)}")
        except export.ExportError as exc:
            box.label(text=str(exc), icon="ERROR")
        box.label(text=f"Frames {scene.frame_start}-{scene.frame_end} at {export.scene_fps(scene):g} fps")
        layout.operator("taichi_frac.simulate", icon="PLAY")
        if settings.last_message:
            layout.label(text=settings.last_message)


classes = (VIEW3D_PT_taichi_frac_simulation,)


register, unregister = bpy.utils.register_classes_factory(classes)
