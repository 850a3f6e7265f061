"""Runs INSIDE Blender (bpy): import a taichi-frac cache through the add-on and render frames
to PNG with Cycles on the CPU. Called by ``taichi-frac render`` (taichi_frac/commands/render.py);
not part of the extension zip.

    python render_cache.py CACHE OUT_DIR --frames 1,50,100 --resolution 320x240 --samples 16 \
        [--look-at 'wall*']

The camera looks at the bounding box of every fragment visible in the rendered frames (one
fixed camera for all of them; with --look-at, only of the objects whose names match one of
its comma-separated globs, e.g. to leave out a projectile that flew far away), a sun and a
grey sky light them, a ground plane lies at z = 0 (or under the lowest fragment when one
goes below it).
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


def visible_bounds(objects, frames):
    low, high = Vector((math.inf,) * 3), Vector((-math.inf,) * 3)
    scene = bpy.context.scene
    for frame in frames:
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for obj in objects:
            if obj.hide_render:
                continue
            matrix = obj.evaluated_get(depsgraph).matrix_world
            for corner in obj.bound_box:
                p = matrix @ Vector(corner)
                low = Vector(map(min, low, p))
                high = Vector(map(max, high, p))
    if low.x == math.inf:
        low, high = Vector((-1, -1, 0)), Vector((1, 1, 1))
    return low, high


def setup_stage(low, high, width, height, samples):
    scene = bpy.context.scene
    center = (low + high) / 2
    radius = max((high - low).length / 2, 0.05)
    ground_z = min(0.0, low.z)

    bpy.ops.mesh.primitive_plane_add(size=max(40 * radius, 10.0), location=(center.x, center.y, ground_z))
    ground = bpy.context.active_object
    ground.name = "ground"
    material = bpy.data.materials.new("ground")
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.32, 0.34, 0.37, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.9
    ground.data.materials.append(material)

    camera_data = bpy.data.cameras.new("camera")
    camera_data.lens = 50.0
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    direction = Vector((1.0, -1.4, 0.75)).normalized()
    # Fit the bounding sphere in the narrower field of view, with a margin.
    fov = camera_data.angle_y if width >= height else camera_data.angle_x
    distance = 1.15 * radius / math.sin(fov / 2)
    camera.location = center + direction * distance
    camera.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    camera_data.clip_start = max(distance - 3 * radius, 1e-3) * 0.1
    camera_data.clip_end = (distance + 50 * radius) * 2
    scene.camera = camera

    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 3.5
    sun.data.angle = math.radians(8)
    sun.rotation_euler = (math.radians(40), math.radians(10), math.radians(35))
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("sky")
    scene.world = world
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.55, 0.62, 0.72, 1.0)
    background.inputs["Strength"].default_value = 0.6

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.film_transparent = False


def main(argv):
    parser = argparse.ArgumentParser()
    parser.add_argument("cache")
    parser.add_argument("out_dir")
    parser.add_argument("--frames", default="")
    parser.add_argument("--resolution", default="320x240")
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
    low, high = visible_bounds(framed, frames)
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
