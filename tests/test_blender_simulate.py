"""Simulating from Blender (bpy 5.0.1 in .venv-blender) with the real command line
(.venv/bin/taichi-frac): tests/blender/check_simulate.py authors the scene and checks what
Blender shows; here the exported scene file is run again from the command line and its
fragments compared with the ones Blender got."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import build_addon  # noqa: E402
from support.blender import run_in_blender  # noqa: E402

pytestmark = pytest.mark.blender

COMMAND = ROOT / ".venv" / "bin" / "taichi-frac"
CHECK = ROOT / "tests" / "blender" / "check_simulate.py"


def run_section(section: str, tmp_path: Path) -> dict:
    addon_zip = build_addon.build(tmp_path / "dist")
    os.environ["TAICHI_FRAC_EXECUTABLE"] = str(COMMAND)
    try:
        run = run_in_blender(CHECK, addon_zip, section, tmp_path, tmp_path=tmp_path, timeout=600)
    finally:
        os.environ.pop("TAICHI_FRAC_EXECUTABLE")
    print(run.stdout[-4000:], run.stderr[-4000:])
    assert run.returncode == 0 and "0 failures" in run.stdout, run.stdout[-4000:] + run.stderr[-4000:]
    return json.loads((tmp_path / "REPORT.json").read_text())


def final_positions(cache: Path) -> dict:
    """Each fragment's world position at the cache's last frame (pxr, independent of Blender)."""
    stage = Usd.Stage.Open(str(cache))
    time = stage.GetEndTimeCode()
    cache_xform = UsdGeom.XformCache(time)
    out = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            out[str(prim.GetPath())] = np.array(cache_xform.GetLocalToWorldTransform(prim).ExtractTranslation())
    return out


def test_simulate_cube_from_blender_and_again_from_the_command_line(tmp_path):
    report = run_section("simulate", tmp_path)
    assert len(report["pieces"]) >= 2
    assert report["second_pieces"] == report["pieces"]  # the same run again: the same pieces
    # The exported scene file repeats the run from the command line: the same fragments,
    # each ending where Blender's run left it.
    again = tmp_path / "again.usdc"
    # (with the add-on's fixed string hash, so Taichi's kernel cache serves both runs)
    run = subprocess.run([str(COMMAND), "run", report["scene_path"], "-o", str(again), "-q"],
                         capture_output=True, text=True, timeout=600, env=dict(os.environ, PYTHONHASHSEED="0"))
    assert run.returncode == 0, run.stderr[-2000:]
    first, second = final_positions(Path(report["cache"])), final_positions(again)
    assert sorted(first) == sorted(second)
    assert sum(1 for p in report["pieces"] if p in second) == len(report["pieces"])
    drift = max(np.linalg.norm(first[k] - second[k]) for k in first)
    assert drift < 1e-3, f"fragments end {drift:.2e} m apart"


def test_missing_executable_and_velocity_from_animation(tmp_path):
    report = run_section("offline", tmp_path)
    assert "no-such-taichi-frac" in report["missing_message"]
    assert "TAICHI_FRAC_EXECUTABLE" in report["not_found_message"]


def test_cancelled_run_keeps_the_frames_done(tmp_path):
    report = run_section("cancel", tmp_path)
    assert report["cancel_exit"] == 130
    layer = report["cancel_layer"]
    assert layer.get("complete") is False, layer
    assert 3 <= layer["lastFrame"] < 2400, layer
