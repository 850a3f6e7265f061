"""The surface stage as the frame loop sees it: futures of bodies' and pieces' surfaces, and
the record of every live body that a process needs to cut it.

:class:`SurfaceFront` keeps, in the process that runs the frames, each live body's render
solid as a key (and, for a scene object's, the arrays it is built from,
``solid.PortableSolid``), a future until the job that makes it is done; the shading of
its scene object and the peak stress its tets have seen. A split becomes a
``stage.CutRequest`` once its parent's render solid is made, and goes to whichever
``stage.SurfaceStage`` the subclass chooses (``pool.py``: this process', or a worker's).
Keys name content, not bodies: a scene object's solid by what it is made from, a cut by its
parent's key and what the cut reads, a piece by its cut's key and its place in it; so a
repeated run's splits have the keys of the first run's, and a stage's memos answer them.
"""

from __future__ import annotations

import dataclasses
import hashlib
from concurrent.futures import Future
from typing import NamedTuple

import numpy as np

from ..model import BodyModel
from .stage import CutRequest


class BodySolid(NamedTuple):
    """A live body's render solid: held under ``key``; ``render`` the arrays of a scene
    object's (any stage rebuilds it), None for a piece's (the stage that cut it holds it)."""

    key: str
    render: object


def _content_key(model: BodyModel, surface) -> str:
    """A digest of what a scene body's surface is made from: its model's boundary and frame,
    and its source surface (None: its tets)."""
    digest = hashlib.sha256()
    arrays = [model.vertices, model.surface_faces, model.com_in_source, np.array([model.spacing])]
    if surface is not None:
        arrays += [surface.vertices, surface.faces]
        uv = getattr(getattr(surface, "visual", None), "uv", None)
        if uv is not None:
            arrays.append(np.asarray(uv))
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype}{array.shape}".encode())
        digest.update(array.tobytes())
    digest.update(b"tets" if surface is None else b"surface")
    return digest.hexdigest()


class Job:
    """A piece of work for a ``stage.SurfaceStage``: a scene object's start (``kind``
    "add_body", ``payload`` (model, surface, shading key)) or a split's cut ("cut", a
    CutRequest). ``size`` [tets] orders the queue (with ``SurfaceFront.waiting_work``);
    ``needs``: the key of the piece's solid it cuts (a stage that does not hold it cuts it
    again first, see ``SurfaceFront.replay``), else None; ``key``: what names its result in
    a stage's memos (the shading key, the cut key); ``makes``: the keys of the solids it
    makes (a cut's pieces'). ``done(result)`` and ``failed(error)`` settle it; ``queued``
    and ``started`` [s, monotonic]: when it was queued and started."""

    def __init__(self, kind: str, payload, size: int, key: str, done, failed, needs=None, makes=()):
        self.kind, self.payload, self.size, self.key = kind, payload, size, key
        self.done, self.failed, self.needs, self.makes = done, failed, needs, tuple(makes)
        self.queued = self.started = 0.0

    def sent(self, holds) -> object:
        """The payload as sent to a stage for which ``holds(key)`` says what it holds: the
        shading it holds goes by its key."""
        return shading_by_key(self.payload, holds) if self.kind == "cut" else self.payload


def shading_by_key(request: CutRequest, holds) -> CutRequest:
    """``request`` with its shading named by its key where ``holds(key)`` says the stage it
    goes to holds it."""
    if holds(request.shading_key):
        return dataclasses.replace(request, shading=request.shading_key)
    return request


