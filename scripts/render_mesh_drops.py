"""Render the drops of `taichi-frac bench meshes` into one picture for the gallery: each
mesh of ../shared/meshes whole at its first frame and broken a few frames later, every
frame framed on its own pieces. Run `taichi-frac bench meshes` first (it writes the caches).

    .venv/bin/python scripts/render_mesh_drops.py [--caches out/bench/meshes_inputs/caches]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parents[1]
MESHES = ("beetle", "cow", "fandisk", "rocker-arm", "spot", "stanford-bunny", "suzanne", "teapot")
SHARED_MESHES = ROOT.parent / "shared" / "meshes"
TILE = (320, 240)


def render(cache: Path, frame: int, folder: Path, samples: int) -> Image.Image:
    """One frame of ``cache``, framed on the pieces it shows."""
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run([str(ROOT / ".venv" / "bin" / "taichi-frac"), "render", str(cache), "--frames", str(frame),
                    "-o", str(folder), "--resolution", f"{TILE[0]}x{TILE[1]}", "--samples", str(samples)],
                   check=True, capture_output=True)
    return Image.open(folder / f"frame_{frame:04d}.png").convert("RGB")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--caches", type=Path, default=ROOT / "out" / "bench" / "meshes_inputs" / "caches")
    parser.add_argument("--broken-frame", type=int, default=8, help="the frame that shows the pieces")
    parser.add_argument("--samples", type=int, default=6)
    parser.add_argument("-o", "--output", type=Path, default=ROOT / "docs" / "gallery" / "meshes_drops.jpg")
    parser.add_argument("--all", action="store_true",
                        help="every mesh of ../shared/meshes (the benchmark's corpus), not the gallery's eight")
    args = parser.parse_args()
    meshes = (sorted(p.stem for p in SHARED_MESHES.iterdir() if p.suffix.lower() in (".obj", ".ply", ".stl", ".off",
                                                                                       ".glb", ".gltf"))
              if args.all else MESHES)
    missing = [m for m in meshes if not (args.caches / f"{m}.usdc").exists()]
    if missing:
        print(f"no drop cache for {', '.join(missing)} under {args.caches}: run `taichi-frac bench meshes` first",
              file=sys.stderr)
        return 2
    columns = 8 if args.all else 4  # four (two) meshes a row, each whole then broken
    rows = -(-len(meshes) * 2 // columns)
    sheet = Image.new("RGB", (columns * TILE[0], rows * TILE[1]), "white")
    for i, name in enumerate(meshes):
        cache = args.caches / f"{name}.usdc"
        for j, frame in enumerate((1, args.broken_frame)):
            tile = render(cache, frame, args.caches.parent / "renders" / name / str(frame), args.samples)
            ImageDraw.Draw(tile).text((8, 6), f"{name}, frame {frame}", fill=(0, 0, 0))
            k = 2 * i + j
            sheet.paste(tile, ((k % columns) * TILE[0], (k // columns) * TILE[1]))
        print(f"rendered {name}", flush=True)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(args.output, quality=85, optimize=True)
    print(f"wrote {args.output} ({args.output.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
