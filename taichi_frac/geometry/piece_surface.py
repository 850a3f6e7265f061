"""Render surfaces of broken pieces: the artist's surface outside, the crack's own surface inside.

The physics decides which pieces exist (tets joined by bonds, cut by crack discs and rings;
``fracture/fragments.py``); this module only gives each piece the surface an artist sees.
A body's *render solid* is the artist's closed surface (``PrepareReport.surface``, full
resolution, with its corner normals and UVs) as an exact-arithmetic ``manifold3d`` solid in
the body's frame. When the body breaks:

1. every crack that parts two different pieces becomes a cutter: the half-space on one side
   of its plane, or the ball inside a ring crack's sphere;
2. the render solid is split by the cutters into cells, but a cell only while its tets
   (by centroid) belong to two or more pieces and the cutter parts them rather than runs
   through one (``STRADDLING_SHARE``), so a piece's material is rarely split apart;
3. each connected cell goes to the piece holding most of its tets' volume; a piece with
   several cells gets them joined by two exact subtractions (solid less (solid less the
   cells): exact booleans do not glue solids that only touch);
4. a piece is trimmed to its tets' convex hull where it reaches more than
   ``HULL_SLACK_FACTOR`` spacings past it (two nearly parallel cracks leave a sliver cell
   running on past its piece), and a piece no cell went to (a few tets where cracks meet)
   is carved out of its neighbour as the hull of its tets.

So crack faces lie exactly on their crack plane (a ring crack's sphere: within its polygon's
sagitta), neighbouring pieces meet on it, and the outside is the artist's triangles clipped
at the crack faces, keeping their UVs and normals (interpolated where a triangle is cut);
inner faces get a planar projection along their crack as UVs and their own flat normal;
every piece is closed, manifold and outward wound (the boolean library guarantees it); a
piece that breaks again cuts its own render solid. Faces from the hull lie on no crack
(crack index ``HULL_FACE``).

``crack_roughness`` (FractureOptions) displaces a plane cutter's face along the crack normal
by smooth value noise, the same for both sides, so the two sides of a crack still fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh

from .surface_attributes import input_corner_normals

#: A cell holding no tet centroid (a chip where a crack grazes the surface) is labelled by a
#: vote of at most about this many of its faces (evenly spread over its list).
MAX_VOTING_FACES = 512

#: A vote whose winner has less than this share of the area is settled by the tets inside.
DECISIVE_VOTE = 0.8
#: How many tets (or points) in a part's box a winding-number check reads at most.
MAX_PROBED_TETS = 128

#: Parts smaller than this [particle spacings cubed] hold no tet: chips where two cracks
#: cross near the surface, far below a render's resolution.
DUST_VOLUME_FACTOR = 1e-2

#: A cutter parts a cell only where at most this share of the cell's tet volume lies in
#: pieces on both of its sides: elsewhere it runs through a piece, which it would split into
#: cells to be joined again.
STRADDLING_SHARE = 0.1

#: A piece's render solid is trimmed to its tets' convex hull only where it reaches more
#: than this [particle spacings] past it.
HULL_SLACK_FACTOR = 1.0

#: Largest gap [particle spacings] between a ring crack's sphere and its polygon.
SPHERE_SAGITTA_FACTOR = 0.02

# Vertex property columns after x, y, z: corner normal (3), UV (2), crack index (-1: the
# artist's surface).
_NORMAL = slice(3, 6)
_UV = slice(6, 8)
_CRACK = 8
_PROPERTY_COUNT = 9
#: The crack index of a carved piece's hull faces (inner faces on no crack).
HULL_FACE = -2


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
    their crack in ``cracks``; ``spacing`` [m] the body's particle spacing."""

    solid: m3.Manifold
    cracks: tuple
    spacing: float

    def moved(self, offset) -> "RenderSolid":
        """The same solid in a frame whose origin is at ``offset`` (3,) [m] of this one."""
        offset = np.asarray(offset, dtype=np.float64)
        return RenderSolid(self.solid.translate(tuple(-offset)), tuple(c.shifted(offset) for c in self.cracks),
                           self.spacing)


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


