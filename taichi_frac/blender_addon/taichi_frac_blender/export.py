"""The scene the artist authored, written as a taichi-frac scene file with its meshes.

Breakable and rigid objects become ``[[objects]]`` with a mesh file each: the evaluated mesh
(modifiers applied) in its world placement (scale and rotation applied, Z up, metres),
triangulated, written as OBJ. Such a mesh's body frame is then parallel to the world, and
``position`` is its centre of mass (the volume centroid of the closed surface, which is the
centre of mass of the tets that fill it), so the engine puts it back exactly where Blender
shows it. Static objects become box colliders: their bounding box, oriented with the object
(what the engine collides with today). The frame range and rate are the scene's; the start
frame is the cache's time 0.

The scene file is the ordinary format (docs/reference/scene-file.md), so
``taichi-frac run SCENE.toml`` repeats the run from the command line.
"""

from __future__ import annotations

import math
import os
import re
import tempfile
from dataclasses import dataclass, field

import bpy
import numpy as np

from . import scene_toml

# One-sided difference step [frames] for velocities from animation: small enough that the
# truncation error of a smooth curve is negligible, large enough that float32 world matrices
# (about 1e-7 relative) do not dominate (about 1e-4 m/s at 24 fps and 2 m from the origin).
VELOCITY_STEP_FRAMES = 0.05


class ExportError(ValueError):
    """The scene cannot be simulated as authored: one line naming the object and the fix."""


@dataclass
class Export:
    """What :func:`export_scene` wrote: the cache, scene file, stats file and mesh folder
    paths, and each scene-file object name's Blender object name."""

    cache_path: str
    scene_path: str
    stats_path: str
    mesh_dir: str
    names: dict = field(default_factory=dict)   # scene-file name -> Blender object name
    breakable: list = field(default_factory=list)  # Blender names of the breakable objects
    frame_start: int = 1
    fps: float = 24.0


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def metres_per_unit(scene) -> float:
    """Metres in one Blender unit (the importer divides by the same)."""
    units = scene.unit_settings
    return 1.0 if units.system == "NONE" or units.scale_length <= 0 else units.scale_length


def cache_path(scene) -> str:
    """The cache file: the scene setting, else ``taichi_frac/<scene>.usdc`` beside the .blend,
    or in the temporary folder while the .blend is unsaved."""
    name = safe_name(scene.name) + ".usdc"
    given = scene.taichi_frac_sim.cache_path.strip()
    if not given:
        folder = (os.path.join(os.path.dirname(bpy.data.filepath), "taichi_frac") if bpy.data.filepath
                  else os.path.join(tempfile.gettempdir(), "taichi_frac"))
        return os.path.join(folder, name)
    if given.startswith("//") and not bpy.data.filepath:
        given = os.path.join(tempfile.gettempdir(), "taichi_frac", given[2:])
    path = os.path.abspath(bpy.path.abspath(given))
    if os.path.isdir(path) or given.endswith(("/", "\\")):
        path = os.path.join(path, name)
    if not path.lower().endswith((".usdc", ".usda", ".usd")):
        raise ExportError(f"cache path {given!r} must name a .usdc, .usda or .usd file (or a folder)")
    return path


def safe_name(name: str) -> str:
    """A name valid as a USD prim name and a file name: letters, digits and underscores,
    not starting with a digit."""
    cleaned = re.sub(r"[^A-Za-z0-9_]", "_", name) or "object"
    return "_" + cleaned if cleaned[0].isdigit() else cleaned


def _unique_names(objects) -> dict:
    names, taken = {}, set()
    for obj in objects:
        base = safe_name(obj.name)
        name, k = base, 1
        while name in taken:
            k += 1
            name = f"{base}_{k}"
        taken.add(name)
        names[obj.name] = name
    return names


