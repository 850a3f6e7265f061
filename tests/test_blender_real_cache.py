"""A real simulation's cache (the single ring breaking, then its pieces coming to rest and
sleeping) imported through the add-on in a real Blender: every object's world matrix and
visibility at chosen frames equal what pxr computes from the same file (an independent
reader), and every fragment the run made is an object."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from taichi_frac.io import schema
from taichi_frac.scenes import load_scene
from taichi_frac.simulation import Simulation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import build_addon  # noqa: E402
from test_blender_import import blender_python, run_in_blender  # noqa: E402

pytestmark = pytest.mark.blender
FRAMES = (0, 20, 30, 45, 60)


def test_real_cache_imports_as_pxr_reads_it(tmp_path):
    blender_python()  # skip/fail as the import test does when .venv-blender is missing
    cache = tmp_path / "ring.usdc"
    scene = load_scene(ROOT / "scenes" / "single_ring.toml", ["ring.fracture.crack_count=3"])
    summary = Simulation(scene, output=cache, frames=max(FRAMES)).run()
    assert summary.fractures >= 1 and summary.fragments >= 4  # pieces born mid-run

    addon_zip = build_addon.build(tmp_path / "dist")
    out = tmp_path / "dump.json"
    run = run_in_blender(ROOT / "tests" / "blender" / "dump_import.py", addon_zip, cache, out, *FRAMES,
                         tmp_path=tmp_path)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-4000:]
    dump = json.loads(out.read_text())

    stage = Usd.Stage.Open(str(cache))
    prims = [p for p in stage.GetPrimAtPath(schema.FRAGMENTS_SCOPE).GetChildren() if p.IsA(UsdGeom.Mesh)]
    assert dump["objects"] == len(prims) == 1 + summary.fragments + summary.fractures - 1  # root, pieces, parents
    held = 0
    for frame in FRAMES:
        objects = dump["frames"][str(frame)]
        assert sorted(objects) == sorted(str(p.GetPath()) for p in prims)
        for prim in prims:
            visible = UsdGeom.Imageable(prim).ComputeVisibility(Usd.TimeCode(frame)) != UsdGeom.Tokens.invisible
            assert objects[str(prim.GetPath())]["visible"] == visible, (prim.GetPath(), frame)
            if not visible:
                continue  # (Blender does not evaluate a hidden object's animation)
            xform = UsdGeom.Xformable(prim)
            # USD: row vectors (p' = p M); Blender: column vectors. Stage: metres, Z up.
            expected = np.asarray(xform.ComputeLocalToWorldTransform(Usd.TimeCode(frame))).T
            got = np.asarray(objects[str(prim.GetPath())]["matrix"])
            np.testing.assert_allclose(got, expected, atol=2e-6, err_msg=f"{prim.GetPath()} at frame {frame}")
            held += frame > xform.GetTimeSamples()[-1]  # a resting piece: its last sample lies before
    assert held > 0  # some frames are read from held poses (the pieces sleep by frame 60)
