"""What an artist relies on in the add-on, in a real Blender (one process,
tests/blender/check_features.py): re-import updates in place (an edited material, a renamed
object with a modifier, an artist's material slot survive; gone pieces removed or hidden; new
ones join their body's collection), retiming puts keys at the right seconds, a frame range,
never-visible pieces skipped, collections per body, lineage as an object pointer, the panel's
selection by generation and birth frame, the stress heat map, UsdPreviewSurface glass and
cut-out materials, and every error path reported in one line."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
sys.path.insert(0, str(ROOT / "scripts"))
import build_addon  # noqa: E402
import variants  # noqa: E402
from support.blender import blender_python, run_in_blender  # noqa: E402
from variants import Piece  # noqa: E402

pytestmark = pytest.mark.blender

FPS = 24.0
V1 = [
    Piece("slab", 0, 12, None, (0.4, 0.3, 0.1), (0, 0, 2), (0, 0, -1), 1.0),
    Piece("shard_a", 12, None, "slab", (0.2, 0.15, 0.1), (0.3, 0, 1.5), (0.5, 0, 0), 2.0),
    Piece("shard_b", 12, 24, "slab", (0.2, 0.15, 0.1), (-0.3, 0, 1.5), (-0.5, 0, 0), -2.0),
    Piece("sliver_1", 24, None, "shard_b", (0.1, 0.1, 0.1), (-1, 0, 1), (0, 0.5, 0)),
    Piece("sliver_2", 24, None, "shard_b", (0.1, 0.1, 0.1), (-1, 0.3, 1), (0, -0.5, 0)),
    Piece("flash", 30, 30, "shard_a", (0.05, 0.05, 0.05), (0.5, 0, 1)),  # born and broken at once
    Piece("plate", 0, None, None, (0.5, 0.5, 0.02), (2, 0, 0)),
]
# The re-simulation: shard_a bigger and faster, shard_b and sliver_2 gone, shard_c new,
# sliver_1 now from shard_a.
V2 = [
    V1[0],
    Piece("shard_a", 12, None, "slab", (0.25, 0.2, 0.12), (0.3, 0, 1.5), (0.8, 0.1, 0), 1.5),
    Piece("shard_c", 12, None, "slab", (0.15, 0.15, 0.1), (0, 0.4, 1.5), (0, 0.6, 0), 0.5),
    Piece("sliver_1", 24, None, "shard_a", (0.1, 0.1, 0.1), (-1, 0, 1), (0, 0.5, 0)),
    V1[6],
]
# 50 fps, for a 24 fps scene: late born at 0.52 s (scene 22.48 with offset 10), blink lives
# 0.52-0.54 s (22.48-22.96: on no frame), brief 0.54-0.56 s (22.96-23.44: on frame 23 only).
RETIME = [
    Piece("mover", 0, None, None, (0.1, 0.1, 0.1), (0, 0, 0), (1, 0, 0), 0.5),
    Piece("late", 26, None, "mover", (0.1, 0.1, 0.1), (0, 1, 0), (0, 0, 1)),
    Piece("blink", 26, 27, "mover", (0.1, 0.1, 0.1), (0, 2, 0)),
    Piece("brief", 27, 28, "mover", (0.1, 0.1, 0.1), (0, 3, 0)),
]


def test_addon_features_in_blender(tmp_path):
    blender_python()  # skip/fail as the import test does when .venv-blender is missing
    spec = {"fps": FPS, "sim": str(tmp_path / "sim.usdc"),
            "v2_pieces": {p.name: variants.describe([p], FPS)["pieces"][0] for p in V2}}
    for key, pieces in (("v1", V1), ("v2", V2)):
        spec[key] = str(tmp_path / f"{key}.usdc")
        variants.write(spec[key], pieces, FPS, 40)
    spec["retime"] = str(tmp_path / "retime.usdc")
    variants.write(spec["retime"], RETIME, 50.0, 100)
    spec["retime_desc"] = variants.describe(RETIME, 50.0)

    spec["glass"] = str(tmp_path / "glass.usda")
    variants.write(spec["glass"], V1[:3], FPS, 20)
    variants.set_preview_inputs(spec["glass"], "slab/outer", diffuseColor=(0.9, 0.95, 1.0), roughness=0.05,
                                opacity=0.1, opacityThreshold=0.0, ior=1.52)
    variants.set_preview_inputs(spec["glass"], "slab/inner", opacity=0.3, opacityThreshold=0.5, ior=1.33)
    spec["subset"] = str(tmp_path / "subset.usda")
    variants.write(spec["subset"], V1[:3], FPS, 20)
    variants.set_preview_inputs(spec["subset"], "slab/outer", opacity=0.5)
    variants.set_preview_inputs(spec["subset"], "slab/inner", opacity=0.8, opacityThreshold=0.5)

    spec["tile"] = str(tmp_path / "tile.usdc")
    variants.write(spec["tile"], [Piece("tile", 0, None, None, (0.5, 0.5, 0.1), (0, 0, 0))], FPS, 2)
    spec["incomplete"] = str(tmp_path / "incomplete.usdc")
    variants.write(spec["incomplete"], V1, FPS, 20, complete=False)
    spec["newer"] = str(tmp_path / "newer.usda")
    variants.write(spec["newer"], V1[:1], FPS, 5)
    variants.set_schema_version(spec["newer"], 99)
    spec["foreign"] = str(tmp_path / "foreign.usda")
    variants.write_foreign_usd(spec["foreign"])
    spec["corrupt"] = str(tmp_path / "corrupt.usdc")
    Path(spec["corrupt"]).write_bytes(b"PXR-USDC" + os.urandom(200))
    spec["truncated"] = str(tmp_path / "truncated.usdc")
    whole = Path(spec["v1"]).read_bytes()
    Path(spec["truncated"]).write_bytes(whole[: len(whole) // 2])
    spec["missing"] = str(tmp_path / "nowhere.usdc")
    spec["folder"] = str(tmp_path)
    spec_path = tmp_path / "spec.json"
    spec_path.write_text(json.dumps(spec))

    addon_zip = build_addon.build(tmp_path / "dist")
    run = run_in_blender(ROOT / "tests" / "blender" / "check_features.py", addon_zip, spec_path, tmp_path=tmp_path)
    print(run.stdout[-6000:])
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-4000:]
    assert "0 failures" in run.stdout
    for section in ("re-import", "retime", "materials", "heat render", "errors"):
        assert f"{section}: checked" in run.stdout
