"""``taichi-frac render`` renders PNGs headless through bpy (tiny and few samples: a smoke test
of the command, the camera framing and visibility; the look is checked by eye, see README)."""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from taichi_frac.cli import main

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
import write_synthetic  # noqa: E402
from support.blender import blender_python  # noqa: E402

pytestmark = pytest.mark.blender


def png_size(path):
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", header[16:24])


def test_render_frames_to_png(tmp_path):
    blender_python()  # skip/fail as the import test does when .venv-blender is missing
    cache = tmp_path / "synthetic.usdc"
    write_synthetic.write(cache)
    out = tmp_path / "renders"
    code = main(["render", str(cache), "--frames", "0,20", "-o", str(out), "--resolution", "64x48", "--samples", "2"])
    assert code == 0
    frames = sorted(p.name for p in out.iterdir())
    assert frames == ["frame_0000.png", "frame_0020.png"]
    for name in frames:
        assert png_size(out / name) == (64, 48)
    # One slab at frame 0, two shards at 20: the pictures differ.
    assert (out / frames[0]).read_bytes() != (out / frames[1]).read_bytes()


def test_render_reports_missing_blender(tmp_path, capsys):
    cache = tmp_path / "c.usdc"
    cache.write_bytes(b"")
    code = main(["render", str(cache), "--blender-python", str(tmp_path / "nope" / "python")])
    assert code == 2 and "no Blender Python" in capsys.readouterr().err


def test_render_look_at_frames_only_matching_objects(tmp_path, capfd):
    from matplotlib.image import imread

    blender_python()
    cache = tmp_path / "synthetic.usdc"
    write_synthetic.write(cache)
    args = ["--frames", "20", "--resolution", "64x48", "--samples", "2"]

    def render(folder, *look_at):
        assert main(["render", str(cache), "-o", str(tmp_path / folder)] + args + list(look_at)) == 0
        return imread(tmp_path / folder / "frame_0020.png")[..., :3]

    # A glob that matches nothing is an error that names some objects.
    assert main(["render", str(cache), "-o", str(tmp_path / "none"), "--look-at", "no_such_*"] + args) == 2
    assert "matches no object" in capfd.readouterr().err
    # '*' frames what no --look-at frames (the pictures differ by sampling noise only);
    # one of the two shards alone moves the camera in (they differ by far more).
    wide, same, near = render("all"), render("star", "--look-at", "*"), render("one", "--look-at", "shard_a")
    noise = np.abs(wide - same).mean()
    assert np.abs(wide - near).mean() > 3 * noise + 1e-3


def test_default_framing_leaves_out_a_far_shard(tmp_path):
    """Nine 10 cm cubes within half a metre and one shard 30 m away: the framed box holds the
    cluster's centre and stays within a few metres of it (the union of every shard would
    reach 30 m); a hidden (unborn) piece is not framed."""
    import json

    from taichi_frac.io import CacheWriter
    from support.blender import run_in_blender

    blender_python()
    cache = tmp_path / "scatter.usdc"
    vertices, faces = write_synthetic.synthetic.box_mesh((0.05, 0.05, 0.05))
    inner = np.zeros(len(faces), bool)
    centres = [(0.4 * i, 0.4 * j, 0.05) for i in (-1, 0, 1) for j in (-1, 0, 1)] + [(30.0, 0.0, 0.05)]
    with CacheWriter(cache, fps=24) as writer:
        ids = [writer.add_fragment(f"piece_{k}", vertices, faces, inner, 0) for k in range(len(centres))]
        unborn = writer.add_fragment("unborn", vertices, faces, inner, 5)
        writer.write_frame(0, ids + [unborn], np.array(centres + [(-50.0, 0.0, 0.05)]),
                           np.tile([1.0, 0, 0, 0], (len(ids) + 1, 1)))
    result = run_in_blender(ROOT / "tests" / "blender" / "check_framing.py", cache, "0", tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    box = json.loads(next(line for line in result.stdout.splitlines() if line.startswith("BOX "))[4:])
    low, high = np.array(box["low"]), np.array(box["high"])
    assert np.all(low <= [-0.3, -0.3, 0.0]) and np.all(high >= [0.3, 0.3, 0.1])  # the cluster
    assert high[0] < 2.0 and low[0] > -2.0  # neither the far shard nor the unborn piece