class SurfaceFront:
    """The futures of every body's surface; subclasses run the jobs (``_run``)."""

    def __init__(self):
        self._render: dict[int, Future] = {}  # body -> future of its BodySolid (None: no render solid)
        self._key: dict[int, str] = {}  # body -> the key its render solid has or will have
        self._shading_key: dict[int, str] = {}  # body -> its scene object's shading key
        self._shading: dict[str, tuple] = {}  # shading key -> (normals, uvs)
        self._peak: dict[int, np.ndarray] = {}  # body -> (T,) [Pa] its tets' peak stress
        self._starting: dict[str, Future] = {}  # shading key -> future of its stage.BodyStart
        self._origin: dict[str, tuple] = {}  # a piece's key -> (the CutRequest that made it, its cut's seconds)
        # A piece's key -> the splits of it asked for before its solid is made: (their size
        # [tets], their pieces' keys) each; see ``waiting_work``.
        self._waiting: dict[str, list] = {}
        self._cut_futures: list[Future] = []

    def _run(self, job: Job) -> None:
        raise NotImplementedError

    def add_body(self, body: int, model: BodyModel, surface) -> Future:
        """Future of a scene object's ``stage.BodySurface``: ``surface`` its source surface
        (``PrepareReport.surface``) or None (an object given as tets)."""
        key = _content_key(model, surface)
        out, render = Future(), Future()
        self._render[body], self._key[body], self._shading_key[body] = render, key + "/render", key

        def settle(start: Future):
            if start.exception() is not None:
                render.set_exception(start.exception())
                out.set_exception(start.exception())
                return
            self._shading[key] = start.result().shading
            render.set_result(BodySolid(key + "/render", start.result().render))
            out.set_result(start.result().surface)

        start = self._starting.get(key)
        if start is None:
            # (the copies of one object in a scene take the first one's start)
            start = self._starting[key] = Future()
            self._run(Job("add_body", (model, surface, key), model.tet_count, key, start.set_result,
                          start.set_exception, makes=(key + "/render",)))
        start.add_done_callback(settle)
        return out

    def cut(self, fracture) -> Future:
        """Future of a split's ``stage.PieceSurfaces`` (a ``fracture.stage.Fracture``)."""
        record = fracture.parent_record
        parent = fracture.parent
        peak = np.maximum(self._peak.pop(parent, np.zeros(record.model.tet_count)),
                          fracture.analysis.particle_principal_stress)
        shading_key = self._shading_key.pop(parent)
        parent_key = self._key.pop(parent)
        parent_render = self._render.pop(parent)
        fields = dict(tet_peak=peak, model=record.model, options=record.fracture,
                      fragment_tets=list(fracture.split.fragment_tets), cracks=list(fracture.analysis.cracks),
                      models=[r.model for r in fracture.children_records],
                      roots=[r.root for r in fracture.children_records],
                      parent_tets=[p.parent_tets for p in fracture.pieces])
        digest = hashlib.sha256(parent_key.encode())
        CutRequest.digest(digest, shading_key, **fields)
        cut_key = digest.hexdigest()
        piece_keys = [hashlib.sha256(f"{cut_key}/{k}".encode()).hexdigest() for k in range(len(fracture.children))]
        renders = []
        for child, piece, key in zip(fracture.children, fracture.pieces, piece_keys):
            self._peak[child] = peak[piece.parent_tets]
            self._shading_key[child], self._key[child] = shading_key, key
            self._render[child] = future = Future()
            renders.append(future)
        out = Future()
        self._cut_futures.append(out)

        def failed(error):
            for future in (*renders, out):
                if not future.done():
                    future.set_exception(error)

        made = []  # (the request, once the parent's solid is known)

        def done(result):
            for future, key, has in zip(renders, piece_keys, result.renders):
                if has:
                    self._origin[key] = (made[0], result.seconds)
                future.set_result(BodySolid(key, None) if has else None)
            out.set_result(result)

        size = record.model.tet_count
        waiting = None
        if not parent_render.done():
            waiting = (size, piece_keys)
            self._waiting.setdefault(parent_key, []).append(waiting)

        def ready(parent_done: Future):
            if waiting is not None:  # (no longer waiting; only an order's hint, so never an error)
                listed = self._waiting.get(parent_key, [])
                if waiting in listed:
                    listed.remove(waiting)
                if not listed:
                    self._waiting.pop(parent_key, None)
            if parent_done.exception() is not None:
                failed(parent_done.exception())
                return
            solid = parent_done.result()
            request = CutRequest(cut_key=cut_key, piece_keys=piece_keys,
                                 parent_key=None if solid is None else solid.key,
                                 render=None if solid is None else solid.render,
                                 shading=self._shading[shading_key], shading_key=shading_key, **fields)
            made.append(request)
            needs = solid.key if solid is not None and solid.render is None else None
            self._run(Job("cut", request, size, cut_key, done, failed, needs=needs, makes=piece_keys))

        parent_render.add_done_callback(ready)
        return out

    def waiting_work(self, keys) -> int:
        """[tets] the splits already asked for that wait, directly or through their own
        pieces, for the solids ``keys`` (a job's ``makes``): a job that holds up a chain of
        splits goes before a larger one that holds up none, so the last split of a run is not
        left to start late behind work any worker could have done."""
        total, stack = 0, list(keys)
        while stack:
            for size, pieces in tuple(self._waiting.get(stack.pop(), ())):  # (a copy: splits come in meanwhile)
                total += size
                stack.extend(pieces)
        return total

    def replay(self, key: str, holds) -> tuple[list, float] | None:
        """The cuts that made the piece's solid ``key``, from the nearest solid ``holds(key)``
        says a stage holds (or a scene object's) down, and their seconds [s]: what a stage
        that does not hold the solid cuts again first (``stage.CutRequest.replay``). None
        where the record does not reach such a solid."""
        chain, seconds = [], 0.0
        while not holds(key):
            if key not in self._origin:
                return None
            request, took = self._origin[key]
            chain.append(request)
            seconds += took
            if request.render is not None:  # (a scene object's solid: any stage builds it)
                break
            key = request.parent_key
        return chain[::-1], seconds

    @property
    def cuts(self) -> list:
        """(seconds, counts) of each finished split that cut a render solid, in the order the
        splits were asked for."""
        done = [f.result() for f in self._cut_futures if f.done() and f.exception() is None]
        return [(r.seconds, r.counts) for r in done if r.counts]
