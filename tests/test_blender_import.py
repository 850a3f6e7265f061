"""The add-on in a real Blender (bpy 5.0.1 in .venv-blender): the built zip installs as an
extension, and caches imported through ``bpy.ops.import_scene.taichi_frac`` match closed-form
motion, births and deaths at every frame (tests/blender/check_import.py does the checking)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"
sys.path.insert(0, str(ROOT / "tests" / "blender"))
sys.path.insert(0, str(ROOT / "scripts"))
import write_synthetic  # noqa: E402
import build_addon  # noqa: E402

pytestmark = pytest.mark.blender


def blender_python() -> Path:
    """The Blender environment, or a skip outside CI (scripts/test.sh creates it; CI must have it).
    TAICHI_FRAC_BLENDER_PYTHON names another one's python, e.g. one with the oldest bpy the
    manifest allows (``pip install bpy==4.4.0`` in a Python 3.11 venv)."""
    override = os.environ.get("TAICHI_FRAC_BLENDER_PYTHON")
    if override:
        return Path(override)
    if BLENDER_PYTHON.exists():
        return BLENDER_PYTHON
    message = f"{BLENDER_PYTHON} missing: run `bash -c 'source scripts/_setup.sh; setup_blender'`"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message)
    pytest.skip(message)


def run_in_blender(script, *args, tmp_path, timeout=300):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    env.pop("PYTHONPATH", None)  # keep the main env's pxr (usd-core) away from Blender's
    return subprocess.run([str(blender_python()), str(script), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=tmp_path)


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
