"""Piece surfaces cut in worker processes (taichi_frac/surfaces/pool.py), the recorder that
writes them in order once they are done (io/recorder.py), and a second run in one process
reusing the first one's World (scene_setup.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from concurrent.futures import Future
from pathlib import Path

import numpy as np
import pytest

from taichi_frac.io.cache import cache_digest
from taichi_frac.scenes import load_scene
from taichi_frac.simulation import Simulation

SCENES = Path(__file__).resolve().parents[1] / "scenes"


def test_workers_write_the_cache_the_process_writes_alone(tmp_path):
    """The ring cracked three ways, pieces breaking again: the same cache, prim for prim and
    sample for sample, with the surfaces cut here or in two worker processes."""
    caches = {}
    for workers in (0, 2):
        scene = load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_count=3"])
        path = tmp_path / f"ring_{workers}.usdc"
        summary = Simulation(scene, output=path, frames=40, surface_workers=workers).run()
        assert summary.fragments >= 3 and summary.surface_workers == workers
        caches[workers] = cache_digest(path)
    assert caches[0] == caches[2]


class _Writer:
    """A cache writer that records its calls."""

    def __init__(self):
        self.calls, self.frames_since_write, self.seconds_since_write = [], 0, 0.0

    def add_fragment(self, name, *args, **kwargs):
        self.calls.append(("add", name))
        return len([c for c in self.calls if c[0] == "add"]) - 1

    def write_frame(self, frame, ids, positions, orientations):
        self.calls.append(("frame", frame, tuple(ids)))

    def end_fragment(self, fid, frame):
        self.calls.append(("end", fid, frame))

    def close(self, complete):
        self.calls.append(("close", complete))


def test_the_recorder_writes_in_order_once_a_surface_is_done():
    from taichi_frac.io.recorder import CacheRecorder
    from taichi_frac.surfaces import BodySurface

    surface = BodySurface(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.zeros(1, bool))
    recorder = CacheRecorder("unused.usdc", fps=50, checkpoint_every=0, checkpoint_seconds=0)
    recorder.writer = writer = _Writer()
    pending = Future()
    recorder._log.append((pending, recorder._add, (7, "late", 0, None, None, None, 0.0)))
    state = {"position": np.zeros((1, 3)), "orientation": np.array([[1.0, 0, 0, 0]])}
    recorder.write_frame(0, [7], state)
    recorder.write_frame(1, [7], state)
    assert writer.calls == []  # (the frames wait for the body's surface)
    pending.set_result(surface)
    recorder.write_frame(2, [7], state)
    assert writer.calls == [("add", "late"), ("frame", 0, (0,)), ("frame", 1, (0,)), ("frame", 2, (0,))]
    recorder.close(complete=True)
    assert writer.calls[-1] == ("close", True)


def test_the_wait_at_the_end_tells_how_many_splits_are_left():
    """close() waiting for surfaces still being cut tells on_wait how many of those it found
    unfinished are left, from all of them down to none, as they finish (out of order here),
    and still writes in order."""
    import threading

    from taichi_frac.io.recorder import CacheRecorder
    from taichi_frac.surfaces import BodySurface

    surface = BodySurface(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.zeros(1, bool))
    recorder = CacheRecorder("unused.usdc", fps=50, checkpoint_every=0, checkpoint_seconds=0)
    recorder.writer = writer = _Writer()
    futures = [Future() for _ in range(3)]
    for k, future in enumerate(futures):
        recorder._log.append((future, recorder._add, (k, f"piece{k}", 0, None, None, None, 0.0)))
    told = []

    def finish():
        for k in (2, 0, 1):
            time.sleep(0.05)
            futures[k].set_result(surface)

    threading.Thread(target=finish).start()
    recorder.close(complete=True, on_wait=lambda left, splits: told.append((left, splits)))
    assert told[0] == (3, 3) and told[-1] == (0, 3)
    assert all(splits == 3 for _, splits in told) and [left for left, _ in told] == sorted(
        {left for left, _ in told}, reverse=True)
    assert writer.calls == [("add", "piece0"), ("add", "piece1"), ("add", "piece2"), ("close", True)]
    told.clear()
    recorder.close(complete=True, on_wait=lambda left, splits: told.append((left, splits)))
    assert told == []  # (nothing to wait for: nothing told)


def test_a_worker_error_reaches_the_caller_with_its_traceback():
    from taichi_frac.surfaces.pool import SurfaceWorkerError, SurfaceWorkers

    workers = SurfaceWorkers(1)
    try:
        future = workers._workers[0].submit(0, "cut", None)  # (no request: the stage fails on it)
        with pytest.raises(SurfaceWorkerError, match="Traceback"):
            future.result(timeout=120)
    finally:
        workers.close()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_a_killed_run_leaves_no_surface_worker_behind(tmp_path):
    script = textwrap.dedent("""
        import sys, time
        from taichi_frac.surfaces.pool import SurfaceWorkers
        workers = SurfaceWorkers(2)
        print("pids", " ".join(str(w.process.pid) for w in workers._workers), flush=True)
        time.sleep(600)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    line = next(line for line in parent.stdout if line.startswith("pids"))  # (after Taichi's banner)
    pids = [int(p) for p in line.split()[1:]]
    assert len(pids) == 2
    parent.send_signal(signal.SIGKILL)
    parent.wait(timeout=30)
    deadline = time.monotonic() + 30
    alive = pids
    while alive and time.monotonic() < deadline:
        alive = [pid for pid in alive if _running(pid)]
        time.sleep(0.1)
    assert not alive, f"workers {alive} outlived their parent"


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"  # (a zombie has ended; only its exit status is left)


