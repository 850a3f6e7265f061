"""The piece-surface stage: what the cache draws of every body, cut anew at each split.

A scene object's surface is the artist's own (its render solid, ``solid.py``) with the
shading of its source surface; a split cuts the parent's render solid along the cracks
(``cut.cut_render_solid``) into one closed surface per piece. :class:`SurfaceStage` does
that work in one process and keeps no record of bodies: it holds the render solids it made
by the keys the requests give them (``front.py`` names every body's solid), a scene
object's solid rebuilt from the arrays a request brings where it has none
(``solid.PortableSolid``), and the memos a repeated run's splits are taken from.
"""

from __future__ import annotations

import atexit
import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from ..memo import remember
from ..model import BodyModel
from . import cut as _cut
from .mesh import fragment_surface, render_surface, root_faces_of, surface_corner_attributes
from .solid import PortableSolid, render_solid_from_surface, render_solid_from_tets

#: Scene objects' starts made in this process (``BodyStart``, the render solid), by what they
#: are made from (the shading key, ``front._content_key``). The next run of an object in
#: this process (a sweep's variants) takes the start made once: finding the corner shading
#: (closest points on the source surface) and the render solid are most of a body's set-up.
#: The oldest go first past this many.
ROOT_SURFACES_KEPT = 64
_ROOT_SURFACES: dict[str, tuple] = {}
#: Splits cut in this process, by what they cut (``CutRequest.cut_key``): (the pieces' render
#: solids, the cut's counts, the pieces' surfaces), all read-only. A run repeated in one
#: process (a second ``Simulation(scene).run()``, a sweep's variant that changes what does
#: not touch the splits) meets the same splits and takes their pieces made once: the cuts are
#: most of what a run with a cache costs besides the physics. The oldest go first past this
#: many (the 13 rings make about 40 splits a run; a sweep's worker, whose variants meet other
#: splits, keeps no more than this many pieces' solids alive).
CUTS_KEPT = 128
_CUTS: dict[str, tuple] = {}


@atexit.register
def _forget_made() -> None:
    # The memos' solids go before the interpreter takes manifold3d down: nanobind counts
    # those still alive then as leaked, and says so on stderr.
    _ROOT_SURFACES.clear()
    _CUTS.clear()


@dataclass(frozen=True, eq=False)
class BodySurface:
    """One body's render mesh as the cache writer takes it, in the body frame. F faces, V vertices.

    Attributes:
        vertices: (V,3) [m]; unused vertices are allowed (the writer drops them).
        faces: (F,3) vertex indices, outward winding.
        inner: (F,) bool, crack faces.
        normals: (F,3,3) per-corner normals (NaN: the face's flat normal), or None.
        uvs: (F,3,2) per-corner UVs (NaN on crack faces), or None.
        face_peak: (F,) [Pa] the largest principal stress the material under each face has
            seen at a split, or None (a body that never broke).
        shade_inner: the crack faces carry their own shading (a cut render solid's do).
    """

    vertices: np.ndarray
    faces: np.ndarray
    inner: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None
    face_peak: np.ndarray | None = None
    shade_inner: bool = False


@dataclass(frozen=True, eq=False)
class BodyStart:
    """A scene object's start in the surface stage.

    Attributes:
        surface: its BodySurface.
        render: the arrays of its render solid (``solid.PortableSolid``).
        shading: (normals (F,3,3), UVs (F,3,2) or None) of its tets' boundary faces, read off
            its source surface, or (None, None) for an object given as tets: what a piece
            the cut gives no part shows.
    """

    surface: BodySurface
    render: PortableSolid
    shading: tuple


@dataclass(frozen=True, eq=False)
class PieceSurfaces:
    """The surfaces of one split's pieces.

    Attributes:
        surfaces: one BodySurface per piece, in the order of ``Fracture.children``.
        seconds: [s] wall time of the render solid's cut (0 without one).
        counts: the cut's counts (``cut.cut_render_solid``), empty without one.
        renders: per piece whether it has a render solid (False: it shows its tets'
            boundary), held by the stage that cut it under the piece's key.
    """

    surfaces: list
    seconds: float = 0.0
    counts: dict | None = None
    renders: list | None = None


@dataclass(frozen=True, eq=False)
class CutRequest:
    """What a split's cut needs, and nothing the World holds, so that it can travel to a
    worker process.

    Attributes:
        cut_key: names the cut (``front.py``: the parent's key and this request's content);
            piece_keys: the keys the pieces' render solids are held under.
        parent_key: the key of the parent's render solid, or None (it shows its tets'
            boundary: nothing to cut); render: the arrays of a scene object's render solid
            (``solid.PortableSolid``), which any stage rebuilds, or None for a piece's,
            which the stage that cut it holds.
        shading: the parent's scene object's shading (``BodyStart.shading``), or the key of
            the shading the stage holds; shading_key: that key.
        tet_peak: (T,) [Pa] the largest principal stress each of the parent's tets has seen
            at a split, this one included.
        model: the parent's BodyModel; options: its FractureOptions.
        fragment_tets: the split's pieces as parent tet indices (``FractureResult``).
        cracks: the analysis' CrackPlane / RingCrack list.
        models: the pieces' BodyModels; roots: their root models; parent_tets: each piece's
            tets in the parent.
        replay: the cuts (CutRequests) that made the parent's solid, from a scene object's
            or a solid the stage holds down, for a stage that does not hold it: they are cut
            again here first (each cut gives the same bytes in any process).
    """

    cut_key: str
    piece_keys: list
    parent_key: str | None
    render: PortableSolid | None
    shading: object
    shading_key: str
    tet_peak: np.ndarray
    model: BodyModel
    options: object
    fragment_tets: list
    cracks: list
    models: list
    roots: list
    parent_tets: list
    replay: tuple = ()

    @staticmethod
    def digest(hasher, shading_key: str, *, model, tet_peak, fragment_tets, cracks, models, parent_tets, options,
               roots=None) -> None:
        """Feed ``hasher`` (hashlib) what a cut's result depends on besides the parent's
        render solid (the request's fields by name; ``roots`` follow from the models): the
        parent's particles, the pieces' tets and origins, the cracks, the peak stresses, the
        options the cut reads and the shading key."""
        arrays = [model.particle_position, tet_peak, *fragment_tets, *[m.com_in_source for m in models],
                  *parent_tets]
        for crack in cracks:
            hasher.update(type(crack).__name__.encode())
            arrays.append(np.concatenate([np.ravel(np.asarray(getattr(crack, f.name), dtype=np.float64))
                                          for f in dataclasses.fields(crack)]))
        for array in arrays:
            array = np.ascontiguousarray(array)
            hasher.update(f"{array.dtype}{array.shape}".encode())
            hasher.update(array.tobytes())
        o = options
        hasher.update(repr((o.crack_roughness, o.crack_roughness_scale, o.seed, o.crack_fit_rounds,
                            o.crack_fit_min_tets, shading_key)).encode())