def _to_manifold(vertices: np.ndarray, faces: np.ndarray, properties: np.ndarray) -> m3.Manifold:
    """Manifold of a triangle mesh whose corners carry ``properties`` (F,3,P): one property
    vertex per distinct (position, properties) row, shared positions merged."""
    rows = np.concatenate([vertices[faces].reshape(-1, 3), properties.reshape(-1, properties.shape[2])], axis=1)
    unique, corner = np.unique(rows, axis=0, return_inverse=True)
    position_of = np.unique(unique[:, :3], axis=0, return_inverse=True)[1].reshape(-1)
    first = np.full(position_of.max() + 1, -1, dtype=np.int64)
    first[position_of[::-1]] = np.arange(len(unique))[::-1]  # each position's first property vertex
    target = first[position_of]
    distinct = np.nonzero(target != np.arange(len(unique)))[0]
    pairs = np.stack([distinct, target[distinct]], axis=1)
    mesh = m3.Mesh64(vert_properties=np.ascontiguousarray(unique, dtype=np.float64),
                     tri_verts=np.ascontiguousarray(corner.reshape(-1, 3), dtype=np.uint64),
                     merge_from_vert=np.ascontiguousarray(pairs[:, 0], dtype=np.uint64),
                     merge_to_vert=np.ascontiguousarray(pairs[:, 1], dtype=np.uint64))
    solid = m3.Manifold(mesh)
    if solid.status() != m3.Error.NoError:
        raise ValueError(f"the render surface is not a closed manifold ({solid.status()})")
    return solid


def render_solid_from_surface(surface: trimesh.Trimesh, origin, spacing: float) -> RenderSolid:
    """The render solid of the artist's closed, outward-wound ``surface`` (source frame,
    metres; its UVs where it has them, else zeros) in a body frame whose origin lies at
    ``origin`` (3,) [m] of the source frame; ``spacing`` [m] the body's particle spacing."""
    vertices = np.asarray(surface.vertices, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    faces = np.asarray(surface.faces, dtype=np.int64)
    props = np.zeros((len(faces), 3, _PROPERTY_COUNT - 3))
    props[:, :, _NORMAL.start - 3:_NORMAL.stop - 3] = input_corner_normals(surface)
    uv = getattr(surface.visual, "uv", None)
    if uv is not None and len(uv) == len(vertices):
        props[:, :, _UV.start - 3:_UV.stop - 3] = np.asarray(uv, dtype=np.float64)[faces]
    props[:, :, _CRACK - 3] = -1.0
    return RenderSolid(_to_manifold(vertices, faces, props), (), float(spacing))


def render_solid_from_tets(model) -> RenderSolid:
    """The render solid of a body with no artist's surface (a tet-mesh file): its tets'
    boundary, flat-shaded, no UVs."""
    faces = np.asarray(model.surface_faces, dtype=np.int64)
    tri = model.vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    props = np.zeros((len(faces), 3, _PROPERTY_COUNT - 3))
    props[:, :, 0:3] = normal[:, None, :]
    props[:, :, _CRACK - 3] = -1.0
    return RenderSolid(_to_manifold(model.vertices, faces, props), (), float(model.spacing))


def _value_noise(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """Smooth value noise in [-1, 1] of lattice coordinates (u, v), three octaves."""
    total = np.zeros_like(u)
    weight_sum = 0.0
    for octave in range(3):
        f, w = 2.0**octave, 0.5**octave
        x, y = u * f, v * f
        i, j = np.floor(x), np.floor(y)
        fx, fy = x - i, y - j
        sx, sy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)

        def lattice(a, b):
            h = np.sin(a * 127.1 + b * 311.7 + (seed + 17 * octave) * 74.7) * 43758.5453
            return 2.0 * (h - np.floor(h)) - 1.0

        top = lattice(i, j) * (1 - sx) + lattice(i + 1, j) * sx
        bottom = lattice(i, j + 1) * (1 - sx) + lattice(i + 1, j + 1) * sx
        total += w * (top * (1 - sy) + bottom * sy)
        weight_sum += w
    return total / weight_sum


def tangent_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The crack's in-plane axes (the analysis' own choice, fracture/cracks.py)."""
    from ..fracture.cracks import tangent_frame as crack_frame

    return crack_frame(normal)


def _plane_cutter(crack: CrackSurface, low, high, spacing: float, roughness: float, roughness_scale: float,
                  seed: int, index: int) -> m3.Manifold:
    """The half-space on the + side of a plane crack, as a box reaching past the solid's box
    (``low``, ``high`` (3,) [m]); its face on the plane carries crack index ``index`` and, when
    ``roughness`` > 0, is displaced along the normal by value noise of that amplitude [m]."""
    e1, e2 = tangent_frame(crack.normal)
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    reach = float(np.max(np.linalg.norm(corners - crack.point, axis=1))) + 2.0 * spacing + 2.0 * roughness
    box = m3.Manifold.cube((2.0 * reach, 2.0 * reach, reach)).translate((-reach, -reach, 0.0))
    if roughness > 0:
        box = box.refine_to_length(roughness_scale / 3.0)

        def displace(points):
            points = np.array(points, dtype=np.float64)
            on_plane = np.abs(points[:, 2]) < 1e-12 * reach
            noise = _value_noise(points[:, 0] / roughness_scale, points[:, 1] / roughness_scale, seed * 1009 + index)
            points[:, 2] += np.where(on_plane, roughness * noise, 0.0)
            return points

        box = box.warp_batch(displace)
    frame = np.column_stack([e1, e2, crack.normal, crack.point])  # (3,4): cutter frame -> body
    return _with_crack_index(box.transform(frame), index)


def _ball_cutter(crack: CrackSurface, spacing: float, index: int) -> m3.Manifold:
    """The ball inside a ring crack's sphere, its polygon within SPHERE_SAGITTA_FACTOR spacings."""
    sagitta = SPHERE_SAGITTA_FACTOR * spacing
    segments = int(np.ceil(np.pi / np.arccos(max(1.0 - sagitta / crack.radius, -1.0)))) + 4
    ball = m3.Manifold.sphere(crack.radius, min(segments, 512))
    return _with_crack_index(ball.translate(tuple(crack.point)), index)