def world_triangles(obj, depsgraph, scale: float):
    """(vertices (V,3) [m], triangles (F,3) int) of the evaluated mesh in world placement."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        mesh.calc_loop_triangles()
        vertices = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
        mesh.vertices.foreach_get("co", vertices)
        triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", triangles)
    finally:
        evaluated.to_mesh_clear()
    vertices = vertices.reshape(-1, 3)
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    vertices = (vertices @ matrix[:3, :3].T + matrix[:3, 3]) * scale
    triangles = triangles.reshape(-1, 3)
    if np.linalg.det(matrix[:3, :3]) < 0.0:  # (a mirroring scale turns the faces inside out)
        triangles = triangles[:, ::-1]
    return vertices, triangles


def volume_centroid(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, float]:
    """(centroid (3,), volume) of the solid a closed, outward-oriented triangle surface
    bounds: the signed tetrahedra from the origin to each face (exact for a closed surface)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    volumes = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    volume = float(volumes.sum())
    if abs(volume) < 1e-15:
        raise ValueError("it encloses no volume")
    return (volumes[:, None] * (a + b + c)).sum(axis=0) / (4.0 * volume), volume


def write_obj(path: str, vertices: np.ndarray, triangles: np.ndarray) -> None:
    with open(path, "w", encoding="ascii") as out:
        out.write("# taichi-frac export: world placement, metres, Z up\n")
        out.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist())
        out.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in triangles.tolist())


def _rotation_vector(rotation: np.ndarray) -> np.ndarray:
    """The axis x angle [rad] of a rotation matrix (3,3)."""
    cos = max(-1.0, min(1.0, (np.trace(rotation) - 1.0) / 2.0))
    angle = math.acos(cos)
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    if angle < 1e-12:
        return axis / 2.0
    return axis * (angle / (2.0 * math.sin(angle)))


def animated_velocity(scene, obj, frame: int, scale: float):
    """(linear [m/s], angular [rad/s]) velocity of ``obj``'s animated world motion right
    after ``frame``: a second-order one-sided difference of its world matrix over
    ``VELOCITY_STEP_FRAMES`` (the motion the simulation continues; constant extrapolation
    before a first key does not halve it). The linear velocity is the object origin's;
    the body's centre of mass moves with it plus the spin's share, added by the caller."""
    fps, h = scene_fps(scene), VELOCITY_STEP_FRAMES
    matrices = []
    for k in range(3):
        offset = k * h
        whole = math.floor(offset)
        scene.frame_set(frame + whole, subframe=offset - whole)
        matrices.append(np.array(obj.matrix_world, dtype=np.float64))
    scene.frame_set(frame)
    dt = h / fps
    positions = [m[:3, 3] * scale for m in matrices]
    linear = (-3.0 * positions[0] + 4.0 * positions[1] - positions[2]) / (2.0 * dt)
    rotations = [_unit_rotation(m[:3, :3]) for m in matrices]
    turns = [_rotation_vector(r @ rotations[0].T) for r in rotations]
    angular = (4.0 * turns[1] - turns[2]) / (2.0 * dt)
    return linear, angular, positions[0]


def _unit_rotation(matrix: np.ndarray) -> np.ndarray:
    """The rotation of a (possibly scaled) 3x3 matrix (polar decomposition)."""
    u, _, vt = np.linalg.svd(matrix)
    rotation = u @ vt
    if np.linalg.det(rotation) < 0:
        u[:, -1] *= -1.0
        rotation = u @ vt
    return rotation


def f32(value) -> float:
    """A Blender float property's value as the shortest decimal that reads back to the same
    float32 (0.2, not 0.20000000298023224)."""
    return float(str(np.float32(value)))


def _vector(values, digits: int = 9) -> list[float]:
    """A computed vector [m, m/s, rad/s], rounded to a nanometre (or nano-unit)."""
    return [round(float(v), digits) + 0.0 for v in values]


