"""The piece-surface stage where the simulation does not wait for it.

:class:`SurfaceWorkers` runs :class:`~taichi_frac.surfaces.stage.SurfaceStage` in worker
processes (``worker.py``): a body and every piece of it go to one worker, which keeps their
render solids; requests return futures at once, so the frame loop goes on while a split's
pieces are cut, and the recorder writes them when they are done. :class:`InProcessSurfaces`
is the same interface in this process (futures already done). Both give the same surfaces:
the same code runs on the same arrays.
"""

from __future__ import annotations

import itertools
import os
import queue
import subprocess
import sys
import threading
from concurrent.futures import Future

from .stage import CutRequest, SurfaceStage
from .worker import read_frame, write_frame


class SurfaceWorkerError(RuntimeError):
    """A piece-surface worker failed: its error's traceback, or how the process ended."""


def default_worker_count(breakable_bodies: int) -> int:
    """Workers for a run with ``breakable_bodies`` scene bodies that may break: one for every
    two cores past the first two, no more than there are such bodies. None on a machine of
    two or three cores, nor when nothing breaks: there each worker's start (its imports) and
    its share of the cores cost the frame loop more than the cuts it takes off it (the
    13 rings on 2 cores ran slower with 1 or 2 workers than without, ``bench startup``)."""
    spare = max(0, (os.cpu_count() or 1) - 2) // 2
    return min(spare, max(0, breakable_bodies))


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


class _Worker:
    """One worker process: a writer thread feeds it requests (a large request must not hold
    up the frame loop while the worker is busy), a reader thread settles their futures."""

    def __init__(self):
        # Pipes of their own: what a library prints at import (Taichi's banner) goes to
        # the worker's stdout, which is not the channel.
        request_read, request_write = os.pipe()
        answer_read, answer_write = os.pipe()
        try:
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


class SurfaceWorkers:
    """The surface stage in ``count`` worker processes (each body and its pieces in one).

    ``cuts``: (seconds, counts) of each finished cut that cut a render solid, in the order
    the splits were asked for.
    """

    def __init__(self, count: int):
        if count < 1:
            raise ValueError(f"count = {count}: at least one worker")
        self.count = count
        self._workers = [_Worker() for _ in range(count)]
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
        """End the workers: once their queued work is done, or at once (``cancel``)."""
        for worker in self._workers:
            worker.kill() if cancel else worker.close()
