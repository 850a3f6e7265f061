"""The piece-surface stage where the simulation does not wait for it.

:class:`SurfaceWorkers` runs :class:`~taichi_frac.surfaces.stage.SurfaceStage` in worker
processes (``worker.py``): a body and every piece of it go to one worker, which keeps their
render solids; requests return futures at once, so the frame loop goes on while a split's
pieces are cut, and the recorder writes them when they are done. Workers are forked from
this process (no imports to wait for) and, after a run, stay idle for the next run in this
process, which takes their memos of root surfaces and cuts with them; they end with it.
:class:`InProcessSurfaces` is the same interface in this process (futures already done).
Both give the same surfaces: the same code runs on the same arrays.
"""

from __future__ import annotations

import atexit
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

from .stage import CutRequest, SurfaceStage
from .worker import read_frame, write_frame


#: Workers are forked from the run's process where the platform forks (Linux: macOS' system
#: libraries do not survive a fork that is not followed by exec), else started as interpreters.
FORK = sys.platform.startswith("linux") and "fork" in multiprocessing.get_all_start_methods()


class SurfaceWorkerError(RuntimeError):
    """A piece-surface worker failed: its error's traceback, or how the process ended."""


def default_worker_count(breakable_bodies: int) -> int:
    """Workers for a run with ``breakable_bodies`` scene bodies that may break: one per core
    and at least four where workers are forked, no more than there are such bodies (none
    when nothing breaks). A run cutting its pieces in this process leaves the second core
    idle (every piece's cut waits for its parent's); a body and its pieces stay in one
    worker, and the splits' costs differ by tenfold, so more workers than cores even out
    the load. On 2 cores the 13 rings run within 5 % of each other with two, four or six
    workers (paired runs: 2 against 4 0.98x, 6 against 4 0.95x) and take 10.0 s inline
    against 8.0 s with four, the frames waiting for every cut. Where a worker is a new
    interpreter (no fork), one for every two cores past the first two: its
    imports cost the frame loop more on fewer cores than the cuts it takes off it."""
    cores = os.cpu_count() or 1
    wanted = max(4, cores) if FORK else max(0, cores - 2) // 2
    return min(wanted, max(0, breakable_bodies))


def _done(value) -> Future:
    future = Future()
    future.set_result(value)
    return future


class InProcessSurfaces:
    """The surface stage in this process, behind :class:`SurfaceWorkers`' interface."""

    count = 0  # (worker processes)

    def __init__(self):
        self.stage = SurfaceStage()

    def add_body(self, body: int, model, surface) -> Future:
        return _done(self.stage.add_body(body, model, surface))

    def cut(self, fracture) -> Future:
        return _done(self.stage.cut(fracture))

    def render_of(self, body: int):
        return self.stage.render_of(body)

    @property
    def cuts(self) -> list:
        return self.stage.cuts

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


def _fork_worker(request_read: int, answer_write: int) -> _Forked:
    """A worker forked from this process: it starts with this process' modules imported (a
    started interpreter spends about 0.8 s importing them). A daemon: an idle one left at
    exit is ended, not waited for."""
    process = multiprocessing.get_context("fork").Process(
        target=_serve_forked, args=(request_read, answer_write, os.getpid()), daemon=True)
    process.start()
    return _Forked(process)


def _serve_forked(request_read: int, answer_write: int, parent: int) -> None:
    """The forked worker's life: it never touches what it inherited of the simulation
    (Taichi's runtime, the other workers' pipes: closed), and leaves without the parent's
    exit handlers (multiprocessing ends a forked child with os._exit)."""
    from ..geometry.workers import die_with_parent
    from .worker import serve

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
    serve(os.fdopen(request_read, "rb"), os.fdopen(answer_write, "wb"))


def _max_fd() -> int:
    try:
        return os.sysconf("SC_OPEN_MAX")
    except (ValueError, OSError):
        return 65536


