"""``taichi-frac render CACHE --frames 1,50,100 -o DIR [--movie out.mp4]``: headless renders.

Blender runs as a Python module in its own environment (.venv-blender: bpy bundles its own USD
and must not meet usd-core), so this command only starts that interpreter on
blender_addon/render_cache.py, which imports the cache through the add-on and renders PNGs
with Cycles on the CPU (960x540 at 16 samples by default). ``--movie`` then joins the frames
into an MP4 (H.264 through imageio-ffmpeg's bundled ffmpeg) or a GIF (Pillow) at the cache's
frame rate.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RENDER_SCRIPT = Path(__file__).resolve().parents[1] / "blender_addon" / "render_cache.py"


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


def cache_frame_range(cache: Path) -> tuple[int, int, float]:
    """(first frame, last frame, frames per second) of a USD cache."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(cache))
    if stage is None:
        raise ValueError(f"USD cannot open {cache}")
    return int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode()), float(stage.GetTimeCodesPerSecond())


#: Colours of a GIF movie's shared palette (at most 256).
GIF_COLORS = 64


def write_movie(frames: list[Path], path: Path, fps: float) -> None:
    """Join PNG ``frames`` (all one size) into ``path``: .mp4 (H.264, yuv420p) or .gif."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to join")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        images = [Image.open(f).convert("RGB") for f in frames]
        # One palette of GIF_COLORS for every frame, from four frames across the movie, and
        # no dithering: Cycles' noise dithered anew each frame compresses poorly.
        width, height = images[0].size
        samples = [images[round(k * (len(images) - 1) / 3)] for k in range(4)]
        sheet = Image.new("RGB", (width, height * len(samples)))
        for k, image in enumerate(samples):
            sheet.paste(image, (0, height * k))
        palette = sheet.quantize(colors=GIF_COLORS, method=Image.Quantize.MEDIANCUT)
        indexed = [image.quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
        # GIF delays are in hundredths of a second: the nearest one to 1/fps.
        indexed[0].save(path, save_all=True, append_images=indexed[1:], loop=0,
                        duration=max(2, round(100.0 / fps)) * 10, optimize=True)
        return
    import imageio_ffmpeg
    import numpy as np

    size = Image.open(frames[0]).size
    writer = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264", quality=7,
                                         macro_block_size=2, ffmpeg_log_level="error")
    writer.send(None)
    try:
        for frame in frames:
            image = Image.open(frame).convert("RGB")
            if image.size != size:
                raise ValueError(f"{frame} is {image.size[0]}x{image.size[1]}, the first frame {size[0]}x{size[1]}")
            writer.send(np.ascontiguousarray(np.asarray(image)))
    finally:
        writer.close()


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
    movie = Path(args.movie) if args.movie else None
    if movie is not None and movie.suffix.lower() not in (".mp4", ".gif"):
        print(f"taichi-frac render: --movie {args.movie!r} must end in .mp4 or .gif", file=sys.stderr)
        return 2
    try:
        frames = _frames(args.frames) if args.frames else ""
    except ValueError as exc:
        print(f"taichi-frac render: bad --frames {args.frames!r}: {exc}", file=sys.stderr)
        return 2
    try:
        width, height = (int(v) for v in args.resolution.lower().split("x"))
        if width < 2 or height < 2:
            raise ValueError
    except ValueError:
        print(f"taichi-frac render: bad --resolution {args.resolution!r}: use WIDTHxHEIGHT, e.g. 960x540",
              file=sys.stderr)
        return 2
    fps = None
    if movie is not None:
        try:
            first, last, fps = cache_frame_range(cache)
        except ValueError as exc:
            print(f"taichi-frac render: {exc}", file=sys.stderr)
            return 2
        if not frames:
            frames = _frames(f"{first}-{last}") if last > first else str(first)
    command = [str(python), str(RENDER_SCRIPT), str(cache.resolve()), str(Path(args.output).resolve()),
               "--resolution", args.resolution, "--samples", str(args.samples)]
    if frames:
        command += ["--frames", frames]
    if args.look_at:
        command += ["--look-at", args.look_at]
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)  # the main environment's pxr must not reach Blender
    code = subprocess.run(command, env=env).returncode
    if code != 0 or movie is None:
        return code
    pngs = [Path(args.output) / f"frame_{int(f):04d}.png" for f in frames.split(",")]
    write_movie(pngs, movie, args.movie_fps or fps)
    print(f"wrote {movie} ({len(pngs)} frames at {args.movie_fps or fps:g} fps)", flush=True)
    return 0


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render frames of a USD cache to PNG in headless Blender",
        description="Render frames of a taichi-frac USD cache to PNG with Blender (Cycles, CPU), "
        "imported through the add-on, with a camera framing the bulk of the pieces, a sun, a sky and a "
        "checkerboard ground; optionally joined into an MP4 or GIF movie.",
    )
    parser.add_argument("cache", help="a cache written by 'taichi-frac run' (.usdc/.usda/.usd)")
    parser.add_argument("--frames", default="",
                        help="frames to render: '1,50,100', '1-100' or '1-100:10' (default: first, middle, "
                             "last; with --movie, every frame)")
    parser.add_argument("--look-at", default="", metavar="GLOBS",
                        help="frame the camera on the objects whose names match these comma-separated globs "
                             "(e.g. 'wall*' to leave out a ball that flew away; default: every object)")
    parser.add_argument("-o", "--output", default="out/renders",
                        help="output folder for frame_NNNN.png (default: out/renders)")
    parser.add_argument("--resolution", default="960x540", help="WIDTHxHEIGHT in pixels (default: 960x540)")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples per pixel (default: 16)")
    parser.add_argument("--movie", default="", metavar="FILE",
                        help="also join the rendered frames into FILE: .mp4 (H.264) or .gif")
    parser.add_argument("--movie-fps", type=float, default=None,
                        help="frame rate of the movie (default: the cache's; lower it for slow motion)")
    parser.add_argument("--blender-python", default=str(default_blender_python()),
                        help="Python with bpy (default: $TAICHI_FRAC_BLENDER_PYTHON or .venv-blender/bin/python)")
    parser.set_defaults(func=run)
