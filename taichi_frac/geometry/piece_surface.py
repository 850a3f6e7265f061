"""Render surfaces of broken pieces: the artist's surface outside, the crack's own surface inside.

The physics decides which pieces exist (tets joined by bonds, cut by crack discs and rings;
``fracture/fragments.py``); this module only gives each piece the surface an artist sees.
A body's *render solid* is the artist's closed surface (``PrepareReport.surface``, full
resolution, with its corner normals and UVs) as an exact-arithmetic ``manifold3d`` solid in
the body's frame. When the body breaks, the render solid is cut by thin slabs lying on the
crack geometry, one per crack, covering exactly the part of the crack that separates two
different pieces, and the connected parts that remain are handed to the pieces whose tets
they hold. So:

- crack faces lie on their crack plane (or ring sphere) to within half the slab thickness
  (``SLAB_THICKNESS_FACTOR`` x the particle spacing), not on the tets' staircase;
- the outside is the artist's triangles clipped at the crack faces, keeping their UVs and
  normals (interpolated where a triangle is cut); inner faces get a planar projection along
  their crack as UVs and their own flat normal;
- every piece is closed, manifold and outward wound (the boolean library guarantees it);
- a piece that breaks again cuts its own render solid.

Why slabs and not plain half-space splits: a crack disc is finite, so a crack plane
separates two pieces in one place and runs through one piece elsewhere. Splitting by the
infinite plane and gluing the same piece's halves back is a union of solids that touch on
coplanar faces, which exact booleans resolve by symbolic perturbation into separate shells
(measured: 158 of 200 random fans of planes through a torus failed to glue). A slab is cut
only where the tets say the crack separates different pieces: its 2-D outline is the union
of the cut tet faces' projections onto the crack plane, grown by one particle spacing so it
reaches through the surface. Where a crack ends against another crack the slab runs up to
one spacing past it, a hairline notch in the piece beyond.

Where a crack cut bonds inside what stayed one piece (a merged small piece, a piece joined
around the crack's end) its slab cuts that piece too; the piece's parts are welded back into
one shell by the render solid within a slab three times as thick over those crossings. A
part reaching far past its piece's tets (the artist's surface joins two pieces across a gap
their tets leave open) is divided by the tets' nearest-centroid cells
(``piece_parts.divide_joined_parts``). What the cut still cannot resolve falls back to the
solid nearest the piece's tets: a piece left with under half its tets' volume, one whose
render solid reaches more than ``piece_parts.OVERREACH_FACTOR`` spacings past its tets or
holds well over their volume (it holds a neighbour's material), and the neighbour that lost
it (``geometry/piece_parts.py``) get the solid nearer their tet centroids than those of the
other pieces so failed, less what the other pieces hold: the artist's surface outside, the
other pieces' crack faces against them, faces between nearest-centroid cells between them.
A piece's crumbs are dropped and its other stray shells bridged to the main shell they lie
against, its own or a neighbour's (``piece_shells.join_stray_shells``).

``crack_roughness`` (FractureOptions) displaces the slabs' faces along the crack normal
by smooth value noise, the same on both faces, so the two sides of a crack still fit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh

from .piece_parts import (assign_parts, carve_missing_pieces, divide_joined_parts, failed_piece_shells, failed_pieces,
                          overfull_pieces, overreaching_pieces)
from .piece_shells import join_stray_shells, without_crumbs
from .surface_attributes import input_corner_normals

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
#: cell still stops the slab halfway to it.
SLAB_REACH_FACTOR = 8.0

#: Parts of the cut solid smaller than this [particle spacings cubed] are dropped: chips
#: where two slabs' edges cross the surface, far below a render's resolution.
DUST_VOLUME_FACTOR = 1e-2

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


def _shared_faces(model, bonds: np.ndarray) -> np.ndarray:
    """(B,3,3) [m] corners of the tet face each bond (tet pair) shares."""
    first, second = model.tets[bonds[:, 0]], model.tets[bonds[:, 1]]
    shared = (first[:, :, None] == second[:, None, :]).any(axis=2)  # (B,4), three True
    keep = np.argsort(~shared, axis=1, kind="stable")[:, :3]
    return model.vertices[np.take_along_axis(first, keep, axis=1)]


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
    return _tangent_frame_of(*(float(c) for c in normal))


@functools.lru_cache(maxsize=4096)
def _tangent_frame_of(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    # Kept per normal: every piece's mesh asks again for each crack it inherited, and a
    # scene's few hundred cracks repeat thousands of times (numpy's small-array overhead).
    from ..fracture.cracks import tangent_frame as crack_frame

    e1, e2 = crack_frame(np.array([x, y, z]))
    e1.flags.writeable = e2.flags.writeable = False
    return e1, e2


def without_dust(solid: m3.Manifold, spacing: float) -> list:
    """The shells of ``solid`` but those under DUST_VOLUME_FACTOR ``spacing`` cubed: chips
    where slabs' or cells' faces cross the surface, and the flat slivers of no volume a union
    leaves where a weld's or a bridge's faces lie on the parts' own."""
    return [shell for shell in solid.decompose() if shell.volume() >= DUST_VOLUME_FACTOR * spacing**3]