class SurfaceStage:
    """Makes scene bodies' surfaces and cuts render solids, in one process.

    It holds render solids by key until they are cut (a scene object's stays: its copies in a
    scene share it), and each scene object's shading by key.
    """

    def __init__(self):
        self._held: dict[str, object] = {}

    def holds(self, key: str) -> bool:
        return key in self._held

    def render_of(self, key: str):
        """The render solid held under ``key`` (``solid.RenderSolid``), or None."""
        return self._held.get(key)

    def add_body(self, model: BodyModel, surface, key: str) -> BodyStart:
        """A scene object's start: ``surface`` is its source surface (a trimesh.Trimesh in
        the model's source frame, ``PrepareReport.surface``), or None for an object given as
        tets, which shows its tets' boundary; its shading and render solid are held under
        ``key`` (and ``key`` + "/render")."""
        if key not in _ROOT_SURFACES:
            if surface is None:
                shading = (None, None)
                render = render_solid_from_tets(model)
            else:
                from ..geometry.surface_attributes import boundary_corner_attributes

                corners = model.vertices[model.surface_faces] + model.com_in_source
                shading = boundary_corner_attributes(surface, corners)
                render = render_solid_from_surface(surface, model.com_in_source, model.spacing)
            start = BodyStart(self._surface(render, model, model, None, shading), render.portable, shading)
            remember(_ROOT_SURFACES, key, (start, render), ROOT_SURFACES_KEPT)
        start, render = _ROOT_SURFACES[key]
        self._held[key] = start.shading
        self._held[key + "/render"] = render
        return start

    def cut(self, request: CutRequest) -> PieceSurfaces:
        """The pieces' surfaces of a split: the parent's render solid cut along its cracks,
        each piece carrying the peak stress its tets have seen."""
        for ancestor in request.replay:
            self.cut(ancestor)
        shading = request.shading
        if isinstance(shading, str):
            shading = self._held[shading]
        else:
            self._held[request.shading_key] = shading
        render = None
        if request.parent_key is not None:
            render = self._held.get(request.parent_key)
            if render is None and request.render is None:
                raise RuntimeError(f"no render solid held under {request.parent_key}: a piece's split goes to the "
                                   "stage that cut the piece")
            if render is None:  # (a scene object's solid this stage has not built)
                render = self._held[request.parent_key] = request.render.rebuilt()
        seconds = 0.0
        made = _CUTS.get(request.cut_key)
        if made is None:
            renders, counts = [None] * len(request.models), {}
            if render is not None:
                options = request.options
                t = time.perf_counter()
                renders, counts = _cut.cut_render_solid(
                    render, request.model, request.fragment_tets, request.cracks,
                    [m.com_in_source for m in request.models], roughness=options.crack_roughness,
                    roughness_scale=options.crack_roughness_scale, seed=options.seed,
                    fit_rounds=options.crack_fit_rounds, fit_min_tets=options.crack_fit_min_tets)
                seconds = time.perf_counter() - t
            surfaces = [self._surface(piece, model, root, request.tet_peak[tets], shading) for model, root, tets, piece
                        in zip(request.models, request.roots, request.parent_tets, renders)]
            made = (tuple(renders), counts, tuple(surfaces))
            if render is not None:
                remember(_CUTS, request.cut_key, made, CUTS_KEPT)
        renders, counts, surfaces = made
        if request.render is None and request.parent_key is not None:
            del self._held[request.parent_key]  # (a piece's solid: cut once)
        for key, piece in zip(request.piece_keys, renders):
            if piece is not None:
                self._held[key] = piece
        return PieceSurfaces(list(surfaces), seconds, counts, [piece is not None for piece in renders])

    @staticmethod
    def _surface(render, model: BodyModel, root: BodyModel, tet_peak, shading) -> BodySurface:
        if render is not None:
            vertices, faces, inner, normals, uvs, face_peak = render_surface(render, model, tet_peak)
            return BodySurface(vertices, faces, inner, normals, uvs, face_peak, shade_inner=True)
        # A piece the render solid gave no part to: its tets' boundary.
        face_peak = None if tet_peak is None else tet_peak[model.surface_face_tet]
        root_faces = root_faces_of(model, root)  # (both calls below need it)
        vertices, faces, inner = fragment_surface(model, root, root_faces)
        normals = uvs = None
        root_normals, root_uvs = shading
        if root_normals is not None:
            normals, uvs = surface_corner_attributes(model, root, root_normals, root_uvs, root_faces)
        return BodySurface(vertices, faces, inner, normals, uvs, face_peak)