class _Worker:
    """One worker process: a writer thread feeds it requests (a large request must not hold
    up the frame loop while the worker is busy), a reader thread settles their futures."""

    def __init__(self):
        # Pipes of their own: what a library prints at import (Taichi's banner) goes to
        # the worker's stdout, which is not the channel.
        request_read, request_write = os.pipe()
        answer_read, answer_write = os.pipe()
        try:
            if FORK:
                self.process = _fork_worker(request_read, answer_write)
            else:
                self.process = subprocess.Popen(
                    [sys.executable, "-m", "taichi_frac.surfaces.worker", str(os.getpid()), str(request_read),
                     str(answer_write)], pass_fds=(request_read, answer_write), stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL)
        finally:
            os.close(request_read)
            os.close(answer_write)
        self.requests = os.fdopen(request_write, "wb")
        self.answers = os.fdopen(answer_read, "rb")
        self.pending: dict[int, Future] = {}
        self.lock = threading.Lock()
        self.outbox: queue.SimpleQueue = queue.SimpleQueue()
        self.load = 0  # tets of the bodies it holds, for choosing a worker
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


#: Worker processes idle between runs of this process, for the next run to take: their
#: memos (``stage._ROOT_SURFACES``, ``stage._CUTS``) serve a repeated run's bodies and splits
#: as this process' own serve a run without workers. They end with this process.
_IDLE: list = []


def _take_workers(count: int) -> list:
    """``count`` workers: idle ones first (in the order they were first started, so that a
    repeated run routes its bodies as before), then new ones."""
    alive = [w for w in _IDLE if w.process.poll() is None]
    _IDLE.clear()
    taken, spare = alive[:count], alive[count:]
    for worker in spare:
        worker.close()
    taken += [_Worker() for _ in range(count - len(taken))]
    for worker in taken:
        worker.load = 0
        worker.tell("reset", None)  # (a new run's body ids: nothing of the last run's bodies)
    return taken


class SurfaceWorkers:
    """The surface stage in ``count`` worker processes (each body and its pieces in one).

    ``cuts``: (seconds, counts) of each finished cut that cut a render solid, in the order
    the splits were asked for.
    """

    def __init__(self, count: int):
        if count < 1:
            raise ValueError(f"count = {count}: at least one worker")
        self.count = count
        self._workers = _take_workers(count)
        self._route: dict[int, _Worker] = {}
        self._tasks = itertools.count()
        self._cut_futures: list[Future] = []

    def add_body(self, body: int, model, surface) -> Future:
        worker = min(self._workers, key=lambda w: w.load)
        worker.load += model.tet_count
        self._route[body] = worker
        # Without trimesh's cache: a spatial index built here does not survive pickling.
        surface = None if surface is None else surface.copy(include_cache=False)
        return worker.submit(next(self._tasks), "add_body", (body, model, surface))

    def cut(self, fracture) -> Future:
        worker = self._route.pop(fracture.parent)
        for child in fracture.children:
            self._route[child] = worker
        future = worker.submit(next(self._tasks), "cut", CutRequest.of(fracture))
        self._cut_futures.append(future)
        return future

    def render_of(self, body: int):
        raise RuntimeError("the render solids live in the worker processes: run with surface_workers = 0 "
                           "(Simulation(..., surface_workers=0)) to read them")

    @property
    def cuts(self) -> list:
        done = [f.result() for f in self._cut_futures if f.done() and f.exception() is None]
        return [(r.seconds, r.counts) for r in done if r.counts]

    def close(self, cancel: bool = False) -> None:
        """Leave the workers idle for the next run in this process once their queued work is
        done, or end them at once (``cancel``: their results are no longer wanted)."""
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
    for worker in idle:
        worker.close()
    deadline = time.monotonic() + timeout
    for worker in idle:
        while worker.process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        if worker.process.poll() is None:
            worker.kill()


atexit.register(close_idle_workers)
