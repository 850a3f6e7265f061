"""What a run writes to its cache, beside the writer (``cache.CacheWriter``): each body's
surface when it appears, its pose every frame, its end when it breaks, and the peak stress
its material has seen (the cache's per-face stress), carried from parent to pieces.

The simulation hands it the bodies at the start, each frame's poses and the fracture
stage's splits (``fracture/stage.py``); nothing here changes the simulation.
"""

from __future__ import annotations

import time
import weakref

import numpy as np

from ..model import BodyModel
from ..options import LOOKS

# The shading attributes of a prepared model's boundary faces, kept while the model lives:
# a process that runs many variants of one scene reuses its models (Simulation(prepare=...),
# a sweep's worker), and finding them (closest points on the source surface) was nearly all
# of such a Simulation's set-up (1.43 of 1.44 s for the ring, profiled on a loaded machine).
# Read-only once computed.
_CORNER_ATTRIBUTES: "weakref.WeakKeyDictionary[BodyModel, tuple]" = weakref.WeakKeyDictionary()


def root_corner_attributes(model: BodyModel, report) -> tuple:
    """(normals (Fr,3,3), uvs (Fr,3,2) or None) of ``model``'s boundary faces from its source surface."""
    if model not in _CORNER_ATTRIBUTES:
        from ..geometry.surface_attributes import boundary_corner_attributes

        corners = model.vertices[model.surface_faces] + model.com_in_source
        _CORNER_ATTRIBUTES[model] = boundary_corner_attributes(report.surface, corners)
    return _CORNER_ATTRIBUTES[model]