def _material(props) -> object:
    if props.material == "custom":
        return scene_toml.Inline(density=f32(props.density), young_modulus=f32(props.young_modulus),
                                 poisson_ratio=f32(props.poisson_ratio),
                                 tensile_strength=f32(props.tensile_strength),
                                 fracture_toughness=f32(props.fracture_toughness), look=props.look)
    if props.strength_override > 0.0:
        return scene_toml.Inline(preset=props.material, tensile_strength=f32(props.strength_override))
    return props.material


def _fracture(props, scale: float) -> dict:
    table = {}
    if not props.crack_count_auto:  # (auto: no key, the engine's default count)
        table["crack_count"] = int(props.crack_count)
    elif props.crack_scale != 1.0:
        table["crack_scale"] = f32(props.crack_scale)
    table["seed"] = int(props.seed)
    if props.crack_length > 0.0:
        table["crack_length"] = f32(float(props.crack_length) * scale)
    table["impact_force_threshold"] = f32(props.impact_force_threshold)
    table["min_fragment_particles"] = int(props.min_fragment_particles)
    table["refracture"] = bool(props.refracture)
    table["stress_model"] = props.stress_model
    if props.crack_roughness > 0.0:
        table["crack_roughness"] = f32(float(props.crack_roughness) * scale)
    return table


def _static_box(obj, depsgraph, scale: float) -> dict:
    """A box collider: the object's local bounding box, placed and oriented with it."""
    evaluated = obj.evaluated_get(depsgraph)
    corners = np.array([tuple(c) for c in evaluated.bound_box], dtype=np.float64)
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    scales = np.linalg.norm(matrix[:3, :3], axis=0)
    rotation = _unit_rotation(matrix[:3, :3])
    low, high = corners.min(axis=0), corners.max(axis=0)
    half = np.maximum((high - low) / 2.0 * scales * scale, 1e-6)
    centre = (matrix[:3, :3] @ ((low + high) / 2.0) + matrix[:3, 3]) * scale
    quaternion = _matrix_quaternion(rotation)
    return {"type": "box", "center": _vector(centre), "half_extents": _vector(half),
            "orientation": _vector(quaternion, 12)}


