"""The collision centres of boundary groups (``contact_sphere_centres``: the formula
and why) in one Taichi kernel launch, f64.

In numpy the computation takes ~20 calls (normals, their sums per group, heights, spans)
plus the inward rays' own preparation and launch, mostly per-call overhead on a few
hundred groups. Here each group is one iteration: its
members' boundary faces give its normal and height, its members' centroids its span,
and its inward ray scans the faces of its own piece near it: the piece's faces lie in
cells along one axis and sorted along another in each, so the ray reads the runs of the
cells within its reach, found by binary search (a slab along one axis alone crosses a
ring twice: ~6 times the faces).
"""

import numpy as np

from ..runtime import ti
from .. import runtime
from . import rows
from .rays import ray_triangle

_vec3d = ti.types.vector(3, ti.f64)


@ti.func
def _corner(vertices: ti.template(), faces: ti.template(), f, k):
    v = faces[f, k]
    return _vec3d(vertices[v, 0], vertices[v, 1], vertices[v, 2])


@ti.func
def _first_index(key: ti.template(), begin, end, x, above: ti.template()):
    """The first index in [begin, end) whose ``key`` (ascending there) is >= x (``above``:
    > x), by binary search."""
    lo = begin
    hi = end
    while lo < hi:
        mid = (lo + hi) // 2
        before = key[mid] < x
        if ti.static(above):
            before = key[mid] <= x
        if before:
            lo = mid + 1
        else:
            hi = mid
    return lo


@ti.kernel
def _centres(
    vertices: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (V,3) [m]
    faces: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (F,3) boundary faces
    tet_faces: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (T+1,) each tet's faces (CSR starts)
    centroids: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (T,3) [m]
    member_offsets: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (G+1,) CSR over members
    members: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (M,) tets
    spheres: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (G,4) centre [m], radius [m]
    group_piece: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (G,)
    scan_faces: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (F,) faces by piece, cell, then along axis a
    scan_key: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (F,) [m] their centres along axis a
    scan_bounds: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (F,4) [m] their centres and radii about them
    cell_first: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (C+1,) each cell's first scan row
    pieces: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (P,7): first cell, cells, axis a, axis b,
    #   lowest face centre along b [m], cell size along b [m], largest face radius [m]
    work: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (G,4) scratch: normal sum, its length
    largest: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (P,) zeros: longest normal sum per piece
    out: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (G,3) [m] collision centres
):
    for g in range(spheres.shape[0]):
        # The area-weighted normals of the members' boundary faces, away from the owning tet.
        n_sum = _vec3d(0.0)
        for m in range(member_offsets[g], member_offsets[g + 1]):
            t = members[m]
            c = _vec3d(centroids[t, 0], centroids[t, 1], centroids[t, 2])
            for f in range(tet_faces[t], tet_faces[t + 1]):
                v0 = _corner(vertices, faces, f, 0)
                v1 = _corner(vertices, faces, f, 1)
                v2 = _corner(vertices, faces, f, 2)
                normal = (v1 - v0).cross(v2 - v0)
                side = ((v0 + v1 + v2) / 3.0 - c).dot(normal)
                if side > 0.0:
                    n_sum += normal
                elif side < 0.0:
                    n_sum -= normal
        for k in ti.static(range(3)):
            work[g, k] = n_sum[k]
        work[g, 3] = n_sum.norm()
        ti.atomic_max(largest[group_piece[g]], work[g, 3])
    for g in range(spheres.shape[0]):
        centre = _vec3d(spheres[g, 0], spheres[g, 1], spheres[g, 2])
        radius = spheres[g, 3]
        length = work[g, 3]
        piece = group_piece[g]
        n_unit = _vec3d(0.0)
        has_normal = length > 1e-12 * ti.max(largest[piece], 1e-300)
        if has_normal:
            n_unit = _vec3d(work[g, 0], work[g, 1], work[g, 2]) / ti.max(length, 1e-300)
        # The height of the true surface above the centre, and the members' span about the normal.
        h = -ti.cast(ti.math.inf, ti.f64)
        rho = ti.cast(0.0, ti.f64)
        for m in range(member_offsets[g], member_offsets[g + 1]):
            t = members[m]
            for f in range(tet_faces[t], tet_faces[t + 1]):
                for k in ti.static(range(3)):
                    h = ti.max(h, (_corner(vertices, faces, f, k) - centre).dot(n_unit))
            rel = _vec3d(centroids[t, 0], centroids[t, 1], centroids[t, 2]) - centre
            along = rel.dot(n_unit)
            rho = ti.max(rho, ti.sqrt(ti.max(rel.dot(rel) - along * along, 0.0)))
        cover = ti.sqrt(ti.max(radius * radius - rho * rho, 0.0))
        shift = ti.cast(0.0, ti.f64)
        if has_normal and h > -ti.math.inf:
            shift = ti.min(radius, cover) - h
        if shift > 0.0:
            # The body's thickness behind the centre: the first face of its piece the inward
            # ray crosses within shift + radius (no further can bound the shift).
            reach = shift + radius
            d = -n_unit
            first_cell = ti.cast(pieces[piece, 0], ti.i32)
            cells = ti.cast(pieces[piece, 1], ti.i32)
            axis_a = ti.cast(pieces[piece, 2], ti.i32)
            axis_b = ti.cast(pieces[piece, 3], ti.i32)
            size = pieces[piece, 5]
            # The face centres that can matter lie within the reach plus the largest face
            # radius of the centre: the cells along b that far, in each the run along a.
            grown = reach + pieces[piece, 6]
            home = ti.cast(ti.floor((centre[axis_b] - pieces[piece, 4]) / size), ti.i32)
            span = ti.cast(ti.ceil(grown / size), ti.i32)
            thickness = ti.cast(ti.math.inf, ti.f64)
            for cell in range(ti.max(home - span, 0), ti.min(home + span, cells - 1) + 1):
                begin = cell_first[first_cell + cell]
                end = cell_first[first_cell + cell + 1]
                lo = _first_index(scan_key, begin, end, centre[axis_a] - grown, False)
                hi = _first_index(scan_key, begin, end, centre[axis_a] + grown, True)
                for s in range(lo, hi):
                    # Only a face whose bounding sphere meets the ray's segment can be hit
                    # (tested on the nearest point of the segment to the face's centre).
                    mid = _vec3d(scan_bounds[s, 0], scan_bounds[s, 1], scan_bounds[s, 2])
                    along = ti.min(ti.max((mid - centre).dot(d), 0.0), reach)
                    if (mid - centre - along * d).norm_sqr() <= scan_bounds[s, 3] * scan_bounds[s, 3]:
                        f = scan_faces[s]
                        thickness = ti.min(thickness, ray_triangle(centre, d, _corner(vertices, faces, f, 0),
                                                                   _corner(vertices, faces, f, 1),
                                                                   _corner(vertices, faces, f, 2), reach))
            shift = ti.min(shift, thickness - radius)
        shift = ti.max(shift, 0.0)
        for k in ti.static(range(3)):
            out[g, k] = centre[k] - shift * n_unit[k]


