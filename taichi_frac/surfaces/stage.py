"""The piece-surface stage: what the cache draws of every body, cut anew at each split.

A scene object's surface is the artist's own (its render solid, ``solid.py``) with the
shading of its source surface; a split cuts the parent's render solid along the cracks
(``cut.cut_render_solid``) into one closed surface per piece. The frame loop
(``simulation.py``) calls :meth:`SurfaceStage.add_body` for each scene object and
:meth:`SurfaceStage.cut` after each split; the recorder (``io/recorder.py``) writes the
:class:`BodySurface` it is handed.
"""

from __future__ import annotations

import atexit
import dataclasses
import hashlib
import time
from dataclasses import dataclass

import numpy as np

from ..model import BodyModel
from . import cut as _cut
from .mesh import fragment_surface, render_surface, root_faces_of, surface_corner_attributes
from .solid import render_solid_from_surface, render_solid_from_tets

#: Scene bodies' surfaces made in this process, by what they are made from (``_content_key``):
#: (shading, render solid, BodySurface), all read-only. The copies of one object in a scene,
#: and the next run of it in this process (a sweep's variants), take the surface made once:
#: finding the corner shading (closest points on the source surface) and the render solid
#: are most of a body's set-up. The oldest go first past this many.
ROOT_SURFACES_KEPT = 64
_ROOT_SURFACES: dict[str, tuple] = {}
#: Splits cut in this process, by what they cut (``_cut_key``): (the cut render solid, the
#: pieces' render solids, the cut's counts), all read-only. A run repeated in one process (a
#: second ``Simulation(scene).run()``, a sweep's variant that changes what does not touch
#: the splits) meets the same splits and takes their pieces made once: the cuts are most of
#: what a run with a cache costs besides the physics. The oldest go first past this many
#: (the 13 rings make about 30 splits a run; a sweep's worker, whose variants meet other
#: splits, keeps no more than this many pieces' solids alive).
CUTS_KEPT = 128
_CUTS: dict[tuple, tuple] = {}


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
class PieceSurfaces:
    """The surfaces of one split's pieces.

    Attributes:
        surfaces: one BodySurface per piece, in the order of ``Fracture.children``.
        seconds: [s] wall time of the render solid's cut (0 without one).
        counts: the cut's counts (``cut.cut_render_solid``), empty without one.
    """

    surfaces: list
    seconds: float = 0.0
    counts: dict | None = None


@dataclass(frozen=True, eq=False)
class CutRequest:
    """What a split's cut needs of a ``fracture.stage.Fracture``, and nothing the World
    holds, so that it can travel to a worker process.

    Attributes:
        parent: the parent's body id; model: its BodyModel; options: its FractureOptions.
        fragment_tets: the split's pieces as parent tet indices (``FractureResult``).
        cracks: the analysis' CrackPlane / RingCrack list.
        principal_stress: (T,) [Pa] the largest principal stress at the parent's tets.
        children: the pieces' body ids; models: their BodyModels; roots: their root models;
        parent_tets: each piece's tets in the parent.
    """

    parent: int
    model: BodyModel
    options: object
    fragment_tets: list
    cracks: list
    principal_stress: np.ndarray
    children: list
    models: list
    roots: list
    parent_tets: list

    @classmethod
    def of(cls, fracture) -> "CutRequest":
        rec = fracture.parent_record
        return cls(parent=fracture.parent, model=rec.model, options=rec.fracture,
                   fragment_tets=list(fracture.split.fragment_tets), cracks=list(fracture.analysis.cracks),
                   principal_stress=fracture.analysis.particle_principal_stress,
                   children=list(fracture.children), models=[r.model for r in fracture.children_records],
                   roots=[r.root for r in fracture.children_records],
                   parent_tets=[p.parent_tets for p in fracture.pieces])


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


def _cut_key(render, request: CutRequest) -> tuple:
    """What a split's cut depends on: the render solid cut (by identity: the memo keeps it
    alive, and a repeated run's parents are the same objects, from ``_ROOT_SURFACES`` and
    earlier cuts), the parent's particles, the pieces' tets and origins, the cracks and the
    options the cut reads."""
    digest = hashlib.sha256()
    arrays = [request.model.particle_position, *request.fragment_tets, *[m.com_in_source for m in request.models]]
    for crack in request.cracks:
        digest.update(type(crack).__name__.encode())
        arrays.append(np.concatenate([np.ravel(np.asarray(getattr(crack, f.name), dtype=np.float64))
                                      for f in dataclasses.fields(crack)]))
    for array in arrays:
        array = np.ascontiguousarray(array)
        digest.update(f"{array.dtype}{array.shape}".encode())
        digest.update(array.tobytes())
    o = request.options
    return (id(render), digest.hexdigest(), o.crack_roughness, o.crack_roughness_scale, o.seed, o.crack_fit_rounds,
            o.crack_fit_min_tets)