class CacheRecorder:
    """Keeps a cache in step with a run.

    Args:
        path: the cache file; lock: its ``io.output.OutputLock``.
        fps: frames per second of the run; checkpoint_every [frames], checkpoint_seconds [s]:
            the scene's ``[output]`` rules for rewriting the file while the run goes on (0:
            only the final write and Ctrl-C's).
        records: body id -> ``fracture.stage.BodyRecord``, the simulation's registry (read
            for each frame's cache ids; the recorder sets ``cache_id``, the shading and the
            render solid on them).

    ``render_cuts``: per split that cut a render solid, (seconds, geometry/piece_surface.py's
    counts).
    """

    def __init__(self, path, *, fps: float, checkpoint_every: int, checkpoint_seconds: float, records: dict,
                 lock=None):
        self.path = path
        self.fps = fps
        self.checkpoint_every = checkpoint_every
        self.checkpoint_seconds = checkpoint_seconds
        self.records = records
        self.lock = lock
        self.writer = None
        self.render_cuts: list[tuple[float, dict]] = []
        # body id -> (T,) [Pa] the largest principal stress each tet of its material has
        # seen at a split, for its pieces' per-face stress.
        self._tet_peak_stress: dict[int, np.ndarray] = {}

    def prepare_body(self, rec, report) -> None:
        """Give a scene object's record what the cache draws of it: the shading of its
        source surface and its render solid (``report``: its PrepareReport)."""
        from ..geometry.render_solid import render_solid_from_surface, render_solid_from_tets

        model = rec.model
        if report.surface is not None:
            rec.root_normals, rec.root_uvs = root_corner_attributes(model, report)
        rec.render = (render_solid_from_tets(model) if report.surface is None else
                      render_solid_from_surface(report.surface, model.com_in_source, model.spacing))

    def open(self) -> None:
        """Create the writer and add every body in ``records`` (born at frame 0); the
        caller then writes frame 0's poses."""
        from .cache import CacheWriter

        self.writer = CacheWriter(self.path, fps=self.fps, start_frame=0,
                                  checkpoint_every=self.checkpoint_every or 2**31 - 1,
                                  checkpoint_seconds=self.checkpoint_seconds, lock=self.lock)
        for rec in self.records.values():
            self._add(rec, birth_frame=0)

    def write_frame(self, frame: int, ids, state) -> None:
        """The poses of the live bodies ``ids`` (``state``: their World ``body_state``), and a
        checkpoint of the file when one is due: the writer's every-N-frames rule; right after
        the first simulated frame; then whenever ``checkpoint_seconds`` of wall time have
        passed, however slow the frames (the first frame compiles kernels: minutes on a cold
        cache). A kill then loses at most that much work."""
        cache_ids = [self.records[b].cache_id for b in ids]
        self.writer.write_frame(frame, cache_ids, state["position"], state["orientation"])
        if self.checkpoint_every == 0 or self.writer.frames_since_write == 0:
            return
        if frame == 1 or (self.checkpoint_seconds > 0 and self.writer.seconds_since_write >= self.checkpoint_seconds):
            self.writer.checkpoint()

    def record_fracture(self, fracture) -> None:
        """A ``fracture.stage.Fracture``: the parent's end, and each piece's surface (the
        parent's render solid cut along the cracks), birth, impact and peak stress."""
        rec, analysis, split, frame = fracture.parent_record, fracture.analysis, fracture.split, fracture.frame
        peak_parent = np.maximum(self._tet_peak_stress.get(fracture.parent, np.zeros(rec.model.tet_count)),
                                 analysis.particle_principal_stress)
        renders = [None] * len(fracture.pieces)
        if rec.render is not None:
            from ..geometry.piece_surface import cut_render_solid

            t_cut = time.perf_counter()
            renders, counts = cut_render_solid(
                rec.render, rec.model, split.fragment_tets, analysis.cracks,
                [p.model.com_in_source for p in fracture.pieces], roughness=rec.fracture.crack_roughness,
                roughness_scale=rec.fracture.crack_roughness_scale, seed=rec.fracture.seed,
                fit_rounds=rec.fracture.crack_fit_rounds, fit_min_tets=rec.fracture.crack_fit_min_tets)
            self.render_cuts.append((time.perf_counter() - t_cut, counts))
        self.writer.end_fragment(rec.cache_id, frame)
        for piece, child, child_rec, render in zip(fracture.pieces, fracture.children, fracture.children_records,
                                                   renders):
            child_rec.render = render
            tet_peak = peak_parent[piece.parent_tets]
            self._tet_peak_stress[child] = tet_peak
            impact = None if piece.impact is None else dict(point=piece.impact.point, force=piece.impact.force)
            self._add(child_rec, frame, parent_cache=rec.cache_id, impact=impact, peak=piece.peak_principal_stress,
                      tet_peak=tet_peak)

    def close(self, complete: bool) -> None:
        """Write the file; ``complete``: every requested frame was written."""
        if self.writer is not None:
            self.writer.close(complete=complete)

    def _add(self, rec, birth_frame: int, parent_cache=None, impact=None, peak=0.0, tet_peak=None):
        from .fragment_mesh import fragment_surface, render_surface, root_faces_of, surface_corner_attributes

        look = None if parent_cache is not None else LOOKS[rec.material.look]  # (pieces share the body's)
        if rec.render is not None:
            vertices, faces, inner, normals, uvs, face_peak = render_surface(rec.render, rec.model, tet_peak)
            rec.cache_id = self.writer.add_fragment(
                rec.name, vertices, faces, inner, birth_frame, parent=parent_cache, impact=impact,
                peak_principal_stress=float(peak), face_peak_stress=face_peak, normals=normals, uvs=uvs,
                shade_inner=True, look=look,
            )
            return
        # A piece the render solid gave no part to: its tets' boundary.
        face_peak = None if tet_peak is None else tet_peak[rec.model.surface_face_tet]
        root_faces = root_faces_of(rec.model, rec.root)  # (both calls below need it)
        vertices, faces, inner = fragment_surface(rec.model, rec.root, root_faces)
        normals = uvs = None
        if rec.root_normals is not None:
            normals, uvs = surface_corner_attributes(rec.model, rec.root, rec.root_normals, rec.root_uvs, root_faces)
        rec.cache_id = self.writer.add_fragment(
            rec.name, vertices, faces, inner, birth_frame, parent=parent_cache, impact=impact,
            peak_principal_stress=float(peak), face_peak_stress=face_peak, normals=normals, uvs=uvs,
            look=look,
        )
