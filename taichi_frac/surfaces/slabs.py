"""The thin slabs that cut a body's render solid along its cracks.

A plane crack's slab covers the part of its plane nearer a bond the crack cut than any bond
it did not (``plane_slab``); a ring crack's is a thin spherical shell (``sphere_shell``). A
plane that parts several pairs of pieces may be cut in stretches, one per pair, each at its
own shift along the normal, with walls across the steps between them (``segment_slabs``;
the shifts come from ``crack_offsets``). ``piece_surface`` subtracts them from the solid.
"""

from __future__ import annotations

import manifold3d as m3
import numpy as np

from .solid import (SLAB_REACH_FACTOR, SLAB_THICKNESS_FACTOR, SPHERE_SAGITTA_FACTOR, CrackSurface,
                    tangent_frame)

#: How far [particle spacings] a crack's slab runs past the line halfway to the nearest
#: crossing it did not cut. Where two or three cracks meet about a small piece, slabs that
#: stop at that line can leave the piece joined to a neighbour around their ends (3 of the
#: 13 rings' pieces, 1 of the glass walls'); half a spacing more closes those gaps, at the
#: price of a hairline slit as deep past a crack's free end.
SLAB_PAST_FACTOR = 0.5

#: Width [particle spacings] of the wall that cuts the step between two stretches of one crack
#: shifted apart (each pair of pieces' own, crack_offsets.CrackSegments).
STEP_WALL_FACTOR = 0.02


