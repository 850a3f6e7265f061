"""Runs INSIDE Blender (bpy): import a taichi-frac cache through the add-on and render frames
to PNG with Cycles on the CPU. Called by ``taichi-frac render`` (taichi_frac/commands/render.py);
not part of the extension zip.

    python render_cache.py CACHE OUT_DIR --frames 1,50,100 --resolution 960x540 --samples 16 \
        [--look-at 'wall*']

One fixed camera frames the bulk of the pieces: the 10th-90th percentile box of the pieces'
centres over the rendered frames, so a few shards that fly metres away do not shrink the
rest to a speck.
``--look-at`` frames only the objects whose names match its comma-separated globs. A sun and
a blue sky light the scene; the ground is a matte checkerboard at z = 0 (or under the lowest
piece), so it reads as a floor and shows scale (tiles of a power of ten metres, at least 4
across the framed box).
"""

from __future__ import annotations

import argparse
import fnmatch
import math
import sys
from pathlib import Path

import bpy
from mathutils import Vector

sys.path.insert(0, str(Path(__file__).resolve().parent))
import taichi_frac_blender  # noqa: E402


def framed_box(objects, frames):
    """(low, high) corners of the box the camera frames: the 10th-90th percentile box of the
    visible objects' centres over ``frames``, widened by the median object's half size."""
    scene = bpy.context.scene
    centres, half_sizes = [], []
    for frame in frames:
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for obj in objects:
            if obj.hide_render:  # (keyed: hidden before its birth and after it broke)
                continue
            evaluated = obj.evaluated_get(depsgraph)
            corners = [evaluated.matrix_world @ Vector(c) for c in obj.bound_box]
            low = Vector(map(min, *corners))
            high = Vector(map(max, *corners))
            centres.append((low + high) / 2)
            half_sizes.append((high - low).length / 2)
    if not centres:
        return Vector((-1, -1, 0)), Vector((1, 1, 1))
    # The 10 % lowest and highest of each coordinate left out (none of fewer than 10).
    trim = len(centres) // 10
    low, high = Vector(), Vector()
    for axis in range(3):
        values = sorted(c[axis] for c in centres)
        low[axis], high[axis] = values[trim], values[-1 - trim]
    margin = sorted(half_sizes)[len(half_sizes) // 2]
    return low - Vector((margin,) * 3), high + Vector((margin,) * 3)


def _ground_material(tile: float):
    """A matte two-tone checkerboard of ``tile``-metre squares (object coordinates)."""
    material = bpy.data.materials.new("ground")  # (Blender 5: always a node tree)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Roughness"].default_value = 0.85
    coordinates = nodes.new("ShaderNodeTexCoord")
    checker = nodes.new("ShaderNodeTexChecker")
    # The checker's period is 1/scale: two tiles.
    checker.inputs["Scale"].default_value = 1.0 / (2.0 * tile)
    checker.inputs["Color1"].default_value = (0.30, 0.25, 0.19, 1.0)
    checker.inputs["Color2"].default_value = (0.20, 0.16, 0.12, 1.0)
    links.new(coordinates.outputs["Object"], checker.inputs["Vector"])
    links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def transmissive_glass(materials) -> None:
    """A Principled material whose alpha is below 1 (a cache's opacity read as a cut-out)
    renders as glass instead: Cycles refracts through Transmission at the same tint."""
    for material in materials:
        tree = getattr(material, "node_tree", None)
        bsdf = next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None) if tree else None
        if bsdf is None or bsdf.inputs["Alpha"].default_value >= 1.0:
            continue
        bsdf.inputs["Alpha"].default_value = 1.0
        bsdf.inputs["Transmission Weight"].default_value = 1.0


def setup_stage(low, high, width, height, samples):
    scene = bpy.context.scene
    center = (low + high) / 2
    radius = max((high - low).length / 2, 0.05)
    ground_z = min(0.0, low.z)

    bpy.ops.mesh.primitive_plane_add(size=max(40 * radius, 10.0), location=(center.x, center.y, ground_z))
    ground = bpy.context.active_object
    ground.name = "ground"
    span = max(high.x - low.x, high.y - low.y, 1e-3)
    ground.data.materials.append(_ground_material(10.0 ** math.floor(math.log10(span / 4))))

    camera_data = bpy.data.cameras.new("camera")
    camera_data.lens = 50.0
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    direction = Vector((1.0, -1.4, 0.75)).normalized()
    # Fit the bounding sphere in the narrower field of view, with a small margin.
    fov = camera_data.angle_y if width >= height else camera_data.angle_x
    distance = 1.05 * radius / math.sin(fov / 2)
    camera.location = center + direction * distance
    camera.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    camera_data.clip_start = max(distance - 3 * radius, 1e-3) * 0.1
    camera_data.clip_end = (distance + 50 * radius) * 2
    scene.camera = camera

    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 4.0
    sun.data.angle = math.radians(4)
    sun.rotation_euler = (math.radians(40), math.radians(10), math.radians(35))
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("sky")
    scene.world = world
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.45, 0.62, 0.9, 1.0)
    background.inputs["Strength"].default_value = 0.8

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "AgX"  # (highlights roll off instead of clipping)
    looks = {item.identifier for item in scene.view_settings.bl_rna.properties["look"].enum_items}
    if "AgX - Punchy" in looks:
        scene.view_settings.look = "AgX - Punchy"


def main(argv):
    parser = argparse.ArgumentParser()
    parser.add_argument("cache")
    parser.add_argument("out_dir")
    parser.add_argument("--frames", default="")
    parser.add_argument("--resolution", default="960x540")
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--look-at", default="")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.resolution.lower().split("x"))

    bpy.ops.wm.read_factory_settings(use_empty=True)
    taichi_frac_blender.register()
    collection = taichi_frac_blender.import_cache(bpy.context, args.cache)
    scene = bpy.context.scene
    if args.frames:
        frames = [int(f) for f in args.frames.split(",")]
    else:
        frames = sorted({scene.frame_start, (scene.frame_start + scene.frame_end) // 2, scene.frame_end})
    framed = list(collection.all_objects)
    if args.look_at:
        globs = [g.strip() for g in args.look_at.split(",") if g.strip()]
        framed = [o for o in framed if any(fnmatch.fnmatchcase(o.name, g) for g in globs)]
        if not framed:
            names = ", ".join(sorted(o.name for o in collection.all_objects)[:10])
            print(f"--look-at {args.look_at!r} matches no object (some names: {names})", file=sys.stderr)
            return 2
    low, high = framed_box(framed, frames)
    transmissive_glass(bpy.data.materials)
    setup_stage(low, high, width, height, args.samples)
    out_dir = Path(args.out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for frame in frames:
        scene.frame_set(frame)
        scene.render.filepath = str(out_dir / f"frame_{frame:04d}.png")
        bpy.ops.render.render(write_still=True)
        print(f"rendered {scene.render.filepath}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