def collision_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius, group_piece, face_piece):
    """The kernel's arguments from ``contact_sphere_centres``' and its launch:
    (G,3) [m] collision centres. ``owner`` (M,) the group of each member (grouped
    together, in order), ``group_piece`` (G,) and ``face_piece`` (F,) the pieces."""
    group_count = len(b_pos)
    if group_count == 0 or len(faces) == 0:
        return np.array(b_pos, dtype=np.float64, copy=True)
    runtime.init()
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    face_tet = np.asarray(face_tet)
    by_tet = np.argsort(face_tet, kind="stable")
    faces, face_tet, face_piece = faces[by_tet], face_tet[by_tet], np.asarray(face_piece)[by_tet]
    owner = np.asarray(owner)
    by_group = np.argsort(owner, kind="stable")
    members, owner = np.asarray(members)[by_group], owner[by_group]
    # Each piece's faces in cells along the axis b their centres spread second most on
    # (a mean group radius plus the largest face radius wide: a ray reads as many as its
    # reach spans), and in each cell sorted along the axis a of the most spread.
    corners = vertices[faces]
    mid = rows.corner_mean(corners)
    offset = corners - mid[:, None, :]
    face_radius = np.sqrt(np.einsum("fki,fki->fk", offset, offset).max(axis=1))
    piece_count = int(max(group_piece.max(), face_piece.max())) + 1
    by_piece = np.argsort(face_piece, kind="stable")
    starts = np.searchsorted(face_piece[by_piece], np.arange(piece_count + 1))
    present = starts[:-1] < starts[1:]
    first = starts[:-1][present]
    lowest, spread, largest_face = np.zeros((piece_count, 3)), np.zeros((piece_count, 3)), np.zeros(piece_count)
    lowest[present] = np.minimum.reduceat(mid[by_piece], first)
    spread[present] = np.maximum.reduceat(mid[by_piece], first) - lowest[present]
    largest_face[present] = np.maximum.reduceat(face_radius[by_piece], first)
    axes = np.argsort(-spread, axis=1, kind="stable")
    axis_a, axis_b = axes[:, 0], axes[:, 1]
    mean_radius = np.bincount(group_piece, weights=b_radius, minlength=piece_count) / np.maximum(
        np.bincount(group_piece, minlength=piece_count), 1)
    size = np.maximum(mean_radius + largest_face, 1e-9)
    cell = np.floor((mid[np.arange(len(faces)), axis_b[face_piece]] - lowest[face_piece, axis_b[face_piece]])
                    / size[face_piece]).astype(np.int64)
    cells = np.zeros(piece_count, dtype=np.int64)
    np.maximum.at(cells, face_piece, cell + 1)
    first_cell = np.cumsum(cells) - cells
    key = mid[np.arange(len(faces)), axis_a[face_piece]]
    scan = np.lexsort((key, first_cell[face_piece] + cell))
    cell_first = np.searchsorted((first_cell[face_piece] + cell)[scan], np.arange(cells.sum() + 1)).astype(np.int32)
    pieces = np.column_stack([first_cell, cells, axis_a, axis_b, lowest[np.arange(piece_count), axis_b], size,
                              largest_face]).astype(np.float64)
    out = np.empty((group_count, 3))
    _centres(vertices, np.ascontiguousarray(faces, dtype=np.int32),
             np.searchsorted(face_tet, np.arange(len(centroids) + 1)).astype(np.int32),
             np.ascontiguousarray(centroids, dtype=np.float64),
             np.searchsorted(owner, np.arange(group_count + 1)).astype(np.int32),
             np.ascontiguousarray(members, dtype=np.int32),
             np.ascontiguousarray(np.column_stack([b_pos, b_radius]), dtype=np.float64),
             np.ascontiguousarray(group_piece, dtype=np.int32), scan.astype(np.int32),
             np.ascontiguousarray(key[scan]), np.ascontiguousarray(np.column_stack([mid[scan], face_radius[scan]])),
             cell_first, np.ascontiguousarray(pieces), np.empty((group_count, 4)), np.zeros(piece_count), out)
    return out


