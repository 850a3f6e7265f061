"""Running scripts in the Blender environment (.venv-blender), for the Blender tests."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"


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
    """Run ``script`` with Blender's python in ``tmp_path``, with a private Blender user folder."""
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"))
    env.pop("PYTHONPATH", None)  # keep the main env's pxr (usd-core) away from Blender's
    return subprocess.run([str(blender_python()), str(script), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=tmp_path)
