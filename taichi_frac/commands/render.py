"""``taichi-frac render CACHE --frames 1,50,100 -o DIR``: headless PNG renders of a cache.

Blender runs as a Python module in its own environment (.venv-blender: bpy bundles its own USD
and must not meet usd-core), so this command only starts that interpreter on
blender_addon/render_cache.py, which imports the cache through the add-on and renders with
Cycles on the CPU (320x240 at 16 samples: a few seconds a frame).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RENDER_SCRIPT = REPO / "blender_addon" / "render_cache.py"


def _frames(text: str) -> str:
    """'1,50,100' or '1-10' or '1-100:10' (every 10th) -> '1,50,100' for the Blender script."""
    frames = []
    for part in text.split(","):
        part = part.strip()
        if "-" in part[1:]:
            span, _, step = part.partition(":")
            first, _, last = span.partition("-")
            frames += range(int(first), int(last) + 1, int(step or 1))
        elif part:
            frames.append(int(part))
    if not frames:
        raise ValueError("no frames")
    return ",".join(str(f) for f in frames)


def default_blender_python() -> Path:
    return Path(os.environ.get("TAICHI_FRAC_BLENDER_PYTHON", REPO / ".venv-blender" / "bin" / "python"))


def run(args) -> int:
    python = Path(args.blender_python)
    if not python.exists():
        print(f"taichi-frac render: no Blender Python at {python}; create it with "
              f"`bash -c 'source scripts/_setup.sh; setup_blender'` or pass --blender-python",
              file=sys.stderr)
        return 2
    cache = Path(args.cache)
    if not cache.exists():
        print(f"taichi-frac render: no such cache {cache}", file=sys.stderr)
        return 2
    try:
        frames = _frames(args.frames) if args.frames else ""
    except ValueError as exc:
        print(f"taichi-frac render: bad --frames {args.frames!r}: {exc}", file=sys.stderr)
        return 2
    command = [str(python), str(RENDER_SCRIPT), str(cache.resolve()), str(Path(args.output).resolve()),
               "--resolution", args.resolution, "--samples", str(args.samples)]
    if frames:
        command += ["--frames", frames]
    if args.look_at:
        command += ["--look-at", args.look_at]
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the main environment's pxr must not reach Blender
    return subprocess.run(command, env=env).returncode


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render frames of a USD cache to PNG in headless Blender",
        description="Render frames of a taichi-frac USD cache to PNG with Blender (Cycles, CPU), "
        "imported through the add-on, with a camera framing the fragments, a sun and a ground plane.",
    )
    parser.add_argument("cache", help="a cache written by 'taichi-frac run' (.usdc/.usda/.usd)")
    parser.add_argument("--frames", default="",
                        help="frames to render: '1,50,100', '1-100' or '1-100:10' (default: first, middle, last)")
    parser.add_argument("--look-at", default="", metavar="GLOBS",
                        help="frame the camera on the objects whose names match these comma-separated globs "
                             "(e.g. 'wall*' to leave out a ball that flew away; default: every object)")
    parser.add_argument("-o", "--output", default="out/renders",
                        help="output folder for frame_NNNN.png (default: out/renders)")
    parser.add_argument("--resolution", default="320x240", help="WIDTHxHEIGHT in pixels (default: 320x240)")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples per pixel (default: 16)")
    parser.add_argument("--blender-python", default=str(default_blender_python()),
                        help="Python with bpy (default: $TAICHI_FRAC_BLENDER_PYTHON or .venv-blender/bin/python)")
    parser.set_defaults(func=run)