def test_a_second_run_in_the_process_takes_the_first_runs_world(tmp_path):
    scene = load_scene(SCENES / "single_ring.toml")
    first = Simulation(scene, output=False, frames=2)
    held = Simulation(scene, output=False, frames=2)  # (built while the first is not run: its own World)
    assert held.world is not first.world
    first.run()
    held.run()
    again = Simulation(scene, output=False, frames=2)
    assert again.world is held.world  # (the last World built, free once its run ended)
    again.run()


def test_world_sizes_are_rounded_up_to_powers_of_two():
    from taichi_frac.scene_setup import _power_of_two, allocated_capacity, world_capacity

    assert [_power_of_two(n) for n in (1, 2, 3, 64, 65, 1000, 1024, 1025)] == [1, 2, 4, 64, 128, 1024, 1024, 2048]
    # The single ring and the 13 rings get one World size (their kernels compiled once).
    from taichi_frac.scene_setup import prepare_objects

    sizes = []
    for name in ("single_ring", "thirteen_rings"):
        scene = load_scene(SCENES / f"{name}.toml")
        sizes.append(allocated_capacity(world_capacity(scene, prepare_objects(scene)[0])))
    assert sizes[0] == sizes[1] and sizes[0].max_boundary_particles == 65536


def test_taichi_error_messages_still_name_the_file_and_line():
    """Taichi's front end as this package runs it (``runtime._plain_source_positions``): an
    error in a kernel names its file, line and source line."""
    import taichi as ti

    field = ti.field(ti.f32, shape=1)

    @ti.kernel
    def broken():
        field[0] = undefined_name  # noqa: F821

    with pytest.raises(Exception) as caught:
        broken()
    message = str(caught.value)
    assert os.path.basename(__file__) in message and "undefined_name" in message, message


