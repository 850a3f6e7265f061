"""The add-on's bpy-free parts in plain Python: retime.py (frame range, retiming, pieces seen
on no frame) against USD's own evaluation of the same cache and hand-worked cases, and the
reader's errors and lineage. The Blender side of the same is in test_blender_addon_features.py."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "blender"))
import synthetic  # noqa: E402
import variants  # noqa: E402
import write_synthetic  # noqa: E402
from addon_loader import addon_module  # noqa: E402

retime = addon_module("retime")
reader = addon_module("reader")


@pytest.fixture(scope="module")
def cache_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("retime") / "synthetic.usdc"
    write_synthetic.write(path)
    return path


def test_clipped_keys_read_as_usd_does(cache_path):
    """Keys clipped to frames 13.3-39.7 (the ends interpolated), evaluated the way Blender
    does (linear per component, quaternion normalised), equal USD's world pose of the same
    prim at the ends, at whole frames (tight) and at quarter frames (loose: nlerp against USD's
    slerp); sliver_2 rests from 42, so its pose past its last sample is held."""
    cache = reader.read_cache(cache_path)
    stage = Usd.Stage.Open(str(cache_path))
    first, last = 13.3, 39.7
    exact = np.concatenate([[first, last], np.arange(14.0, 40.0)])
    checked = 0
    for fragment in cache.fragments:
        frames, positions, orientations = retime.clip_poses(fragment.sample_frames, fragment.positions,
                                                            fragment.orientations, first, last)
        assert frames[0] == first and frames[-1] == last or len(frames) == 1
        xform = UsdGeom.Xformable(stage.GetPrimAtPath(fragment.prim_path))
        for t in np.concatenate([exact, np.arange(14.25, 39.5, 0.5)]):
            if t < fragment.sample_frames[0]:
                continue  # (not born yet: hidden)
            k = np.clip(np.searchsorted(frames, t, side="right") - 1, 0, len(frames) - 1)
            k1 = min(k + 1, len(frames) - 1)
            s = 0.0 if k1 == k else (t - frames[k]) / (frames[k1] - frames[k])
            p = positions[k] + s * (positions[k1] - positions[k])
            q = orientations[k] + s * (orientations[k1] - orientations[k])
            expected = np.asarray(xform.ComputeLocalToWorldTransform(Usd.TimeCode(t))).T
            got = synthetic.world_matrix(p, q / np.linalg.norm(q))
            # nlerp vs slerp half-way between frames: shard_b turns 0.375 rad a frame
            tolerance = 1e-6 if t in exact else 2e-3
            np.testing.assert_allclose(got, expected, atol=tolerance, err_msg=f"{fragment.name} at {t}")
            checked += 1
    assert checked > 150


def test_clipped_visibility_holds_the_value_at_the_first_frame():
    frames = np.array([0.0, 20.0, 35.0])
    visible = np.array([False, True, False])
    f, v = retime.clip_visibility(frames, visible, 25.0, 40.0)
    assert f.tolist() == [25.0, 35.0] and v.tolist() == [True, False]
    f, v = retime.clip_visibility(frames, visible, 0.0, 19.0)
    assert f.tolist() == [0.0] and v.tolist() == [False]


@pytest.mark.parametrize("keys, shown, lo, hi, expected", [
    ([22.48, 22.96], [True, False], 0, 100, False),   # alive between two frames: never drawn
    ([22.96, 23.44], [True, False], 0, 100, True),    # covers frame 23
    ([23.0, 23.0 + 1e-3], [True, False], 0, 100, True),  # a key exactly on a frame shows it
    ([0.0, 30.0, 30.0], [False, True, False], 0, 100, False),  # born and broken at 30
    ([0.0, 50.0], [False, True], 0, 49, False),       # born after the range
    ([0.0, 50.0], [False, True], 0, 50, True),
])
def test_shown_at_some_frame(keys, shown, lo, hi, expected):
    assert retime.shown_at_some_frame(np.array(keys), np.array(shown), lo, hi) is expected


def test_timing_keeps_seconds_and_clips_an_incomplete_cache(cache_path):
    cache = reader.read_cache(cache_path)  # 24 fps, frames 0-48
    timing = retime.make_timing(cache, 30.0, retime.ImportOptions(frame_offset=5.0))
    # frame 24 at 24 fps is 1 s: frame 5 + 30 in a 30 fps scene
    assert timing.to_scene(24) == pytest.approx(35.0) and timing.scene_range() == (5, 65)
    cache.complete, cache.last_frame = False, 20
    timing = retime.make_timing(cache, 24.0, retime.ImportOptions(frame_first=10, frame_last=40))
    assert (timing.first, timing.last) == (10.0, 20.0)
    with pytest.raises(ValueError, match="outside the cache"):
        retime.make_timing(cache, 24.0, retime.ImportOptions(frame_first=30))
    with pytest.raises(ValueError, match="first must be <= last"):
        retime.ImportOptions(frame_first=10, frame_last=5)
    with pytest.raises(ValueError, match="missing"):
        retime.ImportOptions(missing="DELETE")


def test_lineage_generation_and_source(cache_path):
    by_name = {f.name: f for f in reader.read_cache(cache_path).fragments}
    for name, (_, _, parent, _) in synthetic.FRAGMENTS.items():
        generation, node = 0, name
        while synthetic.FRAGMENTS[node][2] is not None:
            node, generation = synthetic.FRAGMENTS[node][2], generation + 1
        assert by_name[name].generation == generation
        assert by_name[name].source == by_name[node].prim_path == by_name["slab"].prim_path


def test_reader_errors_name_the_file(tmp_path, cache_path):
    corrupt = tmp_path / "corrupt.usdc"
    corrupt.write_bytes(b"PXR-USDC" + bytes(range(200)))
    truncated = tmp_path / "truncated.usdc"
    truncated.write_bytes(cache_path.read_bytes()[:4000])
    for path, message in ((tmp_path / "none.usdc", "no such file"), (corrupt, "not a readable USD file"),
                          (truncated, "not a readable USD file"), (tmp_path, "is a folder")):
        with pytest.raises(reader.CacheError, match=message) as info:
            reader.read_cache(path)
        assert str(path) in str(info.value) and "Error in" not in str(info.value)  # (no C++ location)
    foreign = tmp_path / "foreign.usda"
    variants.write_foreign_usd(foreign)
    assert reader.layer_info(foreign) is None
    assert reader.layer_info(cache_path)["complete"] is True


def test_preview_surface_inputs_read_as_authored(tmp_path):
    """Only the inputs a shader authors are read (None elsewhere: Blender keeps its default)."""
    path = tmp_path / "glass.usda"
    variants.write(path, [variants.Piece("pane", 0)], 24.0, 2)
    variants.set_preview_inputs(path, "pane/outer", opacity=0.1, opacityThreshold=0.0, ior=1.52)
    variants.clear_preview_inputs(path, "pane/inner", "opacity", "opacityThreshold", "ior")
    materials = {m.name: m for m in reader.read_cache(path).materials}
    outer = materials["pane_outer"]
    assert (outer.opacity, outer.opacity_threshold, outer.ior) == pytest.approx((0.1, 0.0, 1.52))
    assert outer.base_color == pytest.approx((0.80, 0.78, 0.72)) and outer.roughness == pytest.approx(0.30)
    inner = materials["pane_inner"]
    assert (inner.opacity, inner.opacity_threshold, inner.ior) == (None, None, None)


def test_material_names_follow_their_prim_paths():
    name = reader._material_name
    assert name("/Fracture/Materials/outer") == "outer"
    assert name("/Fracture/Materials/ring_0/inner") == "ring_0_inner"
    assert name("/Looks/glass") == "glass"
