"""The add-on in a real Blender (bpy 5.0.1 in .venv-blender): the built zip installs as an
extension, and caches imported through ``bpy.ops.import_scene.taichi_frac`` match closed-form
motion, births and deaths at every frame (tests/blender/check_import.py does the checking)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
sys.path.insert(0, str(ROOT / "scripts"))
import write_synthetic  # noqa: E402
import build_addon  # noqa: E402

from support.blender import blender_python, run_in_blender  # noqa: E402

pytestmark = pytest.mark.blender


def test_import_matches_cache_at_every_frame(tmp_path):
    python = blender_python()
    assert python.exists()
    z_up = tmp_path / "z_up.usdc"
    y_cm = tmp_path / "y_up_cm.usda"
    write_synthetic.write(z_up)
    write_synthetic.write(y_cm, up_axis="Y", meters_per_unit=0.01)
    addon_zip = build_addon.build(tmp_path / "dist")
    run = run_in_blender(ROOT / "tests" / "blender" / "check_import.py", addon_zip, z_up, y_cm, tmp_path=tmp_path)
    print(run.stdout[-4000:])
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-4000:]
    assert "0 failures" in run.stdout
    assert "z_up.usdc: 5 objects, 179 world matrices checked" in run.stdout
