"""The piece-surface stage where the simulation does not wait for it.

:class:`SurfaceWorkers` runs :class:`~taichi_frac.surfaces.stage.SurfaceStage` in worker
processes (``worker.py``): requests return futures at once, so the frame loop goes on while
a split's pieces are cut, and the recorder writes them when they are done. Each worker takes
one job at a time, the one holding up the most work first (its tets and those of the splits
waiting for its pieces). A scene object's first split goes to any idle
worker (sent the arrays its render solid is built from, ``solid.PortableSolid``); a piece's
split to the worker that cut the piece, which holds its solid, or, when that one stays busy
and a core is idle, to another that cuts the piece again first (a cut gives the same bytes
in any process); a split a worker's memo holds (a repeated run's) to that worker. Workers
are forked from this process (no imports to wait for) and, after a run, stay idle for the
next run in this process, which takes their memos; they end with it. A worker's booleans
run one thread where the workers outnumber the cores two to one (``worker.boolean_threads``). :class:`InProcessSurfaces` is the same
interface in this process (futures already done). Both give the same surfaces: the same code
runs on the same arrays.
"""

from __future__ import annotations

import atexit
import dataclasses
import itertools
import multiprocessing
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future

from ..memo import remember
from .front import Job, SurfaceFront, shading_by_key
from .stage import SurfaceStage
from .worker import boolean_threads, read_frame, write_frame


#: Workers are forked from the run's process where the platform forks (Linux: macOS' system
#: libraries do not survive a fork that is not followed by exec), else started as interpreters.
FORK = sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()


class SurfaceWorkerError(RuntimeError):
    """A piece-surface worker failed: its error's traceback, or how the process ended."""


def default_worker_count(breakable_bodies: int) -> int:
    """Workers for a run with ``breakable_bodies`` scene bodies that may break: one per core
    and at least four where workers are forked, no more than there are such bodies (none
    when nothing breaks). A split's cost is not known before it is cut and differs by a
    hundredfold (the glass walls' three first cuts took 4, 15 and 17 s): with one worker per
    core two long cuts can run one after the other while another core idles (the glass walls
    took 1.055x as long with two workers on 2 cores as with four), and more workers share the
    cores between them instead. Where a worker is a new interpreter (no fork), one for every
    two cores past the first two: its imports cost the frame loop more on fewer cores than
    the cuts it takes off it."""
    cores = os.cpu_count() or 1
    wanted = max(4, cores) if FORK else max(0, cores - 2) // 2
    return min(wanted, max(0, breakable_bodies))


class InProcessSurfaces(SurfaceFront):
    """The surface stage in this process, behind :class:`SurfaceWorkers`' interface."""

    count = 0  # (worker processes)

    def __init__(self):
        super().__init__()
        self.stage = SurfaceStage()

    def _run(self, job: Job) -> None:
        payload = job.sent(self.stage.holds)
        try:
            result = self.stage.add_body(*payload) if job.kind == "add_body" else self.stage.cut(payload)
        except Exception as error:  # noqa: BLE001 (the future carries it to whoever waits)
            job.failed(error)
        else:
            job.done(result)

    def render_of(self, body: int):
        """The render solid of a live body (``solid.RenderSolid``), or None (it shows its
        tets' boundary)."""
        future = self._render.get(body)
        solid = None if future is None else future.result()
        return None if solid is None else self.stage.render_of(solid.key)

    def close(self, cancel: bool = False) -> None:
        pass


class _Forked:
    """A worker forked from this process (``multiprocessing``'s fork context, as
    ``geometry.bounded`` forks its steps), behind the part of ``subprocess.Popen``'s
    interface ``_Worker`` uses."""

    def __init__(self, process):
        self._process = process
        self.pid = process.pid

    @property
    def returncode(self):
        return self._process.exitcode

    def poll(self):
        return self._process.exitcode  # (None while it runs)

    def wait(self):
        self._process.join()
        return self._process.exitcode

    def kill(self) -> None:
        self._process.kill()


def _fork_worker(request_read: int, answer_write: int, threads: int) -> _Forked:
    """A worker forked from this process: it starts with this process' modules imported (a
    started interpreter spends about 0.8 s importing them). A daemon: an idle one left at
    exit is ended, not waited for."""
    process = multiprocessing.get_context("fork").Process(
        target=_serve_forked, args=(request_read, answer_write, os.getpid(), threads), daemon=True)
    process.start()
    return _Forked(process)


