"""What a Dask worker runs for one variant: the scene with its overrides, into its folder.

A worker process keeps one World (its Taichi fields and compiled kernels) and its prepared
bodies (``scene_setup.prepare_object``) between variants, so only its first variant pays for kernel loading and
meshing; the next ones start their first frame at once (``seconds_to_first_frame`` in the
stats). A variant's folder holds, when it is done:

* ``cache.usdc``, the USD cache (written through the checkpointing CacheWriter);
* ``fragment_sizes.png``, the histogram of its fragments' volumes;
* ``stats.json``, written last and atomically: its presence, with the cache's SHA-256 in it,
  is what marks the variant done (see ``results.is_done``).

Everything else a worker could leave (a cache of a run cut short, a stale stats file) is
removed or overwritten before the run, so an incomplete variant never looks done.
"""

from __future__ import annotations

import dataclasses
import gc
import hashlib
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import results

CACHE_NAME = "cache.usdc"
HISTOGRAM_NAME = "fragment_sizes.png"


@dataclass(frozen=True)
class VariantTask:
    """Everything a worker needs for one variant (plain data: it travels to the worker).

    Attributes:
        id, index, settings: the variant (see ``variants.Variant``).
        scene: path of the scene file; the workers read it (a cluster shares the disk).
        scene_sha256: the file's hash when the sweep started (recorded in the stats).
        overrides: the fixed ``--set`` overrides followed by the variant's.
        frames: frames to simulate (None: the scene's duration).
        directory: the variant's folder.
        arch: Taichi backend.
    """

    id: str
    index: int
    settings: dict
    scene: str
    scene_sha256: str
    overrides: tuple
    frames: int | None
    directory: str
    arch: str = "cpu"


class _WorkerState:
    """Kept by a worker process between variants."""

    def __init__(self):
        self.world = None
        self.runs = 0
        self.closed = False


_STATE = _WorkerState()


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def run_variant(task: VariantTask) -> dict:
    """Run one variant and write its folder; returns its stats (the stats.json content).

    Errors propagate (the client reports them with the variant); the World stays usable
    because the next Simulation clears it."""
    start = time.perf_counter()
    if _STATE.closed:
        raise RuntimeError("this worker's Taichi runtime was closed (flush_kernel_cache); start a new worker")
    from ..scenes import load_scene
    from ..simulation import Simulation

    folder = Path(task.directory)
    folder.mkdir(parents=True, exist_ok=True)
    for name in (results.STATS_NAME, HISTOGRAM_NAME, results.THUMBNAIL_NAME):
        (folder / name).unlink(missing_ok=True)
    scene = load_scene(task.scene, list(task.overrides))
    loaded = time.perf_counter()
    first_frame_end = []

    def progress(frame, *_):
        if frame == 1:
            first_frame_end.append(time.perf_counter())

    cache = folder / CACHE_NAME
    sim = _simulation(Simulation, scene, cache, task, progress)
    built = time.perf_counter()
    summary = sim.run()
    if summary.interrupted:
        raise KeyboardInterrupt(f"variant {task.id} was interrupted at frame {summary.frames}")
    _STATE.runs += 1
    live = sim.world.body_ids
    volumes = np.sort([sim.records[b].model.volume for b in live if sim.records[b].generation > 0])
    _write_histogram(folder / HISTOGRAM_NAME, volumes, task)
    first_ms = summary.ms_per_frame["first"]
    stats = dict(
        format=results.STATS_FORMAT, id=task.id, index=task.index, settings=task.settings, status="done",
        scene=task.scene, scene_sha256=task.scene_sha256, overrides=list(task.overrides), frames=summary.frames,
        fragments=summary.fragments, fracture_events=summary.fractures,
        mass_initial=summary.mass_initial, mass_final=summary.mass_final, mass_dropped=summary.mass_dropped,
        ms_per_frame=summary.ms_per_frame["mean"], run_seconds=summary.wall_time,
        wall_time=time.perf_counter() - start,
        seconds_to_first_frame=(first_frame_end[0] - start - first_ms / 1000.0) if first_frame_end else None,
        first_frame_ms=first_ms,
        # Where the time before the first frame went [s]: reading the scene, building the
        # Simulation (meshing, World set-up), and run()'s start (opening the cache).
        startup_seconds=dict(scene=loaded - start, simulation=built - loaded,
                             run_start=(first_frame_end[0] - built - first_ms / 1000.0) if first_frame_end else None,
                             prepare=sim.prepare_seconds),
        fragment_volumes=[float(v) for v in volumes],
        cache=CACHE_NAME, cache_sha256=file_sha256(cache),
        worker=f"{socket.gethostname()}:{os.getpid()}", worker_run_index=_STATE.runs,
        summary=dataclasses.asdict(summary),
    )
    results.write_json_atomic(folder / results.STATS_NAME, stats)
    # What stays between variants (Taichi's objects, the World, the memoised models: ~10^5
    # objects) out of the collector's sight: Simulation.run starts with a full collection,
    # which otherwise walks them all again before every variant's first frame.
    del sim
    gc.collect()
    gc.freeze()
    return stats


