"""Build or update Blender data from a read cache (reader.CacheData).

Layout: one collection per cache file, holding one child collection per body of the scene
(each fragment goes where its lineage starts); one object per fragment; one action for the
whole cache with a slot per object (Blender >= 4.4's slotted actions), keyed with the world
pose and visibility.

Re-import updates in place: objects are matched by the fragment's prim path, their meshes
refilled (same mesh datablock, so its material slots, and the object's modifiers, name,
object-level materials and custom properties stay) and their animation replaced; materials
already made for this collection are reused as the artist left them; pieces the cache no
longer has are removed (or hidden); new pieces join their body's collection.

Visibility: Blender's own USD importer (5.0.1) ignores time-sampled visibility, so the add-on
does not use it. Each fragment gets CONSTANT keyframes on ``hide_viewport`` and
``hide_render`` (held in USD exactly as a constant F-curve holds). Keys are written in bulk
(``keyframe_points.add`` + ``foreach_set``): no per-frame keyframe_insert.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import retime
from .materials import preview_surface_material

# FCurve keyframe interpolation enum values (rna_fcurve.cc: CONSTANT, LINEAR, BEZIER, ...).
_CONSTANT, _LINEAR = 0, 1


@dataclass
class ImportResult:
    collection: object                 # the cache's collection
    timing: retime.Timing
    created: int = 0
    updated: int = 0
    removed: int = 0
    hidden: int = 0
    skipped: int = 0                   # never visible in the range: left out
    warnings: list = field(default_factory=list)


def cache_key(path: str) -> str:
    """How a collection remembers its file (absolute, normalised)."""
    return os.path.normcase(os.path.abspath(path))


def _set_keys(channelbag, data_path: str, index: int, frames: np.ndarray, values: np.ndarray, interpolation: int):
    fcurve = channelbag.fcurves.new(data_path, index=index)
    points = fcurve.keyframe_points
    count = len(frames)
    points.add(count)
    co = np.empty(2 * count, dtype=np.float32)
    co[0::2] = frames
    co[1::2] = values
    points.foreach_set("co", co)
    points.foreach_set("interpolation", np.full(count, interpolation, dtype=np.int32))
    fcurve.update()


def _fill_mesh(mesh, fragment, materials: dict, length_scale: float) -> None:
    """(Re)fill ``mesh`` with the fragment's geometry. ``materials``: cache material index ->
    Blender material. The mesh's material slots are kept; ``taichi_frac_slots`` remembers
    which cache material each slot stands for, so a slot the artist gave another material
    keeps it and its faces."""
    mesh.clear_geometry()  # (keeps the material slots and custom properties)
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

    slots = list(mesh.get("taichi_frac_slots", []))
    used = np.unique(fragment.face_material)
    slot_of = {}
    for index in used.tolist():
        material = materials[index]
        prim = material["taichi_frac_prim"]
        if prim not in slots:
            slots.append(prim)
            mesh.materials.append(material)
        slot_of[index] = slots.index(prim)
    mesh["taichi_frac_slots"] = slots
    lookup = np.zeros(int(used.max()) + 1, dtype=np.int32)
    for index, slot in slot_of.items():
        lookup[index] = slot
    mesh.polygons.foreach_set("material_index", lookup[fragment.face_material])

    if fragment.loop_uvs is not None:
        mesh.uv_layers.new(name="UVMap").data.foreach_set("uv", fragment.loop_uvs.reshape(-1))
    if fragment.face_stress is not None:
        attribute = mesh.attributes.new("peak_principal_stress", "FLOAT", "FACE")
        attribute.data.foreach_set("value", fragment.face_stress)
    mesh.update()
    if fragment.loop_normals is not None:
        mesh.polygons.foreach_set("use_smooth", np.ones(face_count, dtype=bool))
        mesh.normals_split_custom_set(fragment.loop_normals)


@dataclass
class _Plan:
    """One fragment's keys in scene frames."""

    pose_frames: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray
    visibility_frames: np.ndarray
    visible: np.ndarray


