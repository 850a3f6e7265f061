"""Blender materials: the cache's UsdPreviewSurface materials as Principled BSDFs, and the
stress heat-map.

UsdPreviewSurface (https://openusd.org/release/spec_usdpreviewsurface.html) has one opacity
for two different things. With ``opacityThreshold`` 0 a partly opaque surface is a thin
dielectric seen through (glass): Transmission Weight = 1 - opacity and IOR = ior, no alpha
blending (which would drop the refraction and the reflections with it). With
``opacityThreshold`` > 0 opacity is a cut-out mask: the surface is drawn, opaque, where
opacity >= threshold and not at all elsewhere (Alpha 1 or 0; the cache's opacity is constant
per material).
"""

from __future__ import annotations

import bpy

STRESS_ATTRIBUTE = "peak_principal_stress"  # the per-face attribute the importer writes [Pa]
# Heat-map colour ramp (position, linear RGBA): blue (no stress) to red (the largest).
_RAMP = ((0.0, (0.02, 0.05, 0.60, 1.0)), (0.35, (0.00, 0.60, 0.60, 1.0)),
         (0.65, (0.90, 0.80, 0.02, 1.0)), (1.0, (0.80, 0.02, 0.01, 1.0)))


def _principled(material):
    if not material.node_tree:  # (Blender < 5 makes the tree only when use_nodes is set)
        material.use_nodes = True
    return next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)


def preview_surface_material(data):
    """A new material from reader.MaterialData; inputs the cache lacks keep Blender's defaults."""
    material = bpy.data.materials.new(data.name)
    bsdf = _principled(material)
    inputs = bsdf.inputs
    color = data.base_color
    if color is not None:
        inputs["Base Color"].default_value = tuple(color) + (1.0,)
        material.diffuse_color = tuple(color) + (1.0,)
    if data.roughness is not None:
        inputs["Roughness"].default_value = material.roughness = data.roughness
    if data.metallic is not None:
        inputs["Metallic"].default_value = material.metallic = data.metallic
    opacity = 1.0 if data.opacity is None else min(max(data.opacity, 0.0), 1.0)
    threshold = data.opacity_threshold or 0.0
    if threshold > 0.0:
        inputs["Alpha"].default_value = 1.0 if opacity >= threshold else 0.0
    elif opacity < 1.0:
        inputs["Transmission Weight"].default_value = 1.0 - opacity
        if hasattr(material, "use_raytrace_refraction"):  # EEVEE: refract what lies behind
            material.use_raytrace_refraction = True
        material.diffuse_color = tuple(material.diffuse_color[:3]) + (opacity,)  # (solid view)
    if data.ior is not None and threshold == 0.0:
        inputs["IOR"].default_value = data.ior
    material["taichi_frac_prim"] = data.prim_path
    return material


def stress_material(name: str, stress_max: float):
    """The heat-map material: the face attribute ``peak_principal_stress`` [Pa] divided by
    ``stress_max`` [Pa] (clamped to [0, 1]) through a blue-to-red colour ramp, as base colour
    and as emission (so the colours read the same under any lighting)."""
    material = bpy.data.materials.get(name)
    if material is None:
        material = bpy.data.materials.new(name)
        _principled(material)
        tree = material.node_tree
        bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
        attribute = tree.nodes.new("ShaderNodeAttribute")
        attribute.attribute_type = "GEOMETRY"
        attribute.attribute_name = STRESS_ATTRIBUTE
        attribute.location = (-900, 0)
        normalise = tree.nodes.new("ShaderNodeMapRange")
        normalise.name = "Normalise Stress"
        normalise.clamp = True
        normalise.location = (-650, 0)
        ramp = tree.nodes.new("ShaderNodeValToRGB")
        ramp.location = (-400, 0)
        elements = ramp.color_ramp.elements
        while len(elements) < len(_RAMP):
            elements.new(0.5)
        for element, (position, color) in zip(elements, _RAMP):
            element.position, element.color = position, color
        tree.links.new(attribute.outputs["Fac"], normalise.inputs["Value"])
        tree.links.new(normalise.outputs["Result"], ramp.inputs["Fac"])
        tree.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
        tree.links.new(ramp.outputs["Color"], bsdf.inputs["Emission Color"])
        bsdf.inputs["Emission Strength"].default_value = 0.5
        bsdf.inputs["Roughness"].default_value = 0.6
    set_stress_range(material, stress_max)
    return material


def set_stress_range(material, stress_max: float) -> None:
    """Map [0, stress_max] Pa onto the ramp (stress_max <= 0: 1 Pa, everything red)."""
    node = material.node_tree.nodes["Normalise Stress"]
    node.inputs["From Min"].default_value = 0.0
    node.inputs["From Max"].default_value = stress_max if stress_max > 0.0 else 1.0
    node.inputs["To Min"].default_value = 0.0
    node.inputs["To Max"].default_value = 1.0
    material["taichi_frac_stress_max"] = float(stress_max)


def apply_stress_view(objects, material) -> int:
    """Show ``material`` on every slot of each object (object-level links; the mesh's
    materials are untouched); returns how many objects changed."""
    changed = 0
    for obj in objects:
        if obj.taichi_frac.stress_view or obj.type != "MESH":
            continue
        saved = {}
        for i, slot in enumerate(obj.material_slots):
            saved[str(i)] = {"link": slot.link, **({"material": slot.material} if slot.link == "OBJECT" and slot.material else {})}
            slot.link = "OBJECT"
            slot.material = material
        if not obj.material_slots:
            obj.data.materials.append(None)
            obj.material_slots[0].link = "OBJECT"
            obj.material_slots[0].material = material
            saved["added"] = {"link": "DATA"}
        obj["taichi_frac_saved_slots"] = saved
        obj.taichi_frac.stress_view = True
        changed += 1
    return changed


def remove_stress_view(objects) -> int:
    """Undo apply_stress_view: each slot's link and object-level material as they were."""
    changed = 0
    for obj in objects:
        if not obj.taichi_frac.stress_view:
            continue
        saved = obj.get("taichi_frac_saved_slots", {})
        for i, slot in enumerate(obj.material_slots):
            entry = saved.get(str(i), {"link": "DATA"})
            slot.material = entry.get("material")  # (object-level: link is OBJECT here)
            slot.link = entry.get("link", "DATA")
        if "added" in saved and len(obj.data.materials) == 1 and obj.data.materials[0] is None:
            obj.data.materials.clear()
        obj.pop("taichi_frac_saved_slots", None)
        obj.taichi_frac.stress_view = False
        changed += 1
    return changed
