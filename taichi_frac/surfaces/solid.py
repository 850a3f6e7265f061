"""A body's render solid: the artist's closed surface as an exact-arithmetic solid, and the
records a broken piece's surface carries (its crack surfaces, its mesh for the cache).

``cut.py`` cuts it along the cracks; the constants here say how thin the cuts are
and what is dropped, and the vertex property columns say what each corner carries.

A scene object's render solid is built from arrays (:class:`PortableSolid`) that travel
between processes: the boolean library builds the same solid from the same arrays in every
process, so its cut gives the same bytes wherever it is made. A cut piece's solid is not
rebuilt from its own mesh: the library would tidy what a cut leaves (slivers a hairline
slab wide), which moved tiny pieces' crack faces by up to a spacing; it stays in the
process that cut it (``pool.py``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import manifold3d as m3
import numpy as np
import trimesh

from ..geometry.surface_attributes import input_corner_normals
from ..fracture.cracks import tangent_frame as crack_frame
from .layout import CRACK, NORMAL, PROPERTY_COUNT, UV

#: Slab thickness as a fraction of the particle spacing: the two pieces of a crack are this
#: far apart and each crack face lies half of it off its plane (1e-4 spacings: far below
#: what a render shows, far above the boolean library's float64 round-off).
SLAB_THICKNESS_FACTOR = 2e-4

#: Thickness [particle spacings] of the slab that joins a piece's own parts again where a
#: crack's slab cut through the piece: three slabs, so it overlaps the parts on both sides.
WELD_THICKNESS_FACTOR = 3 * SLAB_THICKNESS_FACTOR
#: Half the side [particle spacings] of the square a weld covers about each crossing.
WELD_REACH_FACTOR = 1.0

#: How far [particle spacings] a crack's slab reaches from the bond crossing nearest each of
#: its points: beyond the surface where the plane meets it obliquely, and across the gaps
#: between crossings where the mesher grades the tets coarse inside (the spacing is their
#: mean V^(1/3), which the many small surface tets pull down: a teapot's inner tets are
#: 3-4 spacings across, its crossings up to 11 spacings apart). A gap the slab leaves joins
#: the two pieces' parts into one. Where a crossing inside one piece is nearer, its Voronoi
#: cell still stops the slab (``crack_slabs.SLAB_PAST_FACTOR`` past) halfway to it.
SLAB_REACH_FACTOR = 8.0

#: Parts of the cut solid smaller than this [particle spacings cubed] are dropped: chips
#: where two slabs' edges cross the surface, far below a render's resolution.
DUST_VOLUME_FACTOR = 1e-2

#: Largest gap [particle spacings] between a ring crack's sphere and its polygon.
SPHERE_SAGITTA_FACTOR = 0.02



@dataclass(frozen=True)
class CrackSurface:
    """The crack a piece's inner faces lie on, in the piece's body frame: a plane
    (``radius`` None) through ``point`` (3,) [m] with unit ``normal`` (3,), or the sphere of
    ``radius`` [m] about ``point`` (a ring crack)."""

    point: np.ndarray
    normal: np.ndarray
    radius: float | None = None

    def shifted(self, offset: np.ndarray) -> "CrackSurface":
        return CrackSurface(self.point - offset, self.normal, self.radius)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) [m] signed distance of ``points`` (N,3) from the crack surface."""
        if self.radius is None:
            return (points - self.point) @ self.normal
        return np.linalg.norm(points - self.point, axis=1) - self.radius


@dataclass(frozen=True, eq=False)
class RenderSolid:
    """A body's render surface, body frame [m]: ``solid`` a closed manifold whose vertex
    properties carry the artist's corner normals and UVs and, on crack faces, the index of
    their crack in ``cracks``; ``spacing`` [m] the body's particle spacing. ``volume_scale``
    (a broken piece's): the unbroken body's render volume over its tets' volume, what a
    piece's render solid should hold per volume of its tets; None for an unbroken body's
    (its own volume over its tets'). ``portable``: the arrays a scene object's solid was built
    from (:class:`PortableSolid`), None for a cut piece's."""

    solid: m3.Manifold
    cracks: tuple
    spacing: float
    volume_scale: float | None = None
    portable: object = field(default=None, repr=False)

    def moved(self, offset) -> "RenderSolid":
        """The same solid in a frame whose origin is at ``offset`` (3,) [m] of this one."""
        offset = np.asarray(offset, dtype=np.float64)
        return RenderSolid(self.solid.translate(tuple(-offset)), tuple(c.shifted(offset) for c in self.cracks),
                           self.spacing, self.volume_scale)


