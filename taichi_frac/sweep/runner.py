"""Runs a sweep on dask.distributed and collects its results (the client side).

The variants whose folder already holds a finished run (``results.read_done``) are skipped;
the others go to the cluster, one task each: a ``LocalCluster`` of worker processes (one
thread each) started here, or the scheduler of an existing cluster. Results are written
to sweep.json / sweep.csv after every variant, so an interrupted sweep leaves what it did;
run it again and it does the rest. A variant that raises (or whose worker dies more often
than Dask's ``distributed.scheduler.allowed-failures``) is reported with its error and the
others go on.
"""

from __future__ import annotations

import datetime
import hashlib
import logging
import os
import signal
import sys
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..options import OptionError
from . import results
from .variants import format_value, make_variants
from .worker import VariantTask, flush_kernel_cache, run_variant


@dataclass
class SweepResult:
    """What ``sweep`` returns.

    Attributes:
        directory: the sweep's folder.
        records: one dict per variant, in sweep order (a done variant's stats.json content,
            or id/settings/status "failed" with its error, or status "pending").
        keys: the varied keys (the CSV's first columns).
        ran: variants run by this call; skipped: found done and not run again.
        failed: variants that failed in this call; interrupted: the call was stopped.
        sheet: the contact sheet's path, or None.
    """

    directory: Path
    records: list[dict]
    keys: list[str]
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    interrupted: bool = False
    sheet: Path | None = None
    seconds: float = 0.0
    meta: dict = field(default_factory=dict)

    @property
    def csv_path(self) -> Path:
        return self.directory / "sweep.csv"

    @property
    def json_path(self) -> Path:
        return self.directory / "sweep.json"

    @property
    def done(self) -> list[dict]:
        return [r for r in self.records if r["status"] == "done"]


def sweep(scene, vary, output, *, samples: int | None = None, seed: int = 0, overrides=(), frames: int | None = None,
          workers: int | None = None, scheduler: str | None = None, arch: str = "cpu", sheet: bool = True,
          sheet_options: dict | None = None, progress: bool = True, log=None) -> SweepResult:
    """Run the variants of ``scene`` on Dask; returns a ``SweepResult`` (records, counts, paths).

    Args:
        scene: path of the scene file (TOML).
        vary: ``KEY=VALUES`` specs, keys as ``--set``'s: ``"ring.fracture.seed=0:32"`` (0..31),
            ``"ring.fracture.crack_count=1,3,5"``, ``"ring.material.tensile_strength=2e6..6e6"``
            (a continuous range: with ``samples`` only). See ``sweep.variants``.
        output: the sweep's folder; each variant writes ``output/<variant id>/``.
        samples: None runs the product of the values; N runs N random draws.
        seed: the random draws' seed (``samples`` only).
        overrides: ``KEY=VALUE`` overrides applied to every variant (``--set``).
        frames: frames per variant (None: the scene's duration).
        workers: local worker processes (None: one per core). Ignored with ``scheduler``.
        scheduler: address of a running Dask scheduler (``tcp://HOST:PORT``); its workers must
            import taichi_frac and see the scene file and ``output`` at the same paths.
        arch: Taichi backend of the workers.
        sheet: render the contact sheet (needs Blender's Python, ``.venv-blender``).
        sheet_options: ``resolution`` ("200x150"), ``samples`` (8), ``columns``,
            ``blender_python`` for the contact sheet.
        progress: show a progress bar (a line per variant when stderr is not a terminal).
        log: callable(str) for status lines (default: stderr).

    Variants already done in ``output`` (same id, same scene file, a cache matching its
    stats) are not run again; an interrupted sweep resumes where it stopped.
    """
    started = time.perf_counter()
    log = log or (lambda message: print(message, file=sys.stderr, flush=True))
    from ..scenes import find_scene

    scene_path = find_scene(scene).resolve()
    if not scene_path.is_file():
        raise FileNotFoundError(f"scene file {str(scene)!r} does not exist")
    if workers is not None and workers < 1:
        raise OptionError(f"workers = {workers}: give 1 or more")
    if frames is not None and frames < 1:
        raise OptionError(f"frames = {frames}: give 1 or more")
    fixed = tuple(overrides)
    scene_sha256 = hashlib.sha256(scene_path.read_bytes()).hexdigest()
    variants = make_variants(list(vary), scene_name=scene_path.name, fixed=fixed, frames=frames,
                             samples=samples, seed=seed)
    _check_variants(scene_path, fixed, variants)
    directory = Path(output)
    directory.mkdir(parents=True, exist_ok=True)
    keys = list(variants[0].settings)
    meta = dict(
        generator=f"taichi-frac {__version__}", scene=str(scene_path), scene_sha256=scene_sha256,
        vary=[str(v) for v in vary], samples=samples, sweep_seed=seed if samples is not None else None,
        overrides=list(fixed), frames=frames, arch=arch, keys=keys,
        started=datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    )
    records, tasks = [], []
    for v in variants:
        folder = directory / v.id
        stats = results.read_done(folder, v.id, scene_sha256)
        if stats is not None:
            records.append(stats)
            continue
        records.append(dict(id=v.id, index=v.index, settings=v.settings, status="pending"))
        tasks.append(VariantTask(
            id=v.id, index=v.index, settings=v.settings, scene=str(scene_path), scene_sha256=scene_sha256,
            overrides=fixed + tuple(v.overrides()), frames=frames, directory=str(folder.resolve()), arch=arch,
        ))
    result = SweepResult(directory, records, keys, skipped=len(variants) - len(tasks), meta=meta)
    log(f"sweep: {len(variants)} variants, {result.skipped} already done, {len(tasks)} to run"
        + ("" if not tasks else f" on {scheduler or f'{_local_workers(workers)} local worker processes'}"))
    try:
        if tasks:
            _run_tasks(tasks, result, directory, workers, scheduler, progress, log)
    except KeyboardInterrupt:
        result.interrupted = True
    finally:
        result.seconds = time.perf_counter() - started
        _finish(result)
    if result.interrupted:
        log(f"sweep: interrupted; {sum(r['status'] == 'done' for r in records)} of {len(records)} variants done "
            "(run the same command again to do the rest)")
        return result
    if sheet and result.done:
        from .sheet import contact_sheet

        try:
            result.sheet = contact_sheet(result, log=log, **(sheet_options or {}))
        except KeyboardInterrupt:
            result.interrupted = True
        except (OSError, RuntimeError) as exc:
            log(f"sweep: no contact sheet: {exc}")
    _finish(result)
    return result