def _plane_slab(crack: CrackSurface, sites: np.ndarray, separating: np.ndarray, spacing: float, roughness: float,
                roughness_scale: float, seed: int, index: int,
                thickness_factor: float = SLAB_THICKNESS_FACTOR,
                reach_factor: float = SLAB_REACH_FACTOR, apart_from=()) -> m3.Manifold | None:
    """The thin slab on a plane crack over the part of the plane nearer a separating bond
    crossing than any other: ``sites`` (N,3) [m] where bonds cross the plane, ``separating``
    (N,) bool those between different pieces cut by this crack. Each separating site's
    Voronoi cell (in the plane, bounded to SLAB_REACH_FACTOR spacings about it) joins the
    outline, so the slab reaches the surface however obliquely the plane meets it, and stops
    halfway to the nearest crossing inside one piece. Rough when ``roughness`` > 0;
    ``thickness_factor`` x ``spacing`` thick, reaching ``reach_factor`` spacings; kept off
    the other slabs of the plane cracks ``apart_from`` (CrackSurfaces) by a strip along each
    one's line through this plane."""
    from scipy.spatial import Voronoi, cKDTree

    e1, e2 = tangent_frame(crack.normal)
    rel = sites - crack.point
    flat = np.stack([rel @ e1, rel @ e2], axis=1)  # (N,2)
    if not separating.any():
        return None
    reach = reach_factor * spacing
    box = np.array([[-reach, -reach], [reach, -reach], [reach, reach], [-reach, reach]])
    # Where a separating crossing is within reach, less where another crossing is nearer.
    outline = m3.CrossSection(list(flat[separating][:, None, :] + box[None]), m3.FillRule.Positive)
    if not separating.all():
        # Only crossings within 2 sqrt(2) reach of a separating one can be the nearest to a
        # point of its square (the separating one is within sqrt(2) reach of it): the rest
        # leave the cells over the squares as they are.
        near = cKDTree(flat[separating]).query(flat, distance_upper_bound=2.9 * reach)[0] <= 2.9 * reach
        flat, separating = flat[near], separating[near]
        lo, hi = flat.min(axis=0) - 4 * reach, flat.max(axis=0) + 4 * reach
        fence = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        _, first = np.unique(np.round(flat / (1e-9 * spacing)), axis=0, return_index=True)
        points = np.concatenate([flat[first], fence])
        diagram = Voronoi(points)
        regions = (diagram.regions[diagram.point_region[k]] for k in np.nonzero(~separating[first])[0])
        # (the cells do not overlap, so either winding fills them)
        cells = [diagram.vertices[region] for region in regions if len(region) >= 3 and -1 not in region]
        if cells:
            outline = outline - m3.CrossSection(cells, m3.FillRule.NonZero)
    for other in apart_from:
        outline = outline - _strip_along(crack, other, flat, spacing, thickness_factor, roughness, e1, e2)
    outline = outline.simplify(0.05 * spacing)
    if outline.is_empty():
        return None
    thickness = thickness_factor * spacing
    slab = m3.Manifold.extrude(outline, thickness).translate((0.0, 0.0, -0.5 * thickness))
    if roughness > 0:
        slab = slab.refine_to_length(roughness_scale / 3.0)

        def displace(points):
            points = np.array(points, dtype=np.float64)
            noise = _value_noise(points[:, 0] / roughness_scale, points[:, 1] / roughness_scale, seed * 1009 + index)
            points[:, 2] += roughness * noise
            return points

        slab = slab.warp_batch(displace)
    frame = np.column_stack([e1, e2, crack.normal, crack.point])  # (3,4): slab frame -> body
    return slab.transform(frame)