def _side(crack: CrackSurface, points: np.ndarray) -> np.ndarray:
    """(N,) bool: ``points`` (N,3) on the cutter's side (+ side of a plane, inside a sphere)."""
    d = crack.distance(points)
    return d > 0 if crack.radius is None else d < 0


def _split_cells(solid: m3.Manifold, surfaces, cutters, model, labels: np.ndarray):
    """Cut ``solid`` by the cutters where they part different pieces: the connected cells,
    each with the tets whose centroids it holds ((n,) indices). A cell is cut only while its
    tets belong to two or more pieces (or dropped tets) and the cutter has tets on both
    sides, so a piece's material is rarely split into cells that would need joining again."""
    from .piece_checks import inside

    x = model.particle_position
    cells = [(solid, np.arange(len(x)))]
    for surface, cutter in zip(surfaces, cutters):
        side = _side(surface, x)
        cut = []
        for cell, tets in cells:
            mine = labels[tets]
            inner = side[tets]
            if np.all(mine == mine[0]) or not _parts_pieces(mine, inner, model.tet_volume[tets]):
                cut.append((cell, tets))
                continue
            for part, mask in zip(cell.split(cutter), (inner, ~inner)):
                if not part.is_empty():
                    cut.append((part, tets[mask]))
        cells = cut
    result = []
    for cell, tets in cells:
        parts = cell.decompose()
        if len(parts) == 1:
            result.append((cell, tets))
            continue
        free = np.ones(len(tets), dtype=bool)
        for part in sorted(parts, key=lambda part: part.volume()):
            box = np.asarray(part.bounding_box())
            near = np.nonzero(free & np.all((x[tets] >= box[:3]) & (x[tets] <= box[3:]), axis=1))[0]
            if len(near):
                mesh = part.to_mesh64()
                near = near[inside(x[tets[near]], np.asarray(mesh.vert_properties)[:, :3][
                    np.asarray(mesh.tri_verts, dtype=np.int64)])]
            free[near] = False
            result.append((part, tets[near]))
    return result


def _parts_pieces(tet_labels: np.ndarray, inner: np.ndarray, volume: np.ndarray) -> bool:
    """Does a cutter with ``inner`` (n,) tets on its side part pieces (``tet_labels`` (n,),
    tet ``volume`` (n,) [m^3]) rather than run through them: tets on both sides, and at most
    STRADDLING_SHARE of their volume in pieces that lie on both sides?"""
    if inner.all() or not inner.any():
        return False
    _, piece = np.unique(tet_labels, return_inverse=True)
    on = np.bincount(piece, weights=volume * inner)
    off = np.bincount(piece, weights=volume * ~inner)
    return np.minimum(on, off).sum() <= STRADDLING_SHARE * volume.sum()