def _local_workers(workers: int | None) -> int:
    return workers or os.cpu_count() or 1


def _check_variants(scene_path: Path, fixed: tuple, variants) -> None:
    """Load the scene here before any worker starts, so a bad key or value fails at once and
    names it: with the first variant's settings, then with each varied value alone (all of
    a short list; the ends and 48 values between of a long one). Loading costs ~10 ms, so
    not every one of thousands of combinations is loaded; a combination that only fails
    together is reported by its worker."""
    from ..scenes import load_scene
    from .variants import Variant

    def check(variant):
        try:
            load_scene(scene_path, list(fixed) + variant.overrides())
        except OptionError as exc:
            raise OptionError(f"variant {variant.label()}: {exc}") from None

    check(variants[0])
    for key in variants[0].settings:
        values = list({format_value(v.settings[key]): v.settings[key] for v in variants}.values())
        if len(values) > 50:
            values = [values[i] for i in np.unique(np.linspace(0, len(values) - 1, 50).round().astype(int))]
        for value in values:
            check(Variant("", 0, dict(variants[0].settings, **{key: value})))


def _finish(result: SweepResult) -> None:
    meta = dict(result.meta, seconds=round(result.seconds, 3), interrupted=result.interrupted,
                counts={s: sum(r["status"] == s for r in result.records) for s in ("done", "failed", "pending")},
                sheet=None if result.sheet is None else result.sheet.name)
    results.write_results(result.directory, result.records, result.keys, meta)


