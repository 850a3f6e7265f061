"""A sweep of 4 single-ring variants on a 2-worker LocalCluster: 4 complete caches and a CSV
with the right rows; a rerun does no work; a sweep killed midway and resumed gives the same
CSV as the uninterrupted one (cache hashes included: the runs are bit for bit the same
whichever worker, in whichever order, ran them); a variant run here in the test process on a
fresh World gives the same cache, byte for byte.

The variants are short (the ring starts 0.15 m up, falling at 4.4 m/s, 6 frames: it breaks
in the first frame). The ring keeps the scene's particle count, so the workers' World has
the field sizes of any `taichi-frac run scenes/single_ring.toml` and loads its kernels from
Taichi's offline cache."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pxr import Sdf

from taichi_frac.io import schema
from taichi_frac.scenes import BUILTIN_SCENE_DIR as SCENES
from taichi_frac.sweep import results, sweep
from taichi_frac.sweep.worker import file_sha256

REPO = Path(__file__).resolve().parents[1]
SCENE = SCENES / "single_ring.toml"
VARY = ["ring.fracture.crack_count=1,3", "ring.fracture.seed=0:2"]
FIXED = ["ring.position=[0,0,0.15]", "ring.linear_velocity=[0,0,-4.4]"]
FRAMES = 6

pytestmark = pytest.mark.slow


def _rows(path: Path, drop_timing: bool = True) -> list[dict]:
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    if drop_timing:
        for row in rows:
            for name in results.TIMING_COLUMNS:
                row.pop(name)
    return rows


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "uninterrupted"
    result = sweep(SCENE, VARY, out, overrides=FIXED, frames=FRAMES, workers=2, sheet=False, progress=False)
    return out, result


def test_sweep_on_two_workers_writes_every_variant(finished):
    out, result = finished
    assert (result.ran, result.skipped, result.failed, result.interrupted) == (4, 0, 0, False)
    rows = _rows(result.csv_path, drop_timing=False)
    expected = [(c, s) for c in ("1", "3") for s in ("0", "1")]
    assert [(r["ring.fracture.crack_count"], r["ring.fracture.seed"]) for r in rows] == expected
    workers = set()
    for row, record in zip(rows, result.records):
        folder = out / row["id"]
        stats = results.read_done(folder, row["id"], record["scene_sha256"])
        assert stats is not None and row["status"] == "done"
        # The cache is complete (its layer data says so) and is the file the row describes.
        data = Sdf.Layer.OpenAsAnonymous(str(folder / "cache.usdc")).customLayerData[schema.LAYER_DATA_KEY]
        assert data[schema.KEY_COMPLETE] and data[schema.KEY_LAST_FRAME] == FRAMES
        assert row["cache_sha256"] == file_sha256(folder / "cache.usdc")
        assert int(row["fragments"]) == stats["summary"]["fragments"] == len(stats["fragment_volumes"])
        assert int(row["fracture_events"]) >= 1 and (folder / "fragment_sizes.png").stat().st_size > 1000
        # Mass: the pieces and what fracture dropped add up to the ring (to round-off).
        assert abs(float(row["mass_conserved"]) - 1.0) < 1e-9
        assert float(row["volume_min_m3"]) <= float(row["volume_median_m3"]) <= float(row["volume_max_m3"])
        workers.add(stats["worker"])
    assert len(workers) == 2
    # More cracks, more pieces (the paper's control): crack_count 3 gives more than 1 does.
    counts = [int(r["fragments"]) for r in rows]
    assert min(counts[2:]) > max(counts[:2]) >= 2
    sweep_json = (out / "sweep.json").read_text()
    assert all(r["id"] in sweep_json for r in rows)


def test_rerun_does_no_work(finished):
    out, result = finished
    before = result.csv_path.read_text()
    mtimes = {p: p.stat().st_mtime_ns for p in out.glob("*/cache.usdc")}
    again = sweep(SCENE, VARY, out, overrides=FIXED, frames=FRAMES, workers=2, sheet=False, progress=False)
    assert (again.ran, again.skipped) == (0, 4)
    assert again.csv_path.read_text() == before
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/cache.usdc")} == mtimes


def test_a_variant_runs_bit_for_bit_the_same_in_this_process(finished, tmp_path):
    """The worker ran it on a World and a model that had run other variants; here on fresh
    ones, as `taichi-frac run` would (this fails when the workers' BLAS is pinned to one
    thread, as Dask's nanny does by default: NumPy's products round differently)."""
    from taichi_frac.scenes import load_scene
    from taichi_frac.simulation import Simulation

    out, result = finished
    record = result.records[3]
    scene = load_scene(SCENE, FIXED + [f"{k}={v}" for k, v in record["settings"].items()])
    Simulation(scene, output=tmp_path / "again.usdc", frames=FRAMES).run()
    assert file_sha256(tmp_path / "again.usdc") == record["cache_sha256"]


def test_killed_midway_then_resumed_gives_the_same_csv(finished, tmp_path):
    out, result = finished
    resumed = tmp_path / "resumed"
    command = [sys.executable, "-m", "taichi_frac", "sweep", str(SCENE), "-o", str(resumed), "--frames", str(FRAMES),
               "--workers", "2", "--no-sheet", "-q"]
    for item in VARY:
        command += ["--vary", item]
    for item in FIXED:
        command += ["--set", item]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    process = subprocess.Popen(command, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    deadline = time.monotonic() + 600
    try:
        while not list(resumed.glob("*/stats.json")):
            assert process.poll() is None, process.stderr.read().decode()[-3000:]
            assert time.monotonic() < deadline, "no variant finished in 10 minutes"
            time.sleep(0.2)
    finally:
        # The whole process group: the client, the scheduler in it and the worker processes.
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    finished_before = len(list(resumed.glob("*/stats.json")))
    assert 1 <= finished_before < 4
    again = sweep(SCENE, VARY, resumed, overrides=FIXED, frames=FRAMES, workers=2, sheet=False, progress=False)
    assert again.skipped == finished_before and again.ran == 4 - finished_before and again.failed == 0
    assert _rows(again.csv_path) == _rows(result.csv_path)


def test_a_failing_variant_is_reported_and_the_others_go_on(tmp_path):
    """A torus whose tube is wider than its ring loads (the scene's keys and types are fine)
    but fails on the worker when it is meshed."""
    good, bad = '"torus:major=0.1,minor=0.025"', '"torus:major=0.1,minor=0.2"'
    result = sweep(SCENE, [f"ring.primitive={bad},{good}"], tmp_path, overrides=FIXED, frames=FRAMES, workers=1,
                   sheet=False, progress=False)
    assert (result.ran, result.failed) == (2, 1)
    failed, done = result.records
    assert failed["status"] == "failed" and "minor_radius" in failed["error"]
    assert "minor_radius" in (tmp_path / failed["id"] / results.ERROR_NAME).read_text()
    assert done["status"] == "done" and done["fragments"] >= 2
    rows = _rows(result.csv_path)
    assert [r["status"] for r in rows] == ["failed", "done"] and "minor_radius" in rows[0]["error"]


@pytest.mark.blender
def test_contact_sheet_shows_every_variant(finished, tmp_path):
    """The last frames rendered by Blender, laid out in sweep order under their labels: the
    sheet is a grid of the tiles (checked pixel for pixel against each thumbnail)."""
    from PIL import Image

    from support.blender import blender_python
    from taichi_frac.sweep.sheet import contact_sheet

    python = blender_python()
    out, result = finished
    sheet = contact_sheet(result, resolution="96x72", samples=2, columns=2, blender_python=python, log=lambda m: None)
    tiles = [out / r["id"] / results.THUMBNAIL_NAME for r in result.records]
    assert all(t.exists() for t in tiles)
    with Image.open(sheet) as image:
        assert image.width == 2 * 96 and image.height > 2 * 72
        band = (image.height - 2 * 72) // 2
        for k, tile in enumerate(tiles):
            x, y = (k % 2) * 96, (k // 2) * (72 + band)
            with Image.open(tile) as t:
                assert list(image.crop((x, y, x + 96, y + 72)).getdata()) == list(t.convert("RGB").getdata())


def test_sweep_on_an_existing_scheduler(tmp_path):
    """--scheduler: the variants go to a cluster the sweep did not start (left running).
    Both variants fail when their ring is meshed, so no kernel is compiled: this checks the
    path (submission, results, errors), the other tests the physics."""
    import logging

    from dask.distributed import LocalCluster

    bad = ['"torus:major=0.1,minor=0.2"', '"torus:major=0.1,minor=0.3"']
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.ERROR) as cluster:
        result = sweep(SCENE, [f"ring.primitive={','.join(bad)}"], tmp_path, overrides=FIXED, frames=FRAMES,
                       scheduler=cluster.scheduler_address, sheet=False, progress=False)
        assert cluster.scheduler.workers  # still running
    assert (result.ran, result.failed) == (2, 2)
    assert all("minor_radius" in r["error"] for r in result.records)