def value_noise(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
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


def _cut_outline(flat: np.ndarray, separating: np.ndarray, spacing: float, reach: float, past: float):
    """(outline, keep): the part of a crack plane within ``reach`` [m] of a crossing it cut
    (``flat`` (N,2) [m] the crossings in its plane, ``separating`` (N,) those it cut), less
    where a crossing it did not cut is nearer, grown ``past`` spacings; keep (M,) the
    crossings that matter to it, each position once (indices into ``flat``)."""
    from scipy.spatial import cKDTree

    # Only crossings within 2 sqrt(2) reach of a separating one can be the nearest to a
    # point of its square (the separating one is within sqrt(2) reach of it): the rest leave
    # the cells over the squares as they are.
    near = np.nonzero(cKDTree(flat[separating]).query(flat, distance_upper_bound=2.9 * reach)[0] <= 2.9 * reach)[0]
    keep = near[np.unique(np.round(flat[near] / (1e-9 * spacing)), axis=0, return_index=True)[1]]
    box = np.array([[-reach, -reach], [reach, -reach], [reach, reach], [-reach, reach]])
    outline = m3.CrossSection(list(flat[separating][:, None, :] + box[None]), m3.FillRule.Positive)
    uncut = np.nonzero(~separating[keep])[0]
    if len(uncut):
        cells = _cells(_fenced_voronoi(flat[keep], reach), uncut)
        if cells:
            outline = outline - m3.CrossSection(cells, m3.FillRule.NonZero)
    if past > 0:
        outline = outline.offset(past * spacing, m3.JoinType.Miter)
    return outline, keep


def _fenced_voronoi(flat: np.ndarray, reach: float):
    """The Voronoi diagram of the points ``flat`` (N,2) [m] and four far corners that keep
    every point's cell bounded."""
    from scipy.spatial import Voronoi

    lo, hi = flat.min(axis=0) - 4 * reach, flat.max(axis=0) + 4 * reach
    return Voronoi(np.concatenate([flat, [[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]]))


def _cells(diagram, points) -> list:
    """The cells (each (K,2) [m]) of ``diagram``'s ``points`` (indices), those bounded; they
    do not overlap, so either winding fills them."""
    regions = (diagram.regions[diagram.point_region[k]] for k in points)
    return [diagram.vertices[region] for region in regions if len(region) >= 3 and -1 not in region]


def plane_slab(crack: CrackSurface, sites: np.ndarray, separating: np.ndarray, spacing: float, roughness: float,
                roughness_scale: float, seed: int, index: int,
                thickness_factor: float = SLAB_THICKNESS_FACTOR,
                reach_factor: float = SLAB_REACH_FACTOR, apart_from=(), past: float = 0.0,
                segment: np.ndarray | None = None, shifts: np.ndarray | None = None) -> m3.Manifold | None:
    """The thin slab on a plane crack over the part of the plane nearer a separating bond
    crossing than any other: ``sites`` (N,3) [m] where bonds cross the plane, ``separating``
    (N,) bool those between different pieces cut by this crack. Each separating site's
    Voronoi cell (in the plane, bounded to SLAB_REACH_FACTOR spacings about it) joins the
    outline, so the slab reaches the surface however obliquely the plane meets it, and stops
    halfway to the nearest crossing inside one piece. Rough when ``roughness`` > 0;
    ``thickness_factor`` x ``spacing`` thick, reaching ``reach_factor`` spacings; kept off
    the other slabs of the plane cracks ``apart_from`` (CrackSurfaces) by a strip along each
    one's line through this plane; grown by ``past`` spacings beyond that halfway line
    (``SLAB_PAST_FACTOR`` for a crack's own slab). A rough slab may also carry the stretches'
    shifts (``segment`` (N,) each crossing's stretch, ``shifts`` (S,) [m] each stretch's:
    ``stretch_heights``) in its one warped surface: unlike ``segment_slabs``' flat stretches,
    it needs no walls, and the two sides of the crack still share one surface."""
    e1, e2 = tangent_frame(crack.normal)
    rel = sites - crack.point
    flat = np.stack([rel @ e1, rel @ e2], axis=1)  # (N,2)
    if not separating.any():
        return None
    outline, keep = _cut_outline(flat, separating, spacing, reach_factor * spacing, past)
    height = None
    if segment is not None and roughness > 0:
        cut = separating[keep]
        stretch = segment[keep][cut]  # (each cut crossing's stretch; -1: none, not shifted)
        height = stretch_heights(flat[keep][cut], np.where(stretch >= 0, shifts[np.maximum(stretch, 0)], 0.0),
                                 spacing)
    flat = flat[keep]
    for other in apart_from:
        outline = outline - _strip_along(crack, other, flat, spacing, thickness_factor, roughness, e1, e2)
    outline = outline.simplify(0.05 * spacing)
    if outline.is_empty():
        return None
    thickness = thickness_factor * spacing
    if roughness > 0:
        def lift(points):  # (K,2) [m] -> (K,) [m]: the crack face's height along the normal
            lifted = roughness * value_noise(points[:, 0] / roughness_scale, points[:, 1] / roughness_scale,
                                             seed * 1009 + index)
            return lifted + height(points) if height is not None else lifted

        slab = warped_slab(outline, thickness, roughness_scale / 3.0, lift)
    else:
        slab = m3.Manifold.extrude(outline, thickness).translate((0.0, 0.0, -0.5 * thickness))
    frame = np.column_stack([e1, e2, crack.normal, crack.point])  # (3,4): slab frame -> body
    return slab.transform(frame)


def warped_slab(outline: m3.CrossSection, thickness: float, length: float, lift) -> m3.Manifold:
    """A slab ``thickness`` [m] thick over ``outline`` (2-D, [m]) whose mid-surface is lifted
    along z by ``lift`` ((K,2) [m] -> (K,) [m]), triangulated to edges of at most ``length``
    [m]. Its top and bottom are one triangulation offset by the thickness, so they never
    cross however steeply the lift varies (a warped extrusion's two caps, triangulated apart,
    would: its thickness is far below a triangle's interpolation error)."""
    sheet = m3.Manifold.extrude(outline, thickness).refine_to_length(length).to_mesh()
    points = np.asarray(sheet.vert_properties, dtype=np.float64)[:, :3]
    triangles = np.asarray(sheet.tri_verts, dtype=np.int64)
    top = np.all(points[triangles, 2] > 0.0, axis=1)  # (the upper cap, wound counter-clockwise from above)
    used, faces = np.unique(triangles[top], return_inverse=True)
    faces = faces.reshape(-1, 3)
    uv = points[used, :2]
    z = lift(uv)
    n = len(uv)
    vertices = np.concatenate([np.column_stack([uv, z + 0.5 * thickness]), np.column_stack([uv, z - 0.5 * thickness])])
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    code = edges[:, 0] * n + edges[:, 1]
    rim = edges[~np.isin(code, edges[:, 1] * n + edges[:, 0])]  # (the cap's boundary, each edge once)
    a, b = rim[:, 0], rim[:, 1]
    walls = np.concatenate([np.stack([b, a, a + n], axis=1), np.stack([b, a + n, b + n], axis=1)])
    mesh = m3.Mesh(vert_properties=vertices.astype(np.float32),
                   tri_verts=np.concatenate([faces, faces[:, ::-1] + n, walls]).astype(np.uint32))
    return m3.Manifold(mesh)


#: Width [particle spacings] over which a rough crack's stretches blend from one shift to the
#: next (``stretch_heights``); the warped mesh's triangles smooth it further.
STRETCH_BLEND_FACTOR = 0.5


def stretch_heights(flat: np.ndarray, heights: np.ndarray, spacing: float):
    """The shift field [m] over a crack plane whose cut crossings ``flat`` (M,2) [m] carry the
    shifts ``heights`` (M,) [m] of their stretches: near a crossing its stretch's shift,
    blended over STRETCH_BLEND_FACTOR spacings across the Voronoi edges between stretches
    (a soft nearest-crossing weight). Returns a function of points (K,2) [m] -> (K,) [m]."""
    from scipy.spatial import cKDTree

    tree = cKDTree(flat)
    count = min(6, len(flat))
    tau2 = (STRETCH_BLEND_FACTOR * spacing) ** 2

    def height(points: np.ndarray) -> np.ndarray:
        distance, nearest = tree.query(points, k=count)
        distance, nearest = distance.reshape(len(points), -1), nearest.reshape(len(points), -1)
        weight = np.exp(-(distance**2 - distance[:, :1] ** 2) / tau2)
        return np.sum(weight * heights[nearest], axis=1) / np.sum(weight, axis=1)

    return height


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


def segment_slabs(crack: CrackSurface, sites: np.ndarray, separating: np.ndarray, segment: np.ndarray,
                   shifts: np.ndarray, spacing: float, past: float = SLAB_PAST_FACTOR):
    """A plane crack's slab in stretches, each the part of ``plane_slab``'s outline nearer one
    pair of pieces' crossings than any other, shifted along the normal by that pair's
    ``shifts[segment]`` [m] (the crossings cut inside one piece, ``segment`` -1, not shifted),
    and the walls that cut the steps between neighbouring stretches: without them the
    material between two stretches' heights would join the pieces on their two sides.
    Their union reaches ``past`` spacings beyond ``plane_slab``'s halfway line, as the
    whole slab does, each stretch over the part of that rim nearest its crossings.
    Returns ([(CrackSurface, slab) for each height], the walls' manifold or None)."""
    e1, e2 = tangent_frame(crack.normal)
    rel = sites - crack.point
    flat = np.stack([rel @ e1, rel @ e2], axis=1)  # (N,2)
    reach = SLAB_REACH_FACTOR * spacing
    outline, keep = _cut_outline(flat, separating, spacing, reach, past)
    flat, separating, segment = flat[keep], separating[keep], segment[keep]
    # One slab per height: stretches shifted alike (the fit often leaves several at its
    # bound) share one, so no two slabs meet side by side at one height. -1: a crossing cut
    # inside one piece, or a segment not shifted.
    height = np.where(segment >= 0, shifts[np.maximum(segment, 0)], 0.0)[separating]
    level = np.unique(height, return_inverse=True)[1].reshape(-1)
    group = np.where(height != 0.0, level, -1)
    # Divided among the stretches by the cells of the cut crossings alone (inside the
    # ungrown outline, the same as among all crossings).
    flat = flat[separating]
    diagram = _fenced_voronoi(flat, reach)
    thickness = SLAB_THICKNESS_FACTOR * spacing
    frame = np.column_stack([e1, e2, crack.normal, crack.point])  # (3,4): slab frame -> body
    outlines, parts = {}, []
    for g in np.unique(group):
        mine = group == g
        part = outline ^ m3.CrossSection(_cells(diagram, np.nonzero(mine)[0]), m3.FillRule.NonZero)
        if part.is_empty():
            continue
        outlines[g] = part
        h = float(height[mine][0])
        slab = m3.Manifold.extrude(part, thickness).translate((0.0, 0.0, h - 0.5 * thickness))
        parts.append((CrackSurface(crack.point + h * crack.normal, crack.normal), slab.transform(frame)))
    # The steps: each Voronoi edge between crossings of two stretches at different heights.
    half = 0.5 * STEP_WALL_FACTOR * spacing
    steps = {}
    for (p, q), ridge in zip(diagram.ridge_points, diagram.ridge_vertices):
        if p >= len(flat) or q >= len(flat) or -1 in ridge:
            continue
        if group[p] == group[q] or height[p] == height[q] or group[p] not in outlines or group[q] not in outlines:
            continue
        a, b = diagram.vertices[ridge[0]], diagram.vertices[ridge[1]]
        along = (b - a) / max(float(np.linalg.norm(b - a)), 1e-300)
        across = np.array([-along[1], along[0]]) * half
        rectangle = np.array([a - half * along - across, b + half * along - across, b + half * along + across,
                              a - half * along + across])
        key = (min(group[p], group[q]), max(group[p], group[q]))
        steps.setdefault(key, []).append(rectangle)
    walls = []
    for (g, k), rectangles in steps.items():
        # (only where either stretch's outline is: past them no slab cuts, so neither may a wall)
        region = (outlines[g] + outlines[k]).offset(2.0 * half, m3.JoinType.Miter)
        footprint = m3.CrossSection(rectangles, m3.FillRule.NonZero) ^ region
        if footprint.is_empty():
            continue
        bottom, top = sorted(float(height[group == x][0]) for x in (g, k))
        wall = m3.Manifold.extrude(footprint, top - bottom + thickness).translate((0.0, 0.0, bottom - 0.5 * thickness))
        walls.append(wall.transform(frame))
    wall = m3.Manifold.batch_boolean(walls, m3.OpType.Add) if len(walls) > 1 else (walls[0] if walls else None)
    return parts, wall


def sphere_shell(crack: CrackSurface, spacing: float) -> m3.Manifold:
    """The thin shell on a ring crack's sphere."""
    half = 0.5 * SLAB_THICKNESS_FACTOR * spacing
    sagitta = SPHERE_SAGITTA_FACTOR * spacing
    segments = int(np.ceil(np.pi / np.arccos(max(1.0 - sagitta / crack.radius, -1.0)))) + 4
    segments = min(segments, 512)
    outer = m3.Manifold.sphere(crack.radius + half, segments)
    inner = m3.Manifold.sphere(max(crack.radius - half, 1e-9), segments)
    return (outer - inner).translate(tuple(crack.point))