#: A kept boundary group's collision centre is computed again when a crack face lies
#: within this many of its radii of its centre: the centre moves inward by less than
#: 2 radii (``contact_sphere_centres``: at most R - h, h > -R for a surface group's own
#: faces) and the thickness ray looks a radius beyond that.
CENTRE_REACH = 3.0


def contact_sphere_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius, *,
                           group_piece=None, face_piece=None):
    """Collision centres of the boundary spheres (see ``BodyModel.boundary_contact_position``).

    For each group: its outward normal n (area-weighted normals of its members' boundary
    faces), the height h of the true surface above its centre along n (largest over those
    faces' vertices), the radius rho its members' centroids span about the normal axis,
    and the body's thickness t behind the centre along -n (``ray_exit_distance`` against
    the boundary faces, looked at only as far as the limit can bind, s + R).
    The centre moves inward by

        s = min(R - h, sqrt(R^2 - rho^2) - h, t - R), at least 0:

    toward putting the sphere's outermost point on the surface (R - h), but never so far
    that its cross-section at the surface stops covering its members (so neighbouring
    spheres leave no hole a small body could fall through, even on a coarse mesh), and
    never so far that it pokes out behind (t - R).

    ``group_piece`` (G,) and ``face_piece`` (F,): the piece of each group and face when
    several bodies' groups are given at once (``_assemble``): each group then looks only
    at its own piece's faces, and the smallest normal counted as one is relative to its
    own piece's largest. None: one body. One kernel launch
    (``geometry.collision_centres``); tests/test_model_two_scale.py checks it against
    this formula in numpy.
    """
    if group_piece is None:
        group_piece, face_piece = np.zeros(len(b_pos), dtype=np.int64), np.zeros(len(faces), dtype=np.int64)
    return collision_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius,
                             np.asarray(group_piece), np.asarray(face_piece))
