"""Build Blender data from a read cache (reader.CacheData): one object per fragment in a new
collection, keyframed world pose and visibility, the cache's materials, frame range and fps.

Visibility: Blender's own USD importer (5.0.1) ignores time-sampled visibility, so the add-on
does not use it. Each fragment gets CONSTANT keyframes on ``hide_viewport`` and
``hide_render`` at the cache's visibility samples (held in USD exactly as a constant F-curve
holds, constant extrapolation before the first key). Keys are written in bulk
(``keyframe_points.add`` + ``foreach_set``): no per-frame keyframe_insert.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

# FCurve keyframe interpolation enum values (rna_fcurve.cc: CONSTANT, LINEAR, BEZIER, ...).
_CONSTANT, _LINEAR = 0, 1


def _set_keys(action, obj, data_path: str, index: int, frames: np.ndarray, values: np.ndarray, interpolation: int):
    fcurve = action.fcurve_ensure_for_datablock(obj, data_path, index=index)
    points = fcurve.keyframe_points
    count = len(frames)
    points.add(count)
    co = np.empty(2 * count, dtype=np.float32)
    co[0::2] = frames
    co[1::2] = values
    points.foreach_set("co", co)
    points.foreach_set("interpolation", np.full(count, interpolation, dtype=np.int32))
    fcurve.update()
    return fcurve


def _make_material(data):
    material = bpy.data.materials.new(data.name)
    if hasattr(material, "use_nodes") and not material.use_nodes:
        material.use_nodes = True
    color = tuple(data.base_color) + (1.0,)
    material.diffuse_color = color
    material.roughness = data.roughness
    material.metallic = data.metallic
    bsdf = next((n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is not None:
        bsdf.inputs["Base Color"].default_value = color
        bsdf.inputs["Roughness"].default_value = data.roughness
        bsdf.inputs["Metallic"].default_value = data.metallic
        bsdf.inputs["Alpha"].default_value = data.opacity
    material["taichi_frac_prim"] = data.prim_path
    return material


def _make_mesh(fragment, materials, length_scale: float):
    mesh = bpy.data.meshes.new(fragment.name)
    vertices = (fragment.vertices * length_scale).astype(np.float32)
    loop_count = len(fragment.face_vertices)
    face_count = len(fragment.face_sizes)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.reshape(-1))
    mesh.loops.add(loop_count)
    mesh.loops.foreach_set("vertex_index", fragment.face_vertices)
    mesh.polygons.add(face_count)
    loop_start = np.zeros(face_count, dtype=np.int32)
    np.cumsum(fragment.face_sizes[:-1], out=loop_start[1:])
    mesh.polygons.foreach_set("loop_start", loop_start)
    for material in materials:
        mesh.materials.append(material)
    mesh.polygons.foreach_set("material_index", fragment.face_material)
    if fragment.loop_uvs is not None:
        mesh.uv_layers.new(name="UVMap").data.foreach_set("uv", fragment.loop_uvs.reshape(-1))
    if fragment.face_stress is not None:
        attribute = mesh.attributes.new("peak_principal_stress", "FLOAT", "FACE")
        attribute.data.foreach_set("value", fragment.face_stress)
    mesh.update()
    if fragment.loop_normals is not None:
        mesh.polygons.foreach_set("use_smooth", np.ones(face_count, dtype=bool))
        mesh.normals_split_custom_set(fragment.loop_normals)
    return mesh


def _animate(obj, fragment, length_scale: float):
    obj.rotation_mode = "QUATERNION"
    obj.location = fragment.positions[0] * length_scale
    obj.rotation_quaternion = fragment.orientations[0]
    hidden = (~fragment.visible).astype(np.float32)
    obj.hide_viewport = obj.hide_render = bool(hidden[0])
    obj.animation_data_create()
    action = bpy.data.actions.new(f"{obj.name}Action")
    obj.animation_data.action = action
    frames = fragment.sample_frames
    if len(frames) > 1:
        for axis in range(3):
            _set_keys(action, obj, "location", axis, frames, fragment.positions[:, axis] * length_scale, _LINEAR)
        for axis in range(4):
            _set_keys(action, obj, "rotation_quaternion", axis, frames, fragment.orientations[:, axis], _LINEAR)
    if len(fragment.visibility_frames) > 1:
        for path in ("hide_viewport", "hide_render"):
            _set_keys(action, obj, path, 0, fragment.visibility_frames, hidden, _CONSTANT)


def build_scene(context, cache, collection_name: str | None = None, set_scene_settings: bool = True):
    """Create the collection, objects and materials of ``cache``; returns the collection.

    Lengths come in metres; a scene whose unit system has a scale_length other than 1 (one
    Blender unit = scale_length metres) gets them converted so objects keep their real size.
    """
    scene = context.scene
    units = scene.unit_settings
    length_scale = 1.0 if units.system == "NONE" or units.scale_length <= 0 else 1.0 / units.scale_length

    collection = bpy.data.collections.new(collection_name or os.path.splitext(os.path.basename(cache.path))[0])
    scene.collection.children.link(collection)
    collection["taichi_frac_cache"] = cache.path
    materials = [_make_material(m) for m in cache.materials]

    objects = {}
    for fragment in cache.fragments:
        obj = bpy.data.objects.new(fragment.name, _make_mesh(fragment, materials, length_scale))
        collection.objects.link(obj)
        _animate(obj, fragment, length_scale)
        obj["taichi_frac_prim"] = fragment.prim_path
        if fragment.birth_frame is not None:
            obj["taichi_frac_birth_frame"] = int(fragment.birth_frame)
        obj["taichi_frac_death_frame"] = -1 if fragment.death_frame is None else int(fragment.death_frame)
        if fragment.peak_principal_stress is not None:
            obj["taichi_frac_peak_principal_stress"] = float(fragment.peak_principal_stress)  # Pa
        if fragment.impact_point is not None:
            obj["taichi_frac_impact_point"] = [float(c) * length_scale for c in fragment.impact_point]
        if fragment.impact_force is not None:
            obj["taichi_frac_impact_force"] = [float(c) for c in fragment.impact_force]  # N
        objects[fragment.prim_path] = obj
    for fragment in cache.fragments:
        if fragment.parent in objects:
            # A custom property, not Blender parenting: fragments move independently in world.
            objects[fragment.prim_path]["taichi_frac_parent"] = objects[fragment.parent].name

    if set_scene_settings:
        scene.frame_start = int(round(cache.start_frame))
        scene.frame_end = int(round(cache.end_frame))
        fps = max(1, int(round(cache.fps)))
        scene.render.fps = fps
        scene.render.fps_base = fps / cache.fps
    return collection