def _label_cells(cells, model, labels, spacing):
    """Each cell's piece (-1: dropped tets) by the volume of the tets whose centroids it
    holds, and the centroid of its piece's largest tet there ((C,3), NaN where it holds none:
    such a cell, a chip where a crack grazes the surface, is labelled by a vote of its faces,
    ``_assign_parts``)."""
    owners = [None] * len(cells)
    probes = np.full((len(cells), 3), np.nan)
    for i, (_, tets) in enumerate(cells):
        if len(tets):
            votes = np.bincount(labels[tets] + 1, weights=model.tet_volume[tets])
            owners[i] = int(np.argmax(votes)) - 1
            winners = tets[labels[tets] == owners[i]]
            probes[i] = model.particle_position[winners[np.argmax(model.tet_volume[winners])]]
    unlabelled = [i for i, o in enumerate(owners) if o is None]
    if unlabelled:
        for i, o in zip(unlabelled, _assign_parts([cells[i][0] for i in unlabelled], model, labels, spacing)):
            owners[i] = o
    return owners, probes


def _with_crack_index(cutter: m3.Manifold, index: int) -> m3.Manifold:
    """``cutter`` with every vertex's crack-index property set to ``index`` (normals and UVs
    zero: the piece's inner faces get theirs in ``piece_mesh``)."""
    mesh = cutter.to_mesh64()
    positions = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    props = np.zeros((len(positions), _PROPERTY_COUNT))
    props[:, :3] = positions
    props[:, _CRACK] = index
    return m3.Manifold(m3.Mesh64(vert_properties=props,
                                 tri_verts=np.array(mesh.tri_verts, dtype=np.uint64)))


def _separating_cracks(model, bonds, labels, cracks) -> list[bool]:
    """For each crack: does it cut a bond between two different pieces? (A crack whose cuts
    all stayed inside one piece shapes nothing.)"""
    from ..fracture.cracks import CrackPlane, RingCrack

    x = model.particle_position
    a, b = x[bonds[:, 0]], x[bonds[:, 1]]
    separating = labels[bonds[:, 0]] != labels[bonds[:, 1]]
    result = []
    for crack in cracks:
        if isinstance(crack, CrackPlane):
            da, db = (a - crack.point) @ crack.normal, (b - crack.point) @ crack.normal
            cross = (da >= 0) != (db >= 0)
            t = da / np.where(cross, da - db, 1.0)
            offset = a + t[:, None] * (b - a) - crack.point
            cut = cross & (np.einsum("ij,ij->i", offset, offset) <= crack.extent**2)
        elif isinstance(crack, RingCrack):
            inside_a = np.einsum("ij,ij->i", a - crack.point, a - crack.point) < crack.radius**2
            inside_b = np.einsum("ij,ij->i", b - crack.point, b - crack.point) < crack.radius**2
            cut = inside_a != inside_b
        else:
            raise TypeError(f"unknown crack type {type(crack).__name__}")
        result.append(bool(np.any(cut & separating)))
    return result