def _strip_along(crack: CrackSurface, other: CrackSurface, flat: np.ndarray, spacing: float,
                 thickness_factor: float, roughness: float, e1: np.ndarray, e2: np.ndarray) -> m3.CrossSection:
    """The strip of ``crack``'s plane (2-D, its tangent frame ``e1``, ``e2``) within which a slab
    ``thickness_factor`` spacings thick would touch the slab of the plane crack ``other``:
    along the planes' line, out past the points ``flat`` (N,2) [m]; empty for planes within
    a degree of parallel (they meet far off)."""
    a, b = float(e1 @ other.normal), float(e2 @ other.normal)
    sine = np.hypot(a, b)
    if sine < np.sin(np.radians(1.0)):
        return m3.CrossSection()
    offset = float((other.point - crack.point) @ other.normal)  # the line: a u + b v = offset
    half = (0.5 * (thickness_factor + SLAB_THICKNESS_FACTOR) * spacing * 2.0 + 2.0 * roughness) / sine
    centre = np.array([a, b]) * offset / sine**2
    along = np.array([-b, a]) / sine
    across = np.array([a, b]) / sine
    length = float(np.max(np.linalg.norm(flat - centre, axis=1))) + 10.0 * spacing
    corners = [centre - length * along - half * across, centre + length * along - half * across,
               centre + length * along + half * across, centre - length * along + half * across]
    return m3.CrossSection([np.array(corners)], m3.FillRule.NonZero)


def _sphere_shell(crack: CrackSurface, spacing: float) -> m3.Manifold:
    """The thin shell on a ring crack's sphere."""
    half = 0.5 * SLAB_THICKNESS_FACTOR * spacing
    sagitta = SPHERE_SAGITTA_FACTOR * spacing
    segments = int(np.ceil(np.pi / np.arccos(max(1.0 - sagitta / crack.radius, -1.0)))) + 4
    segments = min(segments, 512)
    outer = m3.Manifold.sphere(crack.radius + half, segments)
    inner = m3.Manifold.sphere(max(crack.radius - half, 1e-9), segments)
    return (outer - inner).translate(tuple(crack.point))


def _with_crack_index(slab: m3.Manifold, index: int) -> m3.Manifold:
    """``slab`` with every vertex's crack-index property set to ``index`` (normals and UVs
    zero: the piece's inner faces get theirs in ``piece_mesh``)."""
    mesh = slab.to_mesh64()
    positions = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    props = np.zeros((len(positions), _PROPERTY_COUNT))
    props[:, :3] = positions
    props[:, _CRACK] = index
    return m3.Manifold(m3.Mesh64(vert_properties=props,
                                 tri_verts=np.array(mesh.tri_verts, dtype=np.uint64)))