def test_a_bad_worker_count_is_one_clear_error(capsys):
    from taichi_frac.cli import main

    assert main(["run", "single_ring", "--no-output", "--surface-workers", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--surface-workers -1" in err[0] and "0" in err[0], err


def test_a_repeated_run_in_the_process_takes_its_cuts_and_writes_the_same_cache(tmp_path, monkeypatch):
    """The ring cracked three ways, run twice in one process cutting in it: the second run
    meets the same splits and cuts none of them again, and its cache is the first's, sample
    for sample."""
    from taichi_frac.surfaces import cut as cut_module

    scene = load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_count=3", "ring.fracture.seed=5"])
    first = tmp_path / "first.usdc"
    Simulation(scene, output=first, frames=40, surface_workers=0).run()
    real, calls = cut_module.cut_render_solid, []
    monkeypatch.setattr(cut_module, "cut_render_solid", lambda *a, **k: calls.append(1) or real(*a, **k))
    second = tmp_path / "second.usdc"
    summary = Simulation(scene, output=second, frames=40, surface_workers=0).run()
    assert summary.fragments >= 3 and calls == []
    assert cache_digest(first) == cache_digest(second)
    # Another crack count: other splits, cut afresh.
    Simulation(load_scene(SCENES / "single_ring.toml", ["ring.fracture.crack_count=2"]), output=tmp_path / "o.usdc",
               frames=40, surface_workers=0).run()
    assert calls


def test_a_second_run_takes_the_idle_workers_and_writes_the_same_cache(tmp_path):
    """Workers left idle by one run serve the next run in the process (its splits from their
    memos), started afresh for it (body ids of its own): the ring cracked three ways, then the
    ring cracked once (other bodies, other splits), then three ways again, all equal to the
    caches cut in this process."""
    from taichi_frac.surfaces import pool

    digests, pids = {}, []
    for label, count, workers in (("3", 3, 0), ("1", 1, 0), ("3w", 3, 2), ("1w", 1, 2), ("3w again", 3, 2)):
        scene = load_scene(SCENES / "single_ring.toml", [f"ring.fracture.crack_count={count}"])
        path = tmp_path / f"ring_{label.replace(' ', '_')}.usdc"
        sim = Simulation(scene, output=path, frames=40, surface_workers=workers)
        if workers:
            pids.append(sorted(w.process.pid for w in sim.surfaces._workers))
        sim.run()
        digests[label] = cache_digest(path)
    assert digests["3w"] == digests["3"] == digests["3w again"] and digests["1w"] == digests["1"]
    assert digests["1"] != digests["3"]
    assert pids[0] == pids[1] == pids[2]  # (the same processes, idle between the runs)
    pool.close_idle_workers()
    assert not pool._IDLE


def test_splits_cut_in_other_workers_than_the_ones_holding_their_solids_give_the_same_cache(tmp_path, monkeypatch):
    """Splits go to a worker that does not hold their parent's render solid while there is
    one: the ring's first split to the one that did not build the ring's solid (sent the
    arrays it is built from), a piece's split to the one that did not cut the piece (which
    cuts again the split that made it first, and so holds its siblings too). The ring thrown
    down, cracked twice, its pieces breaking again (five splits), writes the cache the
    process writes alone, sample for sample."""
    from taichi_frac.surfaces import pool, stage

    ran = []
    real_extra, real_start = pool.SurfaceWorkers._extra, pool.SurfaceWorkers._start

    def elsewhere(self, job, worker):
        key = job.needs if job.needs is not None else job.payload.parent_key if job.kind == "cut" else None
        if key is not None and key in worker.held and any(key not in w.held for w in self._workers):
            return None  # (not where the solid is, while a worker does not hold it)
        return real_extra(self, job, worker)

    def start(self, job, worker):
        replayed = job.kind == "cut" and job.needs is not None and job.needs not in worker.held
        ran.append((job.kind, job.needs is not None, replayed))
        return real_start(self, job, worker)

    scene = load_scene(SCENES / "single_ring.toml", [
        "ring.fracture.crack_count=2", "ring.fracture.refracture=true", "ring.material.tensile_strength=4.5e6",
        "ring.fracture.seed=5", "ring.linear_velocity=[0,0,-4]"])
    alone = tmp_path / "alone.usdc"
    Simulation(scene, output=alone, frames=40, surface_workers=0).run()
    monkeypatch.setattr(stage, "_CUTS", {})  # (cut again, not taken from the run above)
    monkeypatch.setattr(stage, "_ROOT_SURFACES", {})
    monkeypatch.setattr(pool, "_MADE_BY", {})
    monkeypatch.setattr(pool.SurfaceWorkers, "_extra", elsewhere)
    monkeypatch.setattr(pool.SurfaceWorkers, "_start", start)
    spread = tmp_path / "spread.usdc"
    sim = Simulation(scene, output=spread, frames=40, surface_workers=2)
    sim.run()
    cuts = [(piece, replayed) for kind, piece, replayed in ran if kind == "cut"]
    assert sim.fracture_events >= 3 and cuts[0] == (False, False) and len(cuts) == sim.fracture_events
    assert sum(replayed for _, replayed in cuts) >= 2  # (pieces' splits where the pieces were not)
    assert cache_digest(alone) == cache_digest(spread)


def test_a_scene_objects_render_solid_built_again_from_its_arrays_cuts_the_same():
    """``solid.PortableSolid``: two solids built from one scene object's arrays, other solids made in
    between (the boolean library numbers every solid it makes), cut by the same slab into
    the same bytes."""
    import manifold3d as m3
    import trimesh

    from taichi_frac.surfaces.solid import render_solid_from_surface

    ring = trimesh.creation.torus(0.1, 0.025, major_sections=48, minor_sections=16)
    first = render_solid_from_surface(ring, np.zeros(3), 0.01)
    made = []
    for others in (0, 17):
        made += [m3.Manifold.sphere(0.2, 12) for _ in range(others)]
        solid = first.solid if others == 0 else first.portable.rebuilt().solid
        slab = m3.Manifold.cube((0.5, 0.5, 1e-4), center=True).rotate((20.0, 30.0, 0.0))
        pieces = (solid - slab).decompose()
        assert len(pieces) == 2
        made.append(b"".join(np.asarray(p.to_mesh64().vert_properties).tobytes()
                             + np.asarray(p.to_mesh64().tri_verts).tobytes() for p in pieces))
    assert made[0] == made[-1]
    assert abs(first.solid.volume() - ring.volume) <= 1e-9 * ring.volume


def test_a_split_that_holds_up_waiting_splits_goes_before_a_larger_one():
    """The queue's order: scene objects' starts first, then each split by its own tets plus
    those of the splits already asked for that wait for its pieces (through their pieces
    too), here 3,000 + 2,500 + 1,000 against 5,000 (the sums counted by hand)."""
    from taichi_frac.surfaces import pool
    from taichi_frac.surfaces.front import Job

    workers = pool.SurfaceWorkers(1)
    try:
        def job(kind, size, makes):
            return Job(kind, None, size, f"{kind}{size}", None, None, makes=makes)

        large, chain, start = job("cut", 5000, ["a1", "a2"]), job("cut", 3000, ["b1"]), job("add_body", 10, ["r"])
        workers._waiting = {"b1": [(2500, ["c1", "c2"])], "c2": [(1000, ["d1"])], "zz": [(9999, [])]}
        assert workers.waiting_work(chain.makes) == 3500 and workers.waiting_work(large.makes) == 0
        order = sorted([(0, large), (1, chain), (2, start)], key=workers._order)
        assert [entry[1] for entry in order] == [start, chain, large]
        workers._waiting = {"b1": [(1500, [])]}  # (4,500 in all: the larger split first again)
        assert [e[1] for e in sorted([(0, large), (1, chain)], key=workers._order)] == [large, chain]
    finally:
        workers.close(cancel=True)


def test_a_run_keeps_blas_to_one_thread_and_gives_the_threads_back():
    """During a run and its set-up every BLAS library loaded runs one thread (see
    ``taichi_frac.blas``: a threaded BLAS waits for its helper thread at each small solve
    while the surface workers keep the cores busy); between and after them, what the process
    had before."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return {lib["filepath"]: lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}

    from taichi_frac.scene_setup import prepare_object

    def prepare(obj, **options):  # (the set-up's preparing, as the run's own)
        during.append(blas_threads())
        return prepare_object(obj, **options)

    scene = load_scene(SCENES / "single_ring.toml")
    with threadpool_limits(limits=2, user_api="blas"):  # (two where a library can, whatever the cores)
        before, during = blas_threads(), []
        sim = Simulation(scene, output=False, frames=2, prepare=prepare)
        between = blas_threads()
        sim.progress = lambda *_: during.append(blas_threads())
        sim.run()
        after = blas_threads()
    assert 2 in before.values()  # (numpy's and scipy's OpenBLAS; a single-threaded build stays at 1)
    assert len(during) == 3 and all(set(seen) >= set(before) and set(seen.values()) == {1} for seen in during)
    assert between == before and after == before


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2
                    or not os.path.isdir("/proc/self/task"),
                    reason="needs a platform that sets a process's CPUs and lists its threads, and two CPUs")
def test_a_workers_booleans_run_on_the_threads_it_is_given_and_cut_the_same():
    """``worker.start_boolean_threads(1)`` before the first boolean: the boolean library's
    pool starts with no thread of its own (the process has one thread fewer than one whose
    pool took the default, a thread per CPU), the process may run on every CPU again after
    it, and the difference of two spheres is the same to the byte. A worker asks for it where
    the workers number twice the cores or more."""
    code = textwrap.dedent("""
        import hashlib, os, sys
        import manifold3d as m3
        import numpy as np
        from taichi_frac.surfaces.worker import start_boolean_threads
        cpus = os.sched_getaffinity(0)
        if sys.argv[1] == "1":
            start_boolean_threads(1)
        left = m3.Manifold.sphere(1.0, 128)
        mesh = (left - left.translate((0.5, 0.3, 0.1))).to_mesh64()
        digest = hashlib.sha256(np.asarray(mesh.vert_properties).tobytes() + np.asarray(mesh.tri_verts).tobytes())
        print(len(os.listdir("/proc/self/task")), os.sched_getaffinity(0) == cpus, digest.hexdigest())
    """)
    runs = {}
    for threads in ("0", "1"):
        out = subprocess.run([sys.executable, "-c", code, threads], capture_output=True, text=True, check=True)
        count, restored, digest = out.stdout.split()[-3:]
        runs[threads] = (int(count), restored, digest)
    assert runs["1"][0] == runs["0"][0] - 1
    assert runs["1"][1] == runs["0"][1] == "True"
    assert runs["1"][2] == runs["0"][2]
    from taichi_frac.surfaces.worker import boolean_threads

    cores = len(os.sched_getaffinity(0))
    assert boolean_threads(2 * cores) == 1 and boolean_threads(2 * cores - 1) == 0


def test_a_worker_holding_a_queued_splits_solid_takes_that_split_before_one_any_worker_could_take():
    """The one idle worker holds the piece a queued split cuts: that split starts there, and
    the larger split ahead of it in the queue (a scene object's, which any worker can cut)
    waits for a worker holding no queued split's solid. Where the bound split cannot start
    (another worker's memo holds its result: it waits to go there), the other takes the idle
    worker after all."""
    from taichi_frac.surfaces import pool
    from taichi_frac.surfaces.front import Job

    workers = pool.SurfaceWorkers(2)
    try:
        first, second = workers._workers
        started = []

        def start(job, worker):
            started.append((job.key, worker))
            workers._idle.remove(worker)

        workers._start = start
        workers._waiting = {}

        def queue(*jobs):
            workers._queue = [(k, job) for k, job in enumerate(jobs)]
            for job in jobs:
                job.queued = time.monotonic()

        anywhere = Job("cut", None, 5000, "ring", None, None)
        bound = Job("cut", None, 1000, "piece", None, None, needs="ring/piece0")
        first.held, second.held = {"ring/piece0"}, set()
        workers._idle = [first]
        queue(anywhere, bound)
        assert sorted(workers._queue, key=workers._order)[0][1] is anywhere
        workers._pump()
        assert started == [("piece", first)] and [job for _, job in workers._queue] == [anywhere]
        workers._idle = [second]
        workers._pump()
        assert started[1] == ("ring", second) and not workers._queue

        started.clear()
        workers._idle = [first]
        queue(anywhere, bound)
        pool._MADE_BY[bound.key] = (second, 60.0)
        try:
            workers._pump()
        finally:
            pool._MADE_BY.pop(bound.key)
        assert started == [("ring", first)] and [job for _, job in workers._queue] == [bound]
    finally:
        workers._queue = []
        workers.close(cancel=True)


def test_only_a_processs_first_run_skips_the_full_garbage_collection(monkeypatch):
    """Before the objects alive are frozen for a run, the first run in a process collects
    the young generations only (a new process's set-up leaves almost no garbage, and a full
    collection walks every object); a later run collects everything (the runs before it may
    have left theirs)."""
    import gc
    import types

    from taichi_frac import simulation

    asked = []
    monkeypatch.setattr(simulation, "_RUNS_STARTED", False)
    monkeypatch.setattr(simulation, "gc", types.SimpleNamespace(
        collect=lambda generation=2: asked.append(generation) or 0, freeze=gc.freeze, unfreeze=gc.unfreeze))
    scene = load_scene(SCENES / "single_ring.toml")
    for _ in range(2):
        Simulation(scene, output=False, frames=1).run()
    assert asked == [1, 2]
