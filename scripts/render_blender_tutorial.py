"""Render the pictures of the Blender tutorial (docs/guide/blender-simulate.md) in Blender as
a Python module (.venv-blender), through the add-on as an artist would use it: author a
porcelain cube and a rigid ball, press Simulate (the real ``taichi-frac run`` in its own
process) at 4 m/s, read why the cube held, simulate again at 12 m/s, render.

    TAICHI_FRAC_EXECUTABLE=.venv/bin/taichi-frac .venv-blender/bin/python scripts/render_blender_tutorial.py \
        [--out docs/guide] [--samples 16] [--resolution 800x450]

Writes blender-tutorial-setup.jpg, -impact.jpg and -end.jpg, and prints the run's findings.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import bpy
from mathutils import Vector

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "blender_addon"))
import render_cache  # noqa: E402  (its camera, sun, sky and checkerboard floor)
import taichi_frac_blender  # noqa: E402


def author_scene(work: Path):
    """The tutorial's set-up: what its 'Set up' section tells the reader to do."""
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 24, 1.0
    scene.frame_start, scene.frame_end = 1, 25
    settings = scene.taichi_frac_sim
    settings.cache_path = str(work / "tutorial.usdc")
    settings.particles = 2000
    settings.ground = True
    bpy.ops.mesh.primitive_cube_add(size=0.2, location=(0.0, 0.0, 0.3),
                                    rotation=(math.radians(45.0), math.radians(35.0), 0.0))
    cube = bpy.context.active_object
    cube.name = "Cube"
    sim = cube.taichi_frac_sim
    sim.role, sim.material = "BREAKABLE", "porcelain"
    sim.crack_count, sim.crack_length = 3, 0.4
    sim.linear_velocity = (0.0, 0.0, -12.0)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.1, location=(0.35, 0.0, 0.12))
    ball = bpy.context.active_object
    ball.name = "Ball"
    bpy.ops.object.shade_smooth()
    ball.taichi_frac_sim.role = "RIGID"
    ball.taichi_frac_sim.material = "concrete"
    for obj, colour in ((cube, (0.9, 0.89, 0.85, 1.0)), (ball, (0.35, 0.36, 0.38, 1.0))):
        material = bpy.data.materials.new(obj.name)
        material.diffuse_color = colour
        material.use_nodes = True
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = colour
        obj.data.materials.append(material)
    return scene, cube, ball


def render(scene, path: Path, frame: int) -> None:
    scene.frame_set(frame)
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    print(f"rendered {path}", flush=True)


def main(argv) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", default=str(ROOT / "docs" / "guide"))
    parser.add_argument("--work", default=str(ROOT / "out" / "blender_tutorial"))
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--resolution", default="800x450")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.resolution.lower().split("x"))
    out, work = Path(args.out), Path(args.work)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    taichi_frac_blender.register()
    scene, cube, ball = author_scene(work)
    render_cache.setup_stage(Vector((-0.35, -0.3, 0.0)), Vector((0.55, 0.3, 0.45)), width, height, args.samples)
    scene.render.image_settings.file_format = "JPEG"
    scene.render.image_settings.quality = 85
    render(scene, out / "blender-tutorial-setup.jpg", 1)

    # First try: a gentle 4 m/s. The cube holds; the panel says why and what would break it.
    cube.taichi_frac_sim.linear_velocity = (0.0, 0.0, -4.0)
    assert bpy.ops.taichi_frac.simulate(wait=True) == {"FINISHED"}
    held = cube.taichi_frac_sim
    print(f"first run (4 m/s): {held.result_state}: {held.result_note}")
    # Second try: the 12 m/s of the set-up.
    cube.taichi_frac_sim.linear_velocity = (0.0, 0.0, -12.0)
    assert bpy.ops.taichi_frac.simulate(wait=True) == {"FINISHED"}
    print(f"second run (12 m/s): {cube.taichi_frac_sim.result_state}; {scene.taichi_frac_sim.last_message}")
    render(scene, out / "blender-tutorial-impact.jpg", 3)
    render(scene, out / "blender-tutorial-end.jpg", scene.frame_end)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]))