def _plan(fragment, timing: retime.Timing, length_scale: float) -> _Plan:
    frames, positions, orientations = retime.clip_poses(fragment.sample_frames, fragment.positions,
                                                        fragment.orientations, timing.first, timing.last)
    vis_frames, visible = retime.clip_visibility(fragment.visibility_frames, fragment.visible,
                                                 timing.first, timing.last)
    return _Plan(timing.to_scene(frames), positions * length_scale, orientations, timing.to_scene(vis_frames), visible)


def _animate(obj, plan: _Plan, action, strip) -> None:
    obj.rotation_mode = "QUATERNION"
    obj.location = plan.positions[0]
    obj.rotation_quaternion = plan.orientations[0]
    hidden = (~plan.visible).astype(np.float32)
    obj.hide_viewport = obj.hide_render = bool(hidden[0])
    if obj.animation_data is None:
        obj.animation_data_create()
    slot = action.slots.new(id_type="OBJECT", name=obj.name)
    channelbag = strip.channelbag(slot, ensure=True)
    if len(plan.pose_frames) > 1:
        for axis in range(3):
            _set_keys(channelbag, "location", axis, plan.pose_frames, plan.positions[:, axis], _LINEAR)
        for axis in range(4):
            _set_keys(channelbag, "rotation_quaternion", axis, plan.pose_frames, plan.orientations[:, axis], _LINEAR)
    if len(plan.visibility_frames) > 1:
        for path in ("hide_viewport", "hide_render"):
            _set_keys(channelbag, path, 0, plan.visibility_frames, hidden, _CONSTANT)
    obj.animation_data.action = action
    obj.animation_data.action_slot = slot


def _set_properties(obj, fragment, cache, timing: retime.Timing, length_scale: float) -> None:
    props = obj.taichi_frac
    props.prim_path = fragment.prim_path
    props.cache_path = cache.path
    props.source = fragment.source
    props.generation = fragment.generation
    birth = cache.start_frame if fragment.birth_frame is None else fragment.birth_frame
    props.cache_birth_frame = int(birth)
    props.birth_frame = float(timing.to_scene(birth))
    props.cache_death_frame = -1 if fragment.death_frame is None else int(fragment.death_frame)
    props.death_frame = -1.0 if fragment.death_frame is None else float(timing.to_scene(fragment.death_frame))
    props.peak_stress = float(fragment.peak_principal_stress or 0.0)
    props.has_impact = fragment.impact_point is not None and fragment.impact_force is not None
    if props.has_impact:
        props.impact_point = [float(c) * length_scale for c in fragment.impact_point]
        props.impact_force = [float(c) for c in fragment.impact_force]
    props.stale = False


def _find_collection(scene, key: str):
    """The collection this scene already has for the cache file ``key``, if any."""
    for collection in scene.collection.children_recursive:
        if collection.get("taichi_frac_cache") and cache_key(collection["taichi_frac_cache"]) == key:
            return collection
    return None


def _imported_objects(scene, top, key: str) -> dict:
    """Prim path -> object made from this cache before: those in ``top`` and those the artist
    moved to a collection of their own (not those of another import of the same file)."""
    others = set()
    for collection in scene.collection.children_recursive:
        if collection != top and collection.get("taichi_frac_cache"):
            others.update(collection.all_objects)
    found = {o.taichi_frac.prim_path: o for o in top.all_objects if o.taichi_frac.prim_path}
    for obj in scene.objects:
        prim = obj.taichi_frac.prim_path
        if prim and prim not in found and obj not in others and cache_key(obj.taichi_frac.cache_path) == key:
            found[prim] = obj
    return found


def _source_collection(top, source: str):
    """``top``'s child collection for the scene body ``source`` (prim path), made if new."""
    for child in top.children:
        if child.get("taichi_frac_source") == source:
            return child
    child = bpy.data.collections.new(source.rsplit("/", 1)[-1])
    child["taichi_frac_source"] = source
    top.children.link(child)
    return child