def _separating_cracks(model, bonds, labels, cracks):
    """For each crack: (sites (N,3) [m], cut (N,) bool, inside (N,) int): where bonds cross
    its plane, which of them it cuts, and for a cut between two tets of one piece that piece
    (else -1); empty when it separates no two pieces (a ring crack: (None, its cuts between
    pieces, None))."""
    from ..fracture.crack_types import CrackPlane, RingCrack

    x = model.particle_position
    a, b = x[bonds[:, 0]], x[bonds[:, 1]]
    separating = labels[bonds[:, 0]] != labels[bonds[:, 1]]
    per_crack = []
    for crack in cracks:
        if isinstance(crack, CrackPlane):
            da, db = (a - crack.point) @ crack.normal, (b - crack.point) @ crack.normal
            cross = (da >= 0) != (db >= 0)
            t = da / np.where(cross, da - db, 1.0)
            hit = a + t[:, None] * (b - a)
            offset = hit - crack.point
            cut = cross & (np.einsum("ij,ij->i", offset, offset) <= crack.extent**2)
            if not np.any(cut & separating):
                per_crack.append((hit[:0], cut[:0], labels[:0]))  # it separates no two pieces: no slit either
                continue
            # Sites: every crossing but those between pieces another crack cut. A cut inside
            # one piece (a merged small piece, a piece joined around) is cut too: that piece
            # then has two shells a slab apart, as a hairline crack would look.
            site = cross & (cut | ~separating)
            inside_one = np.where(cut & ~separating, labels[bonds[:, 0]], -1)
            per_crack.append((hit[site], cut[site], inside_one[site]))
        elif isinstance(crack, RingCrack):
            inside_a = np.einsum("ij,ij->i", a - crack.point, a - crack.point) < crack.radius**2
            inside_b = np.einsum("ij,ij->i", b - crack.point, b - crack.point) < crack.radius**2
            cut = (inside_a != inside_b) & separating
            per_crack.append((None, cut[cut], None))  # (the whole sphere: rings run all round)
        else:
            raise TypeError(f"unknown crack type {type(crack).__name__}")
    return per_crack


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

    Returns (pieces, stats): pieces a list of F RenderSolid or None (the caller then gives the
    piece its tets' boundary, exact in volume); stats a dict of counts (slabs, parts,
    unassigned parts, pieces without a part, ``fallback_pieces``: pieces the cut failed, see
    ``failed_pieces``, of which ``cell_pieces`` got the solid nearest their tets instead
    (``piece_parts.failed_piece_shells``) and the rest None; ``shells_moved``: stray shells
    joined to another piece, see ``piece_shells.join_stray_shells``).
    """
    from ..fracture.crack_types import CrackPlane

    spacing = render.spacing
    roughness_scale = 4.0 * spacing if roughness_scale is None else float(roughness_scale)
    labels = np.full(model.tet_count, -1, dtype=np.int64)
    for k, tets in enumerate(fragment_tets):
        labels[np.asarray(tets, dtype=np.int64)] = k
    bonds = np.asarray(model.bonds, dtype=np.int64)
    per_crack = _separating_cracks(model, bonds, labels, cracks)

    new_cracks = list(render.cracks)
    slabs, planes = [], []
    for crack, (sites, separating, inside_one) in zip(cracks, per_crack):
        if not len(separating) or not separating.any():
            continue
        index = len(new_cracks)
        if isinstance(crack, CrackPlane):
            surface = CrackSurface(np.asarray(crack.point, float), np.asarray(crack.normal, float))
            slab = _plane_slab(surface, sites, separating, spacing, roughness, roughness_scale, seed, index)
        else:
            surface = CrackSurface(np.asarray(crack.point, float), np.zeros(3), float(crack.radius))
            slab = _sphere_shell(surface, spacing)
        if slab is None or slab.is_empty():
            continue
        new_cracks.append(surface)
        slabs.append(_with_crack_index(slab, index))
        if isinstance(crack, CrackPlane):
            planes.append((surface, sites, inside_one, index))
    stats = dict(slabs=len(slabs), parts=0, unassigned_parts=0, empty_pieces=0, welded_pieces=0, cell_pieces=0)
    if slabs:
        cut = m3.Manifold.batch_boolean([render.solid, *slabs], m3.OpType.Subtract)
    else:
        cut = render.solid
    every_part = cut.decompose()
    parts = [part for part in every_part if part.volume() >= DUST_VOLUME_FACTOR * spacing**3]
    stats["dust_parts"] = len(every_part) - len(parts)
    corners = {}  # id(part) -> (part, its vertices (N,3) [m]): read by the vote and the reach check
    owner = assign_parts(parts, model, labels, spacing, corners)
    parts, owner, received = divide_joined_parts(parts, owner, model, labels, spacing, corners)
    stats["pieces_given_divided_parts"] = len(received)
    parts, owner = carve_missing_pieces(parts, owner, model, fragment_tets, labels, spacing)
    stats["parts"] = len(parts)
    stats["carved_pieces"] = len({o for o in owner if o < -1})
    owner = [-(o + 2) if o < -1 else o for o in owner]
    failed = failed_pieces(parts, owner, model, fragment_tets)
    failed |= overreaching_pieces(parts, owner, model, labels, spacing, corners)
    # (a piece given the material nearest its tets beyond a gap they leave holds more than
    # them by that gap's volume: not a neighbour's material)
    failed |= overfull_pieces(parts, owner, model, labels, spacing) - received
    stats["fallback_pieces"] = len(failed)
    # Each piece's parts without its crumbs, once: the welds and the pieces below read them.
    kept = {k: without_crumbs([p for p, o in zip(parts, owner) if o == k], spacing) for k in set(owner) if k >= 0}
    split_up = {k for k, mine in kept.items() if k not in failed and len(mine) > 1}
    spheres = [surface for surface in new_cracks[len(render.cracks):] if surface.radius is not None]
    welds = _weld_bits(render.solid, planes, spheres, split_up, spacing, roughness, roughness_scale, seed)
    shells = {}  # piece -> its shells, the body's frame
    origins = np.asarray(piece_origins, dtype=np.float64).reshape(-1, 3)
    for k in range(len(origins)):
        mine = kept.get(k, [])
        if k in failed:
            # Its share of the solid nearest its own tets (see failed_piece_shells).
            shells[k] = without_crumbs(failed_piece_shells(render.solid, model, labels, k, failed, parts, owner,
                                                           spacing), spacing)
            stats["cell_pieces"] += bool(shells[k])
        elif not mine:
            stats["empty_pieces"] += 1
        elif k in welds:
            shells[k] = without_dust(m3.Manifold.batch_boolean([*mine, *welds[k]], m3.OpType.Add), spacing)
            stats["welded_pieces"] += 1
        else:
            shells[k] = mine
    solids, stats["shells_moved"] = join_stray_shells({k: mine for k, mine in shells.items() if mine}, spacing)
    pieces = [RenderSolid(solids[k], tuple(new_cracks), spacing).moved(origin) if k in solids else None
              for k, origin in enumerate(origins)]
    stats["unassigned_parts"] = int(sum(1 for o in owner if o == -1))
    return pieces, stats


def _weld_bits(solid: m3.Manifold, planes, spheres, split_up: set, spacing: float, roughness: float,
               roughness_scale: float, seed: int) -> dict:
    """Piece -> the bit of the render ``solid`` that joins its parts again where a crack's slab
    cut through the piece itself (a bond cut between two of its own tets: a merged small piece,
    a piece joined around the crack's end): the solid within a slab WELD_THICKNESS_FACTOR
    spacings thick over those crossings (squares WELD_REACH_FACTOR spacings about each), which
    overlaps the parts on both sides of the hairline, so their union is one shell. So that a
    square reaching past another crack does not join the piece to a sliver in its neighbour,
    the weld keeps off the other plane cracks' lines through its plane (the sliver left
    beyond is apart, under the crumb volume, dropped), and crossings whose square would reach
    a ring crack's sphere (``spheres``) are left out; one overlap is enough to join two
    parts. Only for the pieces in ``split_up``; ``planes``: (surface, sites, inside, index)
    of each plane crack's slab."""
    bits = {}
    for k in sorted(split_up):
        welds = []
        for surface, sites, inside_one, index in planes:
            own = inside_one == k
            for sphere in spheres:
                own &= np.abs(sphere.distance(sites)) > np.sqrt(2.0) * WELD_REACH_FACTOR * spacing
            if not own.any():
                continue
            weld = _plane_slab(surface, sites[own], np.ones(int(own.sum()), dtype=bool), spacing, roughness,
                               roughness_scale, seed, index, thickness_factor=WELD_THICKNESS_FACTOR,
                               reach_factor=WELD_REACH_FACTOR,
                               apart_from=[other for other, _, _, _ in planes if other is not surface])
            if weld is not None and not weld.is_empty():
                welds.append(_with_crack_index(weld, index))
        if welds:
            bits[k] = [solid ^ (m3.Manifold.batch_boolean(welds, m3.OpType.Add) if len(welds) > 1 else welds[0])]
    return bits


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
    corner_crack = np.rint(np.nan_to_num(corner[:, :, _CRACK], nan=-1.0)).astype(np.int64)
    crack = _face_cracks(corner_crack, tri, render.cracks, render.spacing)
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