class SurfaceStage:
    """Holds each live body's render solid and shading, and cuts them when a body breaks.

    Per body id: its render solid (``solid.RenderSolid``, None for a piece the cut gave no
    part to: it shows its tets' boundary), its root's boundary shading and the peak stress
    each of its tets has seen at a split. ``cuts``: per split that cut a render solid,
    (seconds, the cut's counts).
    """

    def __init__(self):
        self._render: dict[int, object] = {}
        self._shading: dict[int, tuple] = {}
        self._tet_peak: dict[int, np.ndarray] = {}
        self.cuts: list[tuple[float, dict]] = []

    def add_body(self, body: int, model: BodyModel, surface) -> BodySurface:
        """A scene object's surface: ``surface`` is its source surface (a trimesh.Trimesh in
        the model's source frame, ``PrepareReport.surface``), or None for an object given as
        tets, which shows its tets' boundary."""
        key = _content_key(model, surface)
        if key not in _ROOT_SURFACES:
            if surface is None:
                self._shading[body] = (None, None)
                self._render[body] = render_solid_from_tets(model)
            else:
                from ..geometry.surface_attributes import boundary_corner_attributes

                corners = model.vertices[model.surface_faces] + model.com_in_source
                self._shading[body] = boundary_corner_attributes(surface, corners)
                self._render[body] = render_solid_from_surface(surface, model.com_in_source, model.spacing)
            while len(_ROOT_SURFACES) >= ROOT_SURFACES_KEPT:
                del _ROOT_SURFACES[next(iter(_ROOT_SURFACES))]
            _ROOT_SURFACES[key] = (self._shading[body], self._render[body], self._surface(body, model, model))
        self._shading[body], self._render[body], made = _ROOT_SURFACES[key]
        return made

    def render_of(self, body: int):
        """The render solid of a live body (``solid.RenderSolid``) or None."""
        return self._render.get(body)

    def cut(self, fracture) -> PieceSurfaces:
        """The pieces' surfaces of a split (a ``fracture.stage.Fracture`` or its
        :class:`CutRequest`): the parent's render solid cut along its cracks, each piece
        carrying the peak stress its tets have seen."""
        request = fracture if isinstance(fracture, CutRequest) else CutRequest.of(fracture)
        parent = request.parent
        peak_parent = np.maximum(self._tet_peak.pop(parent, np.zeros(request.model.tet_count)),
                                 request.principal_stress)
        render = self._render.pop(parent, None)
        shading = self._shading.pop(parent, (None, None))
        renders, seconds, counts = [None] * len(request.children), 0.0, {}
        if render is not None:
            options = request.options
            t = time.perf_counter()
            key = _cut_key(render, request)
            if key not in _CUTS:
                renders, counts = _cut.cut_render_solid(
                    render, request.model, request.fragment_tets, request.cracks,
                    [m.com_in_source for m in request.models], roughness=options.crack_roughness,
                    roughness_scale=options.crack_roughness_scale, seed=options.seed,
                    fit_rounds=options.crack_fit_rounds, fit_min_tets=options.crack_fit_min_tets)
                while len(_CUTS) >= CUTS_KEPT:
                    del _CUTS[next(iter(_CUTS))]
                _CUTS[key] = (render, renders, counts)
            _render, renders, counts = _CUTS[key]
            renders = list(renders)
            seconds = time.perf_counter() - t
            self.cuts.append((seconds, counts))
        surfaces = []
        for child, model, root, tets, piece_render in zip(request.children, request.models, request.roots,
                                                          request.parent_tets, renders):
            self._render[child] = piece_render
            self._shading[child] = shading
            self._tet_peak[child] = peak_parent[tets]
            surfaces.append(self._surface(child, model, root))
        return PieceSurfaces(surfaces, seconds, counts)

    def _surface(self, body: int, model: BodyModel, root: BodyModel) -> BodySurface:
        tet_peak = self._tet_peak.get(body)
        render = self._render.get(body)
        if render is not None:
            vertices, faces, inner, normals, uvs, face_peak = render_surface(render, model, tet_peak)
            return BodySurface(vertices, faces, inner, normals, uvs, face_peak, shade_inner=True)
        # A piece the render solid gave no part to: its tets' boundary.
        face_peak = None if tet_peak is None else tet_peak[model.surface_face_tet]
        root_faces = root_faces_of(model, root)  # (both calls below need it)
        vertices, faces, inner = fragment_surface(model, root, root_faces)
        normals = uvs = None
        root_normals, root_uvs = self._shading.get(body, (None, None))
        if root_normals is not None:
            normals, uvs = surface_corner_attributes(model, root, root_normals, root_uvs, root_faces)
        return BodySurface(vertices, faces, inner, normals, uvs, face_peak)