@dataclass(frozen=True, eq=False)
class PieceMesh:
    """A render solid as a triangle mesh for the cache: vertices (V,3) [m], faces (F,3)
    outward, face_is_inner (F,) bool, normals (F,3,3) unit and uvs (F,3,2) per corner (UVs:
    the artist's on outer faces, [m] along the crack's tangent frame on inner ones),
    face_crack (F,) index into ``cracks`` (-1 on outer faces, HULL_FACE on a carved piece's
    faces that lie on no crack)."""

    vertices: np.ndarray
    faces: np.ndarray
    face_is_inner: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    face_crack: np.ndarray
    cracks: tuple


@dataclass(frozen=True, eq=False)
class PortableSolid:
    """The arrays a scene object's render solid (``solid.RenderSolid``) is built from.

    Attributes:
        vert_properties: (V,P) float64, the solid's vertices: x, y, z [m] then the property
            columns (``layout.py``).
        tri_verts: (F,3) uint64 vertex indices, outward.
        merge_from, merge_to: (M,) uint64, the property vertices that share a position.
        spacing: [m] the body's particle spacing.
    """

    vert_properties: np.ndarray
    tri_verts: np.ndarray
    merge_from: np.ndarray
    merge_to: np.ndarray
    spacing: float

    @classmethod
    def of_arrays(cls, vert_properties, tri_verts, merge_from, merge_to, spacing: float) -> "PortableSolid":
        arrays = (np.ascontiguousarray(vert_properties, dtype=np.float64),
                  np.ascontiguousarray(tri_verts, dtype=np.uint64).reshape(-1, 3),
                  np.ascontiguousarray(merge_from, dtype=np.uint64), np.ascontiguousarray(merge_to, dtype=np.uint64))
        return cls(*arrays, float(spacing))

    def rebuilt(self) -> RenderSolid:
        """The render solid these arrays are of, as every process builds it."""
        solid = m3.Manifold(m3.Mesh64(vert_properties=self.vert_properties, tri_verts=self.tri_verts,
                                      merge_from_vert=self.merge_from, merge_to_vert=self.merge_to))
        if solid.status() != m3.Error.NoError:
            raise ValueError(f"the render surface is not a closed manifold ({solid.status()})")
        return RenderSolid(solid, (), self.spacing, portable=self)


def _built(vertices: np.ndarray, faces: np.ndarray, properties: np.ndarray, spacing: float) -> RenderSolid:
    """The render solid of a triangle mesh whose corners carry ``properties`` (F,3,P): one
    property vertex per distinct (position, properties) row, shared positions merged; built
    from arrays any process can be sent (:class:`PortableSolid`)."""
    rows = np.concatenate([vertices[faces].reshape(-1, 3), properties.reshape(-1, properties.shape[2])], axis=1)
    unique, corner = np.unique(rows, axis=0, return_inverse=True)
    position_of = np.unique(unique[:, :3], axis=0, return_inverse=True)[1].reshape(-1)
    first = np.full(position_of.max() + 1, -1, dtype=np.int64)
    first[position_of[::-1]] = np.arange(len(unique))[::-1]  # each position's first property vertex
    target = first[position_of]
    distinct = np.nonzero(target != np.arange(len(unique)))[0]
    return PortableSolid.of_arrays(unique, corner.reshape(-1, 3), distinct, target[distinct], spacing).rebuilt()