def _serve_forked(request_read: int, answer_write: int, parent: int, threads: int) -> None:
    """The forked worker's life: it never touches what it inherited of the simulation
    (Taichi's runtime, the other workers' pipes: closed), and leaves without the parent's
    exit handlers (multiprocessing ends a forked child with os._exit). The objects it
    inherited are frozen out of the cyclic garbage collector: a collection would walk them
    all, copying the pages it touches from the parent's."""
    import gc

    from ..geometry.workers import die_with_parent
    from .worker import serve

    gc.freeze()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent)
    devnull = os.open(os.devnull, os.O_RDWR)
    os.dup2(devnull, 0)
    os.dup2(devnull, 1)
    keep = sorted({request_read, answer_write})
    os.closerange(3, keep[0])
    os.closerange(keep[0] + 1, keep[1])
    os.closerange(keep[1] + 1, _max_fd())
    serve(os.fdopen(request_read, "rb"), os.fdopen(answer_write, "wb"), threads)


def _max_fd() -> int:
    try:
        return os.sysconf("SC_OPEN_MAX")
    except (ValueError, OSError):
        return 65536


class _Worker:
    """One worker process, its booleans on ``threads`` threads: a writer thread feeds it
    requests (a large request must not hold up the frame loop while the worker is busy), a
    reader thread settles their futures."""

    def __init__(self, threads: int):
        # Pipes of their own: what a library prints at import (Taichi's banner) goes to
        # the worker's stdout, which is not the channel.
        request_read, request_write = os.pipe()
        answer_read, answer_write = os.pipe()
        try:
            if FORK:
                self.process = _fork_worker(request_read, answer_write, threads)
            else:
                self.process = subprocess.Popen(
                    [sys.executable, "-m", "taichi_frac.surfaces.worker", str(os.getpid()), str(request_read),
                     str(answer_write), str(threads)], pass_fds=(request_read, answer_write), stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL)
        finally:
            os.close(request_read)
            os.close(answer_write)
        self.requests = os.fdopen(request_write, "wb")
        self.answers = os.fdopen(answer_read, "rb")
        self.pending: dict[int, Future] = {}
        self.lock = threading.Lock()
        self.outbox: queue.SimpleQueue = queue.SimpleQueue()
        self.held: set[str] = set()  # keys of the render solids and shading its stage holds
        threading.Thread(target=self._write, daemon=True).start()
        threading.Thread(target=self._read, daemon=True).start()

    def submit(self, task: int, kind: str, payload) -> Future:
        future = Future()
        with self.lock:
            if self.process.poll() is not None:
                future.set_exception(self._ended())
                return future
            self.pending[task] = future
        self.outbox.put((task, kind, payload))
        return future

    def tell(self, kind: str, payload) -> None:
        """A request the worker does not answer."""
        self.outbox.put((-1, kind, payload))

    def close(self) -> None:
        self.outbox.put(None)

    def kill(self) -> None:
        self.process.kill()

    def _write(self) -> None:
        try:
            while (request := self.outbox.get()) is not None:
                write_frame(self.requests, request)
            self.requests.close()
        except (OSError, ValueError):
            pass  # (the process ended: the reader fails what is pending)

    def _read(self) -> None:
        try:
            while (answer := read_frame(self.answers)) is not None:
                task, ok, result = answer
                with self.lock:
                    future = self.pending.pop(task)
                if ok:
                    future.set_result(result)
                else:
                    future.set_exception(SurfaceWorkerError(f"a piece-surface worker failed:\n{result}"))
        except Exception as error:  # noqa: BLE001 (a broken channel: what is pending fails with it)
            reason = error
        else:
            reason = None
        self.process.wait()
        with self.lock:
            left, self.pending = list(self.pending.values()), {}
        for future in left:
            future.set_exception(self._ended(reason))

    def _ended(self, reason=None) -> SurfaceWorkerError:
        code = self.process.returncode
        return SurfaceWorkerError(f"the piece-surface worker (pid {self.process.pid}) stopped with exit code {code}"
                                  + (f" ({reason})" if reason else "") + " before it answered")


#: Worker processes idle between runs of this process, for the next run to take (no new
#: process to start; their memos, ``stage._CUTS``, answer a repeated run's splits). They end
#: with this process.
_IDLE: list = []