def _matrix_quaternion(r: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (Shepperd's method)."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0, r[1, 0] - r[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


def simulated_objects(scene):
    """The scene's objects with a role, in a stable order (by name)."""
    return sorted((o for o in scene.objects if o.taichi_frac_sim.role != "NONE"), key=lambda o: o.name)


def export_scene(context) -> Export:
    """Write the scene file, its meshes and nothing else; returns what was written. Raises
    ExportError naming the object when one cannot be simulated (not a mesh, not closed)."""
    scene = context.scene
    objects = simulated_objects(scene)
    bodies = [o for o in objects if o.taichi_frac_sim.role in ("BREAKABLE", "RIGID")]
    if not any(o.taichi_frac_sim.role == "BREAKABLE" for o in bodies):
        raise ExportError("no object is Breakable: set an object's taichi-frac role to Breakable "
                          "(Sidebar > taichi-frac > Simulation)")
    for obj in objects:
        if obj.taichi_frac_sim.role != "STATIC" and obj.type != "MESH":
            raise ExportError(f"object {obj.name!r} is a {obj.type.lower()}, not a mesh: only meshes can be "
                              f"{obj.taichi_frac_sim.role.lower()}; convert it to a mesh or set its role to Static")
    if scene.frame_end <= scene.frame_start:
        raise ExportError(f"the scene's frame range {scene.frame_start}-{scene.frame_end} has no frame to "
                          "simulate: make the end frame later than the start frame")
    cache = cache_path(scene)
    mesh_dir = os.path.splitext(cache)[0] + "_meshes"
    os.makedirs(mesh_dir, exist_ok=True)
    scale = metres_per_unit(scene)
    fps = scene_fps(scene)
    names = _unique_names(objects)
    current = scene.frame_current
    try:
        return _write(context, scene, objects, bodies, names, cache, mesh_dir, scale, fps)
    finally:
        scene.frame_set(current)  # (the artist's frame: the export reads the start frame)


def _write(context, scene, objects, bodies, names, cache, mesh_dir, scale, fps) -> Export:
    """export_scene's writing, at the start frame."""
    settings = scene.taichi_frac_sim
    frame_start, frame_end = scene.frame_start, scene.frame_end
    stem, folder = os.path.splitext(cache)[0], os.path.dirname(cache)
    scene.frame_set(frame_start)
    # Velocities from animation first: they move the frame, the meshes are read at the start.
    velocities = {}
    for obj in bodies:
        props = obj.taichi_frac_sim
        if props.velocity_source == "ANIMATION":
            velocities[obj.name] = animated_velocity(scene, obj, frame_start, scale)
    depsgraph = context.evaluated_depsgraph_get()
    entries, colliders = [], []
    if settings.ground:
        colliders.append({"type": "ground", "height": f32(float(settings.ground_height) * scale)})
    for obj in objects:
        props = obj.taichi_frac_sim
        if props.role == "STATIC":
            colliders.append(_static_box(obj, depsgraph, scale) | {
                "friction": f32(props.friction), "restitution": f32(props.restitution)})
            continue
        vertices, triangles = world_triangles(obj, depsgraph, scale)
        try:
            centre, volume = volume_centroid(vertices, triangles)
        except ValueError as exc:
            raise ExportError(f"object {obj.name!r}: its mesh {exc}: a simulated body must be a closed surface") \
                from None
        if volume < 0:
            raise ExportError(f"object {obj.name!r}: its mesh is inside out (negative volume {volume:.3g} m^3): "
                              "recalculate its normals outside (Mesh > Normals > Recalculate Outside)")
        mesh_file = os.path.join(mesh_dir, names[obj.name] + ".obj")
        write_obj(mesh_file, vertices, triangles)
        if obj.name in velocities:
            linear, angular, origin = velocities[obj.name]
            linear = linear + np.cross(angular, centre - origin)  # the centre of mass's velocity
        else:
            linear = np.asarray(props.linear_velocity, dtype=np.float64) * scale
            angular = np.asarray(props.angular_velocity, dtype=np.float64)
        entry = {
            "name": names[obj.name],
            "mesh": os.path.relpath(mesh_file, folder).replace(os.sep, "/"),
            "material": _material(props),
            "breakable": props.role == "BREAKABLE",
            "position": _vector(centre),
            "linear_velocity": _vector(linear),
            "angular_velocity": _vector(angular),
            "friction": f32(props.friction),
            "restitution": f32(props.restitution),
            "particles": {"target_particles": int(settings.particles)},
        }
        if props.role == "BREAKABLE":
            entry["fracture"] = _fracture(props, scale)
            if settings.draft:
                entry["fracture"]["crack_fit_rounds"] = 0
        entries.append(entry)
    document = {
        "name": safe_name(scene.name),
        "simulation": {"fps": float(fps), "duration": (frame_end - frame_start) / fps,
                       "substeps": int(settings.substeps)},
        "output": {"path": os.path.basename(cache)},
        "colliders": colliders,
        "objects": entries,
    }
    header = (f"Exported from Blender scene {scene.name!r}: frames {frame_start}-{frame_end} at {fps:g} fps "
              f"(time 0 is frame {frame_start}).\nMeshes are in world placement (metres, Z up); each position is "
              "its mesh's centre of mass.\nRun again with: taichi-frac run " + os.path.basename(stem) + ".toml")
    scene_path = stem + ".toml"
    with open(scene_path, "w", encoding="utf-8") as out:
        out.write(scene_toml.dumps(document, header))
    return Export(cache_path=cache, scene_path=scene_path, stats_path=stem + ".stats.json", mesh_dir=mesh_dir,
                  names={v: k for k, v in names.items()},
                  breakable=[o.name for o in bodies if o.taichi_frac_sim.role == "BREAKABLE"],
                  frame_start=frame_start, fps=fps)
