"""No data lost: a writer killed mid-run leaves a valid cache of the frames up to its last
checkpoint; an exception inside ``with CacheWriter(...)`` still writes what was done."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

sys.path.insert(0, str(Path(__file__).resolve().parent / "blender"))
import synthetic  # noqa: E402

from taichi_frac.io import CacheWriter, schema  # noqa: E402
from taichi_frac.io.cache import check_cache  # noqa: E402

WRITER = Path(__file__).resolve().parent / "blender" / "write_synthetic.py"


def test_sigkill_mid_run_keeps_frames_up_to_last_checkpoint(tmp_path):
    path = tmp_path / "killed.usdc"
    # Checkpoints after 10 and 20 written frames (frames 9 and 19); killed after frame 27.
    run = subprocess.run(
        [sys.executable, str(WRITER), str(path), "--checkpoint-every", "10", "--kill-after-frame", "27"],
        capture_output=True, text=True, timeout=120,
    )
    assert run.returncode == -signal.SIGKILL, run.stderr
    assert "killing after frame 27" in run.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["killed.usdc"]  # no temporary file left
    assert check_cache(path) == []
    stage = Usd.Stage.Open(str(path))
    data = stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY]
    assert data[schema.KEY_COMPLETE] is False and data[schema.KEY_LAST_FRAME] == 19
    assert stage.GetEndTimeCode() == 19
    slab = stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/slab")
    translate = slab.GetAttribute("xformOp:translate")
    assert translate.GetTimeSamples() == list(range(20))
    for frame in range(20):
        np.testing.assert_allclose(translate.Get(frame), synthetic.pose("slab", frame)[0], atol=1e-12)
    # Fragments born after the checkpoint (frame 20) are not in it.
    assert not stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/shard_a")


def test_exception_inside_with_block_writes_incomplete_cache(tmp_path):
    path = tmp_path / "aborted.usda"
    vertices, faces = synthetic.box_mesh((1, 1, 1))
    try:
        with CacheWriter(path, fps=24, checkpoint_every=1000) as writer:
            fid = writer.add_fragment("box", vertices, faces, np.zeros(12, bool), 0)
            for frame in range(5):
                writer.write_frame(frame, [fid], [[0, 0, frame]], [[1, 0, 0, 0]])
            raise RuntimeError("solver blew up")
    except RuntimeError:
        pass
    stage = Usd.Stage.Open(str(path))
    assert stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY][schema.KEY_COMPLETE] is False
    assert stage.GetEndTimeCode() == 4
    prim = stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/box")
    assert UsdGeom.Xformable(prim).GetTimeSamples() == [0, 1, 2, 3, 4]