def _take_workers(count: int) -> list:
    """``count`` workers: idle ones first (in the order they were first started), then new
    ones."""
    alive = [w for w in _IDLE if w.process.poll() is None]
    _IDLE.clear()
    taken, spare = alive[:count], alive[count:]
    for worker in spare:
        worker.close()
    taken += [_Worker(boolean_threads(count)) for _ in range(count - len(taken))]
    for worker in taken:
        worker.held = set()
        worker.tell("reset", None)  # (nothing of the last run's solids)
    return taken


#: A job waits for the worker holding its piece's solid (or its memo) up to this many times
#: what another worker would take to make the solid again first (``SurfaceFront.replay``),
#: then goes to an idle one: the cores are busy anyway while new splits come in, and a
#: worker that makes a solid again spends time a split could have used.
STEAL_WAIT_FACTOR = 2.0

#: Which worker's memo holds each split cut (and each scene object started) in this process,
#: and how long that job took [s]: a repeated run's jobs go to it (key -> (worker, seconds)).
#: The oldest go first past this many (more than the workers' memos keep: ``stage.CUTS_KEPT``
#: each).
MADE_BY_KEPT = 4096
_MADE_BY: dict = {}


class SurfaceWorkers(SurfaceFront):
    """The surface stage in ``count`` worker processes, one job at a time each.

    A job goes to the idle worker where it costs least: one holding the piece's solid it
    cuts (or whose memo holds its result), else, while fewer workers are busy than there are
    cores and once it has waited STEAL_WAIT_FACTOR times what another worker would have to
    cut again first (the cuts that made the piece, ``replay``), to that one: so no core
    idles long while one worker has a queue, and no core makes a solid again while a split
    could use it.
    """

    def __init__(self, count: int):
        if count < 1:
            raise ValueError(f"count = {count}: at least one worker")
        super().__init__()
        self.count = count
        self._workers = _take_workers(count)
        self._idle = list(self._workers)
        self._queue: list[tuple] = []  # (order, job): see _order
        self._tasks = itertools.count()
        self._lock = threading.RLock()  # (a settled job's callbacks may queue jobs: same thread)
        self._timer = None  # (wakes the queue when a waiting job may go to another worker)
        self._cores = os.cpu_count() or 1
        self._closed = False

    def _run(self, job: Job) -> None:
        with self._lock:
            job.queued = time.monotonic()
            self._queue.append((next(self._tasks), job))
            self._pump()

    def _order(self, entry: tuple) -> tuple:
        """A queued job's place: scene objects' starts first, then the most work it holds up
        (its own tets and those of the splits waiting for its pieces, ``waiting_work``),
        then the first asked."""
        order, job = entry
        return job.kind != "add_body", -(job.size + self.waiting_work(job.makes)), order

    def _extra(self, job: Job, worker: "_Worker") -> float | None:
        """[s] what ``job`` costs more on ``worker`` than where it costs least: the time it
        took where another worker's memo holds its result, and the cuts it replays where
        ``worker`` does not hold the piece's solid; None where it cannot go."""
        extra = 0.0
        made = _MADE_BY.get(job.key)
        if made is not None and made[0] is not worker and made[0] in self._workers:
            extra += made[1]
        if job.needs is not None and job.needs not in worker.held:
            replay = self.replay(job.needs, worker.held.__contains__)
            if replay is None:
                return None
            extra += replay[1]
        return extra

    def _pump(self) -> None:
        """Start queued jobs on idle workers in ``_order``, each where it costs least;
        one that costs more on every idle worker waits for its own as long as that (called
        with the lock held). A worker holding a solid that a queued job needs takes such a
        job first: another job, which any worker could take, waits for one holding none, or
        for what the first pass leaves idle (a job bound to a busy worker's solid waited
        behind a long one that an idle worker could have taken, and the chain of splits
        after it ended the run)."""
        if self._closed:
            return
        now, wake = time.monotonic(), None
        self._queue.sort(key=self._order)  # (splits asked for since the last pump move their parents up)
        for bound_first in (True, False):
            needed = None  # per idle worker, the queued jobs that need a solid it holds (until a job starts)
            for entry in list(self._queue):
                if not self._idle:
                    break
                job = entry[1]
                if needed is None:
                    needed = [sum(e[1].needs in w.held for e in self._queue) for w in self._idle]
                costs = [(extra, needed[i], i) for i, w in enumerate(self._idle)
                         if (extra := self._extra(job, w)) is not None]
                if not costs:
                    if all(self._extra(job, w) is None for w in self._workers):
                        self._queue.remove(entry)  # (no worker holds the solid, or can make it again)
                        job.failed(SurfaceWorkerError(f"no piece-surface worker can cut the split {job.key}"))
                    continue
                extra, waiting, i = min(costs)
                if bound_first and waiting and job.needs not in self._idle[i].held:
                    continue  # (that worker is another queued job's)
                if extra > 0.0 and len(self._workers) - len(self._idle) >= self._cores:
                    continue  # (no core is idle: what is made again would take one from a split)
                extra *= STEAL_WAIT_FACTOR
                if now - job.queued < extra:
                    wake = min(wake if wake is not None else extra, job.queued + extra - now)
                    continue
                self._queue.remove(entry)
                self._start(job, self._idle[i])
                needed = None
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if wake is not None and self._idle:
            self._timer = threading.Timer(wake + 1e-3, self._wake)
            self._timer.daemon = True
            self._timer.start()

    def _wake(self) -> None:
        with self._lock:
            self._pump()

    def _start(self, job: Job, worker: "_Worker") -> None:
        self._idle.remove(worker)
        holds = worker.held.__contains__
        payload = job.sent(holds)
        if job.kind == "add_body" and payload[1] is not None:
            # Without trimesh's cache: a spatial index built here does not survive pickling.
            payload = (payload[0], payload[1].copy(include_cache=False), payload[2])
        if job.kind == "cut":
            if job.needs is not None and job.needs not in worker.held:
                chain, _ = self.replay(job.needs, holds)
                sent = []
                for request in chain:  # (its pieces' solids stay there too)
                    sent.append(shading_by_key(request, holds))
                    worker.held.add(request.shading_key)
                    worker.held |= {k for k in request.piece_keys if k in self._origin}
                    if request.render is None:
                        worker.held.discard(request.parent_key)
                payload = dataclasses.replace(payload, replay=tuple(sent))
            worker.held.add(job.payload.shading_key)
            worker.held.discard(job.needs)  # (the stage lets go of a piece's solid it cuts)
        job.started = time.monotonic()
        future = worker.submit(next(self._tasks), job.kind, payload)
        future.add_done_callback(lambda f: self._settle(worker, job, f))

    def _settle(self, worker: "_Worker", job: Job, future: Future) -> None:
        error = future.exception()
        with self._lock:
            if error is None:
                result = future.result()
                if job.kind == "add_body":
                    worker.held.add(job.key)
                else:
                    worker.held |= {k for k, has in zip(job.payload.piece_keys, result.renders) if has}
                took = time.monotonic() - job.started
                made = _MADE_BY.get(job.key)
                if made is not None and made[0] is worker:  # (a memo's answer: what the job took first)
                    took = max(took, made[1])
                remember(_MADE_BY, job.key, (worker, took), MADE_BY_KEPT)
            if not self._closed:
                self._idle.append(worker)
                self._idle.sort(key=self._workers.index)
        if error is None:
            job.done(result)
        else:
            job.failed(error)
        with self._lock:
            self._pump()

    def render_of(self, body: int):
        raise RuntimeError("the render solids live in the worker processes: run with surface_workers = 0 "
                           "(Simulation(..., surface_workers=0)) to read them")

    def close(self, cancel: bool = False) -> None:
        """Leave the workers idle for the next run in this process once their work is done,
        or end them at once (``cancel``: their results are no longer wanted). Jobs not
        started are dropped."""
        with self._lock:
            self._closed = True
            self._queue.clear()
            if self._timer is not None:
                self._timer.cancel()
        for worker in self._workers:
            if cancel:
                worker.kill()
            elif worker.process.poll() is None:
                _IDLE.append(worker)
        self._workers = []


def close_idle_workers(timeout: float = 5.0) -> None:
    """End the workers left idle for a next run, and wait up to ``timeout`` seconds for them
    to exit (at this process' exit: none outlives it, not even by the moment the kernel's
    parent-death signal takes)."""
    idle, _IDLE[:] = list(_IDLE), []
    _MADE_BY.clear()
    for worker in idle:
        worker.close()
    deadline = time.monotonic() + timeout
    for worker in idle:
        while worker.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        if worker.process.poll() is None:
            worker.kill()


atexit.register(close_idle_workers)
