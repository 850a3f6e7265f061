#!/usr/bin/env bash
# Re-render the gallery and the README picture from the shipped scenes: run each scene to a
# cache under out/gallery/, render chosen frames with `taichi-frac render` (960x540, the
# command's defaults), and save them as small JPEGs (and one GIF) in docs/gallery/.
# Takes a few minutes on a laptop (the runs, then Cycles on the CPU). Set up as demo.sh does.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_setup.sh
setup_main
setup_blender
OUT=out/gallery
DOCS=docs/gallery
mkdir -p "$OUT" "$DOCS"
frac=.venv/bin/taichi-frac

# Each scene's cache; REUSE_CACHES=1 keeps caches already under out/gallery/ (render only).
run() {
  local cache=$1; shift
  if [ "${REUSE_CACHES:-0}" = 1 ] && [ -f "$cache" ]; then echo "reusing $cache"; return; fi
  $frac run "$@" -q -o "$cache"
}
run "$OUT/ring_n1.usdc" single_ring --frames 60
run "$OUT/ring_n5.usdc" single_ring --frames 60 --set ring.fracture.crack_count=5
run "$OUT/glass_walls.usdc" glass_walls --frames 50
run "$OUT/thirteen_rings.usdc" thirteen_rings

$frac render "$OUT/ring_n1.usdc" --frames 60 -o "$OUT/ring_n1"
$frac render "$OUT/ring_n5.usdc" --frames 60 -o "$OUT/ring_n5"
$frac render "$OUT/glass_walls.usdc" --frames 0,8,50 -o "$OUT/glass_walls"
$frac render "$OUT/thirteen_rings.usdc" --frames 20,150 -o "$OUT/thirteen_rings"
# A short slow-motion loop of the ball going through the walls (small: it is a GIF).
$frac render "$OUT/glass_walls.usdc" --frames 0-24 --resolution 320x180 --samples 6 \
    -o "$OUT/glass_walls_movie" --movie "$DOCS/glass_walls.gif" --movie-fps 12.5

# PNG -> JPEG (quality 85: ~100 KB at 960x540) under docs/gallery/.
.venv/bin/python - "$OUT" "$DOCS" <<'PY'
import sys
from pathlib import Path
from PIL import Image

out, docs = Path(sys.argv[1]), Path(sys.argv[2])
picks = {
    "ring_n1/frame_0060.png": "single_ring_crack_count_1.jpg",
    "ring_n5/frame_0060.png": "single_ring_crack_count_5.jpg",
    "glass_walls/frame_0000.png": "glass_walls_start.jpg",
    "glass_walls/frame_0008.png": "glass_walls_impact.jpg",
    "glass_walls/frame_0050.png": "glass_walls_end.jpg",
    "thirteen_rings/frame_0020.png": "thirteen_rings_landing.jpg",
    "thirteen_rings/frame_0150.png": "thirteen_rings_end.jpg",
}
for source, target in picks.items():
    Image.open(out / source).convert("RGB").save(docs / target, quality=85, optimize=True)
    print(f"wrote {docs / target} ({(docs / target).stat().st_size // 1024} KB)")
PY

# The test meshes' drops, when `taichi-frac bench meshes` has written their caches.
if [ -d out/bench/meshes_inputs/caches ]; then
  .venv/bin/python scripts/render_mesh_drops.py --samples 6
fi