def cut_render_solid(render: RenderSolid, model, fragment_tets, cracks, piece_origins, *,
                     roughness: float = 0.0, roughness_scale: float | None = None, seed: int = 0):
    """Cut a body's render solid along the cracks that broke it.

    Args:
        render: the body's render solid (``model``'s body frame).
        model: the body's BodyModel (tets, bonds, particle positions).
        fragment_tets: the pieces' tet index arrays (``FractureResult.fragment_tets``); tets
            in none (dropped) lose their part of the render solid.
        cracks: the ``CrackPlane``/``RingCrack`` list that cut the bonds.
        piece_origins: (F,3) [m] each piece's body-frame origin in ``model``'s frame (its
            ``com_in_source``).
        roughness: [m] crack-face noise amplitude (0: flat); roughness_scale [m] its
            wavelength (None: 4 particle spacings); seed: the noise's seed.

    Returns (pieces, stats): pieces a list of F RenderSolid or None (a piece that got no part
    of the render solid: the caller falls back to its tets' boundary); stats a dict of counts
    (slabs: the cracks cut along, parts: cells of their arrangement, unassigned_parts: cells
    of dropped tets, dust_parts: cells left out of every piece, empty_pieces, carved_pieces).
    """
    from ..fracture.cracks import CrackPlane

    spacing = render.spacing
    roughness_scale = 4.0 * spacing if roughness_scale is None else float(roughness_scale)
    labels = np.full(model.tet_count, -1, dtype=np.int64)
    for k, tets in enumerate(fragment_tets):
        labels[np.asarray(tets, dtype=np.int64)] = k
    bonds = np.asarray(model.bonds, dtype=np.int64)
    low, high = np.asarray(render.solid.bounding_box()).reshape(2, 3)

    new_cracks = list(render.cracks)
    surfaces, cutters = [], []
    for crack, separates in zip(cracks, _separating_cracks(model, bonds, labels, cracks)):
        if not separates:
            continue
        index = len(new_cracks)
        if isinstance(crack, CrackPlane):
            surface = CrackSurface(np.asarray(crack.point, float), np.asarray(crack.normal, float))
            cutter = _plane_cutter(surface, low, high, spacing, roughness, roughness_scale, seed, index)
        else:
            surface = CrackSurface(np.asarray(crack.point, float), np.zeros(3), float(crack.radius))
            cutter = _ball_cutter(surface, spacing, index)
        new_cracks.append(surface)
        surfaces.append(surface)
        cutters.append(cutter)
    cells = _split_cells(render.solid, surfaces, cutters, model, labels)
    owners, probes = _label_cells(cells, model, labels, spacing)
    solids = [_piece_of_cells(render.solid, cells, owners, probes, k, spacing) for k in range(len(fragment_tets))]
    stats = dict(slabs=len(cutters), parts=len(cells), unassigned_parts=int(sum(o == -1 for o in owners)),
                 dust_parts=int(sum(1 for o, p in zip(owners, probes) if o >= 0 and np.isnan(p[0]))))
    solids, carved = _carve_missing_pieces(solids, model, fragment_tets)
    stats["carved_pieces"] = carved
    solids = [None if solid is None else _within_hull(solid, model, np.asarray(tets, dtype=np.int64))
              for solid, tets in zip(solids, fragment_tets)]
    stats["empty_pieces"] = int(sum(s is None for s in solids))
    pieces = [None if solid is None else RenderSolid(solid, tuple(new_cracks), spacing).moved(origin)
              for solid, origin in zip(solids, np.asarray(piece_origins, dtype=np.float64).reshape(-1, 3))]
    return pieces, stats


def _piece_of_cells(solid: m3.Manifold, cells, owners, probes, k: int, spacing: float) -> m3.Manifold | None:
    """Piece ``k``'s render solid: the cells labelled ``k`` that hold one of its tets (chips
    without one, where a crack grazes the surface, are left out). Exact booleans do not glue
    solids that only touch, but subtract cleanly: several cells are joined as ``solid`` less
    (``solid`` less the cells), keeping the parts that hold the cells' tets."""
    own = [i for i, o in enumerate(owners) if o == k and not np.isnan(probes[i, 0])]
    if not own:
        own = [i for i, o in enumerate(owners) if o == k]
        return None if not own else m3.Manifold.compose([cells[i][0] for i in own])
    if len(own) == 1:
        return cells[own[0]][0]
    others = m3.Manifold.batch_boolean([solid, *(cells[i][0] for i in own)], m3.OpType.Subtract)
    joined = solid - others
    return _parts_holding(joined, probes[own], spacing) or m3.Manifold.compose([cells[i][0] for i in own])