def _retire(obj, missing: str, result: ImportResult) -> None:
    if missing == "HIDE":
        if obj.animation_data:
            obj.animation_data.action = None
        obj.hide_viewport = obj.hide_render = True
        obj.taichi_frac.stale = True
        result.hidden += 1
        return
    mesh = obj.data
    bpy.data.objects.remove(obj)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    result.removed += 1


def build_scene(context, cache, options: retime.ImportOptions = retime.ImportOptions()) -> ImportResult:
    """Create, or update in place, the collection, objects and materials of ``cache``.

    Lengths come in metres; a scene whose unit system has a scale_length other than 1 (one
    Blender unit = scale_length metres) gets them converted so objects keep their real size.
    """
    scene = context.scene
    units = scene.unit_settings
    length_scale = 1.0 if units.system == "NONE" or units.scale_length <= 0 else 1.0 / units.scale_length
    if options.set_scene_settings:
        fps = max(1, int(round(cache.fps)))
        scene.render.fps = fps
        scene.render.fps_base = fps / cache.fps
    timing = retime.make_timing(cache, scene.render.fps / scene.render.fps_base, options)
    lo, hi = timing.scene_range()

    key = cache_key(cache.path)
    top = _find_collection(scene, key) if options.update_existing else None
    found = top is not None
    if not found:
        top = bpy.data.collections.new(os.path.splitext(os.path.basename(cache.path))[0])
        scene.collection.children.link(top)
        top["taichi_frac_cache"] = cache.path
    result = ImportResult(collection=top, timing=timing)

    known = dict(top.get("taichi_frac_materials", {}))  # prim path -> material made before
    materials = {}
    for index, data in enumerate(cache.materials):
        material = known.get(data.prim_path)
        if material is None:
            material = known[data.prim_path] = preview_surface_material(data)
        materials[index] = material
    top["taichi_frac_materials"] = known

    existing = _imported_objects(scene, top, key) if found else {}
    old_actions = {o.animation_data.action for o in existing.values() if o.animation_data and o.animation_data.action}
    action = bpy.data.actions.new(f"{top.name}Action")
    action["taichi_frac_cache"] = cache.path
    strip = action.layers.new("Fracture").strips.new(type="KEYFRAME")

    objects = {}
    for fragment in cache.fragments:
        plan = _plan(fragment, timing, length_scale)
        if options.skip_never_visible and not retime.shown_at_some_frame(plan.visibility_frames, plan.visible, lo, hi):
            result.skipped += 1
            continue
        obj = existing.pop(fragment.prim_path, None)
        if obj is not None and obj.type == "MESH":
            _fill_mesh(obj.data, fragment, materials, length_scale)
            result.updated += 1
        else:
            mesh = bpy.data.meshes.new(fragment.name)
            _fill_mesh(mesh, fragment, materials, length_scale)
            obj = bpy.data.objects.new(fragment.name, mesh)
            _source_collection(top, fragment.source).objects.link(obj)
            result.created += 1
        _animate(obj, plan, action, strip)
        _set_properties(obj, fragment, cache, timing, length_scale)
        objects[fragment.prim_path] = obj

    by_path = {f.prim_path: f for f in cache.fragments}
    for fragment in cache.fragments:
        obj = objects.get(fragment.prim_path)
        if obj is None:
            continue
        parent = fragment.parent  # the nearest ancestor that was imported
        while parent is not None and parent not in objects and parent in by_path:
            parent = by_path[parent].parent
        obj.taichi_frac.parent = objects.get(parent)

    for obj in existing.values():
        _retire(obj, options.missing, result)
    for old in old_actions:
        if old != action and old.users == 0 and "taichi_frac_cache" in old:
            bpy.data.actions.remove(old)

    if options.set_scene_settings:
        scene.frame_start, scene.frame_end = lo, hi
    if cache.complete is False:
        result.warnings.append(
            f"{os.path.basename(cache.path)} is incomplete (its run was interrupted or is still going): "
            f"frames up to {cache.last_frame}, the last complete one, were imported")
    return result