def _client(workers: int | None, scheduler: str | None):
    """A Dask client on the given scheduler, or on a new LocalCluster of worker processes."""
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler, timeout="30s"), None
    # One thread a worker: a worker runs one variant at a time (Taichi keeps one state per
    # process); no memory limit: the nanny would restart a worker that grows past its share.
    # Taichi's own thread pool keeps its default size (every core): the offline cache's key
    # includes it, and with another size each worker would compile every kernel again
    # instead of loading what `taichi-frac run` and earlier sweeps compiled.
    # The workers' environment is this process's: Dask's nanny would otherwise pin the
    # BLAS libraries to one thread (OMP/MKL/OPENBLAS_NUM_THREADS=1). The pieces do not
    # depend on it (no BLAS product enters the physics: geometry/mass.py), but a variant
    # then runs as `taichi-frac run` runs, timings included.
    with dask.config.set({"distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": 65536}}):
        cluster = LocalCluster(n_workers=_local_workers(workers), threads_per_worker=1, processes=True,
                               dashboard_address=":0", memory_limit=0, silence_logs=logging.ERROR)
    return Client(cluster), cluster


def _run_tasks(tasks, result: SweepResult, directory: Path, workers, scheduler, progress: bool, log) -> None:
    from dask.distributed import as_completed

    by_key = {}
    local_pids = []
    client, cluster = _client(workers, scheduler)
    bar = _ProgressBar(len(result.records), result.skipped, progress, log)
    finished = False
    try:
        # The local workers' process ids: after Ctrl-C they are stopped by id (a worker in
        # the middle of a kernel compile does not answer a polite close for minutes).
        local_pids = list(client.run(os.getpid).values()) if cluster is not None else []
        token = uuid.uuid4().hex[:8]
        futures = []
        for task in tasks:
            future = client.submit(run_variant, task, key=f"taichi-frac-variant-{task.id}-{token}", pure=False)
            by_key[future.key] = task
            futures.append(future)
        for future in as_completed(futures):
            task = by_key[future.key]
            try:
                record = future.result()
            except Exception as exc:  # the variant's own error, or KilledWorker
                record = _failure(task, exc, future)
                result.failed += 1
                (Path(task.directory) / results.ERROR_NAME).write_text(record["traceback"] or record["error"])
            result.records[task.index] = record
            result.ran += 1
            bar.advance(record)
            results.write_results(directory, result.records, result.keys, result.meta)
        finished = True
    finally:
        bar.stop()
        if cluster is not None and finished:
            # Only once every task is over: the flush ends each worker's Taichi runtime.
            try:
                client.run(flush_kernel_cache)
            except Exception:  # a worker that is gone: its kernels are compiled again next time
                pass
        if cluster is not None and not finished:
            for pid in local_pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        try:
            client.close(timeout=10)
            if cluster is not None:
                cluster.close(timeout=20)
        except Exception as exc:  # (a timeout): the processes are gone or going; nothing is lost
            log(f"sweep: closing the cluster: {type(exc).__name__}: {exc}")


def _failure(task: VariantTask, exc: BaseException, future) -> dict:
    try:
        tb = "".join(traceback.format_tb(future.traceback())) if future.traceback() else ""
    except Exception:  # the traceback may not travel back (a dead worker)
        tb = ""
    error = f"{type(exc).__name__}: {exc}"
    return dict(id=task.id, index=task.index, settings=task.settings, status="failed", error=error,
                traceback=f"{tb}{error}\n")


class _ProgressBar:
    """A rich bar over the variants on a terminal; one line per variant otherwise."""

    def __init__(self, total: int, already: int, enabled: bool, log):
        self.total, self.count, self.failed, self.log = total, already, 0, log
        self.bar = self.task = None
        self.enabled = enabled
        if enabled and sys.stderr.isatty():
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
            from rich.progress import TimeRemainingColumn

            self.bar = Progress(TextColumn("variants"), BarColumn(), MofNCompleteColumn(),
                                TextColumn("failed {task.fields[failed]}  last: {task.fields[last]}"),
                                TimeElapsedColumn(), TimeRemainingColumn())
            self.bar.start()
            self.task = self.bar.add_task("sweep", total=total, completed=already, failed=0, last="")

    def advance(self, record: dict) -> None:
        self.count += 1
        self.failed += record["status"] == "failed"
        what = (f"{record['fragments']} fragments in {record['wall_time']:.1f} s" if record["status"] == "done"
                else record["error"].splitlines()[0][:120])
        if self.bar is not None:
            self.bar.update(self.task, advance=1, failed=self.failed, last=f"{record['id']} {what}")
        elif self.enabled:
            self.log(f"[{self.count}/{self.total}] {record['id']} {record['status']}: {what}")

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