def render_solid_from_surface(surface: trimesh.Trimesh, origin, spacing: float) -> RenderSolid:
    """The render solid of the artist's closed, outward-wound ``surface`` (source frame,
    metres; its UVs where it has them, else zeros) in a body frame whose origin lies at
    ``origin`` (3,) [m] of the source frame; ``spacing`` [m] the body's particle spacing."""
    vertices = np.asarray(surface.vertices, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    faces = np.asarray(surface.faces, dtype=np.int64)
    props = np.zeros((len(faces), 3, PROPERTY_COUNT - 3))
    props[:, :, NORMAL.start - 3:NORMAL.stop - 3] = input_corner_normals(surface)
    uv = getattr(surface.visual, "uv", None)
    if uv is not None and len(uv) == len(vertices):
        props[:, :, UV.start - 3:UV.stop - 3] = np.asarray(uv, dtype=np.float64)[faces]
    props[:, :, CRACK - 3] = -1.0
    return _built(vertices, faces, props, float(spacing))


def render_solid_from_tets(model) -> RenderSolid:
    """The render solid of a body with no artist's surface (a tet-mesh file): its tets'
    boundary, flat-shaded, no UVs."""
    faces = np.asarray(model.surface_faces, dtype=np.int64)
    tri = model.vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    props = np.zeros((len(faces), 3, PROPERTY_COUNT - 3))
    props[:, :, 0:3] = normal[:, None, :]
    props[:, :, CRACK - 3] = -1.0
    return _built(model.vertices, faces, props, float(model.spacing))


def tangent_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The crack's in-plane axes (the analysis' own choice, fracture/cracks.py)."""
    return _tangent_frame_of(*(float(c) for c in normal))


@functools.lru_cache(maxsize=4096)
def _tangent_frame_of(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    # Kept per normal: every piece's mesh asks again for each crack it inherited, and a
    # scene's few hundred cracks repeat thousands of times (numpy's small-array overhead).
    e1, e2 = crack_frame(np.array([x, y, z]))
    e1.flags.writeable = e2.flags.writeable = False
    return e1, e2


def solid_arrays(solid: m3.Manifold) -> tuple[np.ndarray, np.ndarray]:
    """``solid`` as arrays: (props (V,P) [m then the vertex properties], float64: x, y, z first;
    triangles (F,3) int64 into props, outward)."""
    mesh = solid.to_mesh64()
    return np.asarray(mesh.vert_properties, dtype=np.float64), np.asarray(mesh.tri_verts, dtype=np.int64)


def difference(solid: m3.Manifold, cutters) -> m3.Manifold:
    """``solid`` less each of the manifolds ``cutters``. Where the cutters hold more triangles
    than the solid, they are taken away one at a time, each difference made at once: the
    library's batch difference first joins the cutters, at a cost that follows all their
    triangles, while one at a time each costs about the solid's (a piece's tets grown by
    the trim's reach, dozens of overlapping hulls: 0.40 s against 0.70 s over the 13 rings'
    trims). A few small cutters go in one batch, which is no slower. The same solid either
    way, but not the same triangles: a cut whose parts a vote of their faces hands out keeps
    the batch (``cut._cut_parts``)."""
    cutters = list(cutters)
    if not cutters:
        return solid
    if sum(cutter.num_tri() for cutter in cutters) <= solid.num_tri():
        return m3.Manifold.batch_boolean([solid, *cutters], m3.OpType.Subtract)
    for cutter in cutters:
        solid = solid - cutter
        solid.num_tri()  # (made now: the library joins a chain of pending differences into one batch)
    return solid


def without_dust(solid: m3.Manifold, spacing: float) -> list:
    """The shells of ``solid`` but those under DUST_VOLUME_FACTOR ``spacing`` cubed: chips
    where slabs' or cells' faces cross the surface, and the flat slivers of no volume a union
    leaves where a weld's or a bridge's faces lie on the parts' own."""
    return [shell for shell in solid.decompose() if shell.volume() >= DUST_VOLUME_FACTOR * spacing**3]


def with_crack_index(slab: m3.Manifold, index: int) -> m3.Manifold:
    """``slab`` with every vertex's crack-index property set to ``index`` (normals and UVs
    zero: the piece's inner faces get theirs in ``piece_mesh``)."""
    mesh = slab.to_mesh64()
    positions = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    props = np.zeros((len(positions), PROPERTY_COUNT))
    props[:, :3] = positions
    props[:, CRACK] = index
    return m3.Manifold(m3.Mesh64(vert_properties=props,
                                 tri_verts=np.array(mesh.tri_verts, dtype=np.uint64)))
