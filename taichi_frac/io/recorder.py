"""What a run writes to its cache, beside the writer (``cache.CacheWriter``): each body's
surface when it appears, its pose every frame, its end when it breaks, and the peak stress
of the impact that made each piece.

The simulation hands it everything: the bodies' surfaces (``surfaces.SurfaceStage``), each
frame's poses and the fracture stage's splits with their pieces' surfaces. It computes
nothing and changes nothing of the simulation.
"""

from __future__ import annotations


class CacheRecorder:
    """Keeps a cache in step with a run.

    Args:
        path: the cache file; lock: its ``io.output.OutputLock``.
        fps: frames per second of the run; checkpoint_every [frames], checkpoint_seconds [s]:
            the scene's ``[output]`` rules for rewriting the file while the run goes on (0:
            only the final write and Ctrl-C's).
    """

    def __init__(self, path, *, fps: float, checkpoint_every: int, checkpoint_seconds: float, lock=None):
        self.path = path
        self.fps = fps
        self.checkpoint_every = checkpoint_every
        self.checkpoint_seconds = checkpoint_seconds
        self.lock = lock
        self.writer = None
        self._cache_ids: dict[int, int] = {}  # body id -> the writer's fragment id

    def open(self, bodies) -> None:
        """Create the writer and add ``bodies``, born at frame 0: (body id, name, look
        (``options.MaterialLook``), ``surfaces.BodySurface``) each. The caller then writes
        frame 0's poses."""
        from .cache import CacheWriter

        self.writer = CacheWriter(self.path, fps=self.fps, start_frame=0,
                                  checkpoint_every=self.checkpoint_every or 2**31 - 1,
                                  checkpoint_seconds=self.checkpoint_seconds, lock=self.lock)
        for body, name, look, surface in bodies:
            self._add(body, name, surface, birth_frame=0, look=look)

    def write_frame(self, frame: int, ids, state) -> None:
        """The poses of the live bodies ``ids`` (``state``: their World ``body_state``), and a
        checkpoint of the file when one is due: the writer's every-N-frames rule; right after
        the first simulated frame; then whenever ``checkpoint_seconds`` of wall time have
        passed, however slow the frames (the first frame compiles kernels: minutes on a cold
        cache). A kill then loses at most that much work."""
        cache_ids = [self._cache_ids[b] for b in ids]
        self.writer.write_frame(frame, cache_ids, state["position"], state["orientation"])
        if self.checkpoint_every == 0 or self.writer.frames_since_write == 0:
            return
        if frame == 1 or (self.checkpoint_seconds > 0 and self.writer.seconds_since_write >= self.checkpoint_seconds):
            self.writer.checkpoint()

    def record_fracture(self, fracture, surfaces) -> None:
        """A ``fracture.stage.Fracture``: the parent's end, and each piece's birth with its
        surface (``surfaces``: one ``surfaces.BodySurface`` per piece), impact and peak stress."""
        parent_cache = self._cache_ids.pop(fracture.parent)
        self.writer.end_fragment(parent_cache, fracture.frame)
        for piece, child, child_rec, surface in zip(fracture.pieces, fracture.children, fracture.children_records,
                                                    surfaces):
            impact = None if piece.impact is None else dict(point=piece.impact.point, force=piece.impact.force)
            # (pieces share their body's look: the writer takes it from the parent)
            self._add(child, child_rec.name, surface, fracture.frame, parent=parent_cache, impact=impact,
                      peak=piece.peak_principal_stress)

    def close(self, complete: bool) -> None:
        """Write the file; ``complete``: every requested frame was written."""
        if self.writer is not None:
            self.writer.close(complete=complete)

    def _add(self, body: int, name: str, surface, birth_frame: int, *, look=None, parent=None, impact=None,
             peak=0.0) -> None:
        self._cache_ids[body] = self.writer.add_fragment(
            name, surface.vertices, surface.faces, surface.inner, birth_frame, parent=parent, impact=impact,
            peak_principal_stress=float(peak), face_peak_stress=surface.face_peak, normals=surface.normals,
            uvs=surface.uvs, shade_inner=surface.shade_inner, look=look,
        )