def _parts_holding(solid: m3.Manifold, points: np.ndarray, spacing: float) -> m3.Manifold | None:
    """The connected parts of ``solid`` that hold any of ``points`` (N,3) [m] (None: none).
    Parts under DUST_VOLUME_FACTOR spacings cubed hold none; each part is asked about at
    most MAX_PROBED_TETS of the points in its box."""
    from .piece_checks import inside

    parts = solid.decompose()
    if len(parts) == 1:
        return parts[0]
    kept = []
    for part in parts:
        if part.volume() < DUST_VOLUME_FACTOR * spacing**3:
            continue
        box = np.asarray(part.bounding_box())
        near = points[np.all((points >= box[:3]) & (points <= box[3:]), axis=1)]
        if not len(near):
            continue
        near = near[:: max(1, len(near) // MAX_PROBED_TETS)]
        mesh = part.to_mesh64()
        if inside(near, np.asarray(mesh.vert_properties)[:, :3][np.asarray(mesh.tri_verts, dtype=np.int64)]).any():
            kept.append(part)
    if not kept:
        return None
    return kept[0] if len(kept) == 1 else m3.Manifold.compose(kept)


def _within_hull(solid: m3.Manifold, model, tets: np.ndarray) -> m3.Manifold:
    """``solid`` less what lies outside the convex hull of its piece's tets: a cell of the
    crack planes' arrangement can run on as a sliver past its piece (two nearly parallel
    cracks), where no tet of the piece is."""
    from scipy.spatial import ConvexHull

    corners = model.vertices[model.tets[tets]].reshape(-1, 3)
    centre = corners.mean(axis=0)
    grown = centre + (corners - centre) * (1.0 + 1e-6)
    mesh = solid.to_mesh64()
    equations = ConvexHull(grown).equations  # (H,4): outward unit normal, offset
    vertices = np.asarray(mesh.vert_properties)[:, :3]
    if np.all(vertices @ equations[:, :3].T + equations[:, 3] <= HULL_SLACK_FACTOR * model.spacing):
        return solid  # (the common case: no boolean needed)
    hull = _with_crack_index(m3.Manifold.hull_points(np.ascontiguousarray(grown)), HULL_FACE)
    kept = solid ^ hull
    if kept.is_empty():
        return solid
    return _parts_holding(kept, model.particle_position[tets], model.spacing) or kept


def _carve_missing_pieces(solids, model, fragment_tets):
    """A piece no cell went to (a few tets where cracks meet, outvoted in every cell) is
    carved out of the piece whose solid holds most of its tets: that solid's intersection
    with the convex hull of its tets becomes the piece, the rest stays. Its faces inside are
    then the hull's planes, not a crack's (crack index HULL_FACE). Returns (solids, count)."""
    from .piece_checks import inside

    solids, carved = list(solids), 0
    for k, tets in enumerate(fragment_tets):
        if solids[k] is not None:
            continue
        tets = np.asarray(tets, dtype=np.int64)
        probe = model.particle_position[tets[:: max(1, len(tets) // 16)]]
        best, best_count = None, 0
        for j, solid in enumerate(solids):
            if solid is None or j == k:
                continue
            lo, hi = (np.asarray(v) for v in (solid.bounding_box()[:3], solid.bounding_box()[3:]))
            near = np.all((probe >= lo) & (probe <= hi), axis=1)
            if not near.any():
                continue
            mesh = solid.to_mesh64()
            triangles = np.asarray(mesh.vert_properties)[:, :3][np.asarray(mesh.tri_verts, dtype=np.int64)]
            count = int(inside(probe[near], triangles).sum())
            if count > best_count:
                best, best_count = j, count
        if best is None:
            continue
        hull = _with_crack_index(
            m3.Manifold.hull_points(np.ascontiguousarray(model.vertices[model.tets[tets]].reshape(-1, 3))), HULL_FACE)
        piece, rest = solids[best].split(hull)
        if piece.is_empty():
            continue
        solids[best], solids[k] = rest, piece
        carved += 1
    return solids, carved


def _assign_parts(parts, model, labels, spacing) -> list[int]:
    """The piece (label) each connected part belongs to: an area-weighted vote of its faces,
    each probed a quarter spacing inside the part, for the piece of the nearest tet centroid
    (-1: dropped tets)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(model.particle_position)
    owners = []
    for part in parts:
        mesh = part.to_mesh64()
        vp = np.asarray(mesh.vert_properties)[:, :3]
        tri_verts = np.asarray(mesh.tri_verts, dtype=np.int64)
        tri = vp[tri_verts[:: max(1, len(tri_verts) // MAX_VOTING_FACES)]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(normal, axis=1)
        normal /= np.maximum(2.0 * area[:, None], 1e-300)
        probe = tri.mean(axis=1) - 0.25 * spacing * normal
        _, nearest = tree.query(probe)
        votes = np.bincount(labels[nearest] + 1, weights=area)
        if votes.max() < DECISIVE_VOTE * votes.sum() and part.volume() >= spacing**3:
            # A thin part (three tets across a glass pane) can sit nearer a neighbour's tets
            # than its own: ask which tets' centroids it holds, by their volume. (Not for
            # chips under a spacing cubed: a refracture through a piece's hairline shells
            # leaves dozens, and which side owns one is invisible.)
            tets = _tets_inside(part, model, vp.min(axis=0), vp.max(axis=0), tri)
            if len(tets):
                votes = np.bincount(labels[tets] + 1, weights=model.tet_volume[tets])
        owners.append(int(np.argmax(votes)) - 1)
    return owners


def _tets_inside(part, model, low, high, triangles) -> np.ndarray:
    """Up to MAX_PROBED_TETS tets (evenly spread over those in the part's box) whose
    centroids lie inside ``part``; ``triangles`` its faces."""
    from .piece_checks import inside

    in_box = np.nonzero(np.all((model.particle_position >= low) & (model.particle_position <= high), axis=1))[0]
    in_box = in_box[:: max(1, len(in_box) // MAX_PROBED_TETS)]
    mesh = part.to_mesh64()
    every = np.asarray(mesh.vert_properties)[:, :3][np.asarray(mesh.tri_verts, dtype=np.int64)]
    return in_box[inside(model.particle_position[in_box], every)]


def _face_cracks(corner_crack: np.ndarray, triangles: np.ndarray, cracks, spacing: float) -> np.ndarray:
    """(F,) each face's crack index from its corners' (F,3): the one they share, else (a face
    the booleans gave corners of two origins) the crack whose surface all three corners lie on
    (within SPHERE_SAGITTA_FACTOR spacings), else the artist's surface (-1), or a hull's."""
    crack = corner_crack[:, 0].copy()
    mixed = np.nonzero((corner_crack != corner_crack[:, :1]).any(axis=1))[0]
    for f in mixed:
        crack[f] = HULL_FACE if (corner_crack[f] == HULL_FACE).any() else -1
        for index in np.unique(corner_crack[f][corner_crack[f] >= 0]):
            if np.all(np.abs(cracks[index].distance(triangles[f])) <= SPHERE_SAGITTA_FACTOR * spacing):
                crack[f] = index
                break
    return crack


def piece_mesh(render: RenderSolid) -> PieceMesh:
    """The render solid as a triangle mesh with per-corner shading (see PieceMesh)."""
    mesh = render.solid.to_mesh64()
    props = np.asarray(mesh.vert_properties, dtype=np.float64)
    tri_verts = np.asarray(mesh.tri_verts, dtype=np.int64)
    # One vertex per topological vertex: property vertices repeat one across UV and normal
    # seams (the merge vectors say which), while two vertices the solid pinches together at
    # one position stay two, so the mesh stays manifold.
    topological = np.arange(len(props))
    topological[np.asarray(mesh.merge_from_vert, dtype=np.int64)] = np.asarray(mesh.merge_to_vert, dtype=np.int64)
    used, vertex_of = np.unique(topological, return_inverse=True)
    positions = props[used, :3]
    faces = vertex_of.reshape(-1)[tri_verts]
    corner = props[tri_verts]  # (F,3,P)
    tri = positions[faces]
    crack = _face_cracks(np.rint(corner[:, :, _CRACK]).astype(np.int64), tri, render.cracks, render.spacing)
    inner = crack != -1
    flat = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300)
    normals = corner[:, :, _NORMAL].copy()
    normals[inner] = flat[inner][:, None, :]
    length = np.linalg.norm(normals, axis=2, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-300), flat[:, None, :])
    uvs = corner[:, :, _UV].copy()
    uvs[crack == HULL_FACE] = np.nan  # (the cache writer projects them on a box)
    for index in np.unique(crack[crack >= 0]):
        rows = np.nonzero(crack == index)[0]
        surface = render.cracks[index]
        rel = tri[rows] - surface.point
        if surface.radius is None:
            e1, e2 = tangent_frame(surface.normal)
            uvs[rows] = np.stack([rel @ e1, rel @ e2], axis=2)
        else:  # a sphere: longitude and latitude scaled to metres on the sphere
            r = np.linalg.norm(rel, axis=2)
            uvs[rows] = np.stack([np.arctan2(rel[..., 1], rel[..., 0]) * surface.radius,
                                  np.arcsin(np.clip(rel[..., 2] / np.maximum(r, 1e-300), -1, 1)) * surface.radius],
                                 axis=2)
    return PieceMesh(positions, faces, inner, normals, uvs, crack, render.cracks)
