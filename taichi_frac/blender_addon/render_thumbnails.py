"""Runs INSIDE Blender (bpy): render the last frame of many taichi-frac caches, one small PNG
each, in one Blender process (starting Blender costs more than a small render). Called by
``taichi-frac sweep`` for its contact sheet (taichi_frac/sweep/sheet.py); not part of the
extension zip.

    python render_thumbnails.py JOBS.json --resolution 200x150 --samples 8

JOBS.json is a list of [cache, png] pairs. Each cache is imported through the add-on into
a fresh scene and framed and lit as ``render_cache.py`` does. A cache that fails is reported
on stderr and the others go on; the exit status is 1 when any failed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parent))
import render_cache  # noqa: E402
import taichi_frac_blender  # noqa: E402


def render_last_frame(cache: str, png: str, width: int, height: int, samples: int) -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Object, "taichi_frac"):  # (the add-on's properties, once a process)
        taichi_frac_blender.register()
    collection = taichi_frac_blender.import_cache(bpy.context, cache)
    scene = bpy.context.scene
    frame = scene.frame_end
    low, high = render_cache.framed_box(list(collection.all_objects), [frame])
    render_cache.transmissive_glass(bpy.data.materials)
    render_cache.setup_stage(low, high, width, height, samples)
    scene.frame_set(frame)
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    scene.render.filepath = png
    bpy.ops.render.render(write_still=True)


def main(argv) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("jobs")
    parser.add_argument("--resolution", default="200x150")
    parser.add_argument("--samples", type=int, default=8)
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.resolution.lower().split("x"))
    failed = 0
    for cache, png in json.loads(Path(args.jobs).read_text()):
        try:
            render_last_frame(cache, png, width, height, args.samples)
            print(f"rendered {png}", flush=True)
        except Exception as exc:  # one bad cache must not cost the others their pictures
            failed += 1
            print(f"could not render {cache}: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
