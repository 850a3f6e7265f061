"""What a run writes to its cache, beside the writer (``cache.CacheWriter``): each body's
surface when it appears, its pose every frame, its end when it breaks, and the peak stress
of the impact that made each piece.

The simulation hands it everything: the bodies' surfaces as futures (the surface stage,
``surfaces/pool.py``, may still be cutting them), each frame's poses and the fracture
stage's splits. It writes them to the cache in the order they happened, as soon as the
surfaces they need are done: a frame waits in memory (its poses: a few numbers a body)
until every body alive in it has its surface. It computes nothing and changes nothing of
the simulation.
"""

from __future__ import annotations

import collections
import concurrent.futures
import time


class CacheRecorder:
    """Keeps a cache in step with a run.

    Args:
        path: the cache file; lock: its ``io.output.OutputLock``.
        fps: frames per second of the run; checkpoint_every [frames], checkpoint_seconds [s]:
            the scene's ``[output]`` rules for rewriting the file while the run goes on (0:
            only the final write and Ctrl-C's).

    ``wait_seconds``: [s] how long :meth:`close` waited for surfaces still being made.
    """

    def __init__(self, path, *, fps: float, checkpoint_every: int, checkpoint_seconds: float, lock=None):
        self.path = path
        self.fps = fps
        self.checkpoint_every = checkpoint_every
        self.checkpoint_seconds = checkpoint_seconds
        self.lock = lock
        self.writer = None
        self.wait_seconds = 0.0
        self._cache_ids: dict[int, int] = {}  # body id -> the writer's fragment id
        self._log: collections.deque = collections.deque()  # what is not written yet, in order

    def open(self, bodies) -> None:
        """Create the writer and add ``bodies``, born at frame 0: (body id, name, look
        (``options.MaterialLook``), future of its ``surfaces.BodySurface``) each. The caller
        then writes frame 0's poses."""
        from .cache import CacheWriter

        self.writer = CacheWriter(self.path, fps=self.fps, start_frame=0,
                                  checkpoint_every=self.checkpoint_every or 2**31 - 1,
                                  checkpoint_seconds=self.checkpoint_seconds, lock=self.lock)
        for body, name, look, surface in bodies:
            self._log.append((surface, self._add, (body, name, 0, look, None, None, 0.0)))
        self._flush()

    def write_frame(self, frame: int, ids, state) -> None:
        """The poses of the live bodies ``ids`` (``state``: their World ``body_state``); then
        what is ready of the log is written, with a checkpoint of the file when one is due:
        the writer's every-N-frames rule; right after the first simulated frame; then
        whenever ``checkpoint_seconds`` of wall time have passed, however slow the frames
        (the first frame compiles kernels: minutes on a cold cache). A kill then loses at
        most that much work."""
        poses = (frame, list(ids), state["position"].copy(), state["orientation"].copy())
        self._log.append((None, self._poses, poses))
        self._flush()

    def record_fracture(self, fracture, surfaces) -> None:
        """A ``fracture.stage.Fracture``: the parent's end, and each piece's birth with its
        surface (``surfaces``: future of the split's ``surfaces.PieceSurfaces``), impact and
        peak stress."""
        self._log.append((surfaces, self._pieces, fracture))
        self._flush()

    @property
    def pending(self) -> bool:
        """Whether entries wait for surfaces still being made (after :meth:`close`: ones it
        gave up on, at a second Ctrl-C)."""
        return bool(self._log)

    def close(self, complete: bool, on_wait=None) -> None:
        """Write the file, once every surface asked for is done; ``complete``: every requested
        frame was written. A Ctrl-C while it waits writes what is done so far, marked
        incomplete. ``on_wait``: callable(left, splits) told how many of the splits' surfaces
        it found unfinished are left, when it starts waiting and as each is written."""
        if self.writer is None:
            return
        t = time.perf_counter()
        try:
            self._flush(wait=True, on_wait=on_wait)
        except KeyboardInterrupt:
            complete = False
            self._flush()
        finally:
            self.wait_seconds += time.perf_counter() - t
            self.writer.close(complete=complete and not self._log)

    def _flush(self, wait: bool = False, on_wait=None) -> None:
        """Write the log's entries in order up to the first whose surface is not done
        (``wait``: all of them, waiting for each, telling ``on_wait`` as ``close`` says)."""
        waiting, told = None, None  # (the futures unfinished when the wait began; the count last told)
        while self._log:
            future, write, args = self._log[0]
            if future is not None and not future.done():
                if not wait:
                    return
                if on_wait is not None and waiting is None:
                    waiting = [f for f, _, _ in self._log if f is not None and not f.done()]
                    told = len(waiting)
                    on_wait(told, len(waiting))
                concurrent.futures.wait([future])
            write(args, None if future is None else future.result())
            self._log.popleft()
            if waiting:
                left = sum(1 for f in waiting if not f.done())
                if left < told:
                    told = left
                    on_wait(left, len(waiting))

    def _add(self, args, surface) -> None:
        body, name, birth_frame, look, parent, impact, peak = args
        self._cache_ids[body] = self.writer.add_fragment(
            name, surface.vertices, surface.faces, surface.inner, birth_frame, parent=parent, impact=impact,
            peak_principal_stress=float(peak), face_peak_stress=surface.face_peak, normals=surface.normals,
            uvs=surface.uvs, shade_inner=surface.shade_inner, look=look,
        )

    def _poses(self, args, _) -> None:
        frame, ids, positions, orientations = args
        self.writer.write_frame(frame, [self._cache_ids[b] for b in ids], positions, orientations)
        if self.checkpoint_every == 0 or self.writer.frames_since_write == 0:
            return
        if frame == 1 or (self.checkpoint_seconds > 0 and self.writer.seconds_since_write >= self.checkpoint_seconds):
            self.writer.checkpoint()

    def _pieces(self, fracture, pieces) -> None:
        parent_cache = self._cache_ids.pop(fracture.parent)
        self.writer.end_fragment(parent_cache, fracture.frame)
        for piece, child, child_rec, surface in zip(fracture.pieces, fracture.children, fracture.children_records,
                                                    pieces.surfaces):
            impact = None if piece.impact is None else dict(point=piece.impact.point, force=piece.impact.force)
            # (pieces share their body's look: the writer takes it from the parent)
            self._add((child, child_rec.name, fracture.frame, None, parent_cache, impact,
                       piece.peak_principal_stress), surface)