def flush_kernel_cache() -> bool:
    """Write the worker's compiled kernels to Taichi's offline cache, so the next sweep's
    workers load them instead of compiling (minutes on a loaded machine). Taichi writes
    the cache only when its runtime is finalised (``runtime.finish``), which a worker process
    stopped by its nanny may never reach. This ends the worker's Taichi runtime: the client
    calls it just before it closes its LocalCluster."""
    from .. import runtime

    if not runtime.is_initialised() or _STATE.closed:
        return False
    _STATE.world = None
    _STATE.closed = True
    return runtime.finish()


def _simulation(Simulation, scene, cache, task, progress):
    """A Simulation on the worker's World; a variant that needs larger capacities than
    the World has (more particles) gets a new World, which later variants then share. The
    pieces' surfaces are cut in this process: the sweep's workers already fill the cores."""
    try:
        sim = Simulation(scene, output=cache, arch=task.arch, frames=task.frames, progress=progress,
                         world=_STATE.world, surface_workers=0)
    except ValueError as exc:
        if _STATE.world is None or "the World given has" not in str(exc):
            raise
        sim = Simulation(scene, output=cache, arch=task.arch, frames=task.frames, progress=progress,
                         world=None, surface_workers=0)
    _STATE.world = sim.world
    return sim


def _write_histogram(path: Path, volumes: np.ndarray, task: VariantTask) -> None:
    """The fragments' volumes [cm^3] on logarithmic bins (a piece's size spans decades).
    Fixed margins and plain tick labels: matplotlib's tight layout and its mathtext
    exponents cost more than the rest of the plot. Without matplotlib (the ``plots`` extra)
    no histogram is drawn; the stats hold the volumes all the same."""
    try:
        import matplotlib
    except ModuleNotFoundError:
        return

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    from .variants import Variant

    fig = plt.figure(figsize=(4.0, 2.6))
    ax = fig.add_axes((0.15, 0.2, 0.8, 0.62))
    cm3 = volumes * 1e6
    if len(cm3):
        low, high = cm3.min(), cm3.max()
        bins = np.geomspace(low / 1.05, high * 1.05, 16) if high > low else 8
        ax.hist(cm3, bins=bins, color="#4c72b0", edgecolor="white")
        if high > low:
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.xaxis.set_minor_formatter(NullFormatter())
    else:
        ax.text(0.5, 0.5, "no fragments", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("fragment volume [cm³]")
    ax.set_ylabel("fragments")
    label = Variant(task.id, task.index, task.settings).label()
    ax.set_title(f"{label}\n{len(cm3)} fragments", fontsize=8)
    fig.savefig(path, dpi=90)
    plt.close(fig)
