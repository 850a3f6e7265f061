"""First hits of short rays against a triangle set, in one Taichi kernel (f64).

The fragment model build asks, for each boundary sphere whose collision centre it moves
inward, how thick the body is behind it (``model.ray_exit_distance``): a few dozen to a
few hundred rays against a piece's boundary faces, each looked at only a few particle
radii far. The numpy version (a KD-tree ball query over the face centres, then the
Moller-Trumbore test on the candidates, vectorised) spent most of its time on the big
piece left when a chip breaks off a ring (90-200 rays, 1,700 faces, 54 candidates a ray)
building the tree, flattening the query's lists and gathering corners (3.1 ms a call
on a ring piece of over 1,000 faces; 1.3 here). Here the faces are sorted along the axis
their centres spread most on, each ray scans the slab of them within its reach with a
bounding-sphere test first (a face whose centre lies beyond the ray's reach plus the
face's own radius cannot be hit within the reach), and runs the same Moller-Trumbore
test on the rest.
"""


import numpy as np
import taichi as ti

from .. import runtime
from . import rows

_vec3 = ti.types.vector(3, ti.f64)
_vec4 = ti.types.vector(4, ti.f64)


@ti.kernel
def _first_hits(
    corners: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (F,3,3) [m] face corners
    bounds: ti.types.ndarray(dtype=_vec4, ndim=1),  # (F,4) [m] face centre, radius about it
    origin: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (P,3) [m]
    direction: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (P,3) unit
    reach: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (P,) [m]
    scan: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (P,2) faces [begin, end) ray p scans
    hit_out: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (P,) [m] first hit, or inf
):
    for r in range(origin.shape[0]):
        o = _vec3(origin[r, 0], origin[r, 1], origin[r, 2])
        d = _vec3(direction[r, 0], direction[r, 1], direction[r, 2])
        limit = reach[r]
        best = ti.cast(ti.math.inf, ti.f64)
        for f in range(scan[r, 0], scan[r, 1]):
            b = bounds[f]
            c = _vec3(b[0], b[1], b[2])
            grown = limit + b[3]
            if (c - o).norm_sqr() <= grown * grown:
                v0 = _vec3(corners[f, 0, 0], corners[f, 0, 1], corners[f, 0, 2])
                e1 = _vec3(corners[f, 1, 0], corners[f, 1, 1], corners[f, 1, 2]) - v0
                e2 = _vec3(corners[f, 2, 0], corners[f, 2, 1], corners[f, 2, 2]) - v0
                p = d.cross(e2)
                det = e1.dot(p)
                if ti.abs(det) > 1e-18:
                    inv = 1.0 / det
                    s = o - v0
                    u = s.dot(p) * inv
                    q = s.cross(e1)
                    v = d.dot(q) * inv
                    t = e2.dot(q) * inv
                    if u >= 0.0 and v >= 0.0 and u + v <= 1.0 and t > 0.0 and t <= limit:
                        best = ti.min(best, t)
        hit_out[r] = best


def face_bounds(corners: np.ndarray):
    """Each triangle's centre (F,3) [m] and the farthest its corners lie from it (F,) [m],
    for ``corners`` (F,3,3): a triangle comes within r of a point only if its centre does
    within r + that radius."""
    centre = rows.corner_mean(corners)
    offset = corners - centre[:, None, :]
    return centre, np.sqrt(np.einsum("fki,fki->fk", offset, offset).max(axis=1))


def first_hits(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, direction: np.ndarray,
               reach: np.ndarray, *, ray_group: np.ndarray | None = None,
               face_group: np.ndarray | None = None) -> np.ndarray:
    """(P,) [m] distance along each ray (``origin`` (P,3) [m], unit ``direction`` (P,3)) to
    the first of the triangles ``faces`` (F,3) over ``vertices`` (V,3) [m] it crosses
    within ``reach`` (P,) [m]; inf when none does. Triangles seen edge-on (|det| <= 1e-18)
    are not hit. ``ray_group`` (P,) and ``face_group`` (F,) (ints, both or neither): a ray
    crosses only the faces of its own group (the pieces of one split, built together);
    each group is answered as it would be alone, all of them in at most one kernel launch
    and one numpy pass."""
    origin = np.ascontiguousarray(origin, dtype=np.float64).reshape(-1, 3)
    result = np.full(len(origin), np.inf)
    if len(origin) == 0 or len(faces) == 0:
        return result
    direction = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, 3)
    reach = np.ascontiguousarray(reach, dtype=np.float64).reshape(-1)
    corners = np.asarray(vertices, dtype=np.float64)[faces]  # (F,3,3)
    centre, radius = face_bounds(corners)
    if ray_group is None:
        ray_group, face_group = np.zeros(len(origin), dtype=np.int64), np.zeros(len(faces), dtype=np.int64)
    ray_order = np.argsort(ray_group, kind="stable")
    face_order = np.argsort(face_group, kind="stable")
    groups, ray_start = np.unique(ray_group[ray_order], return_index=True)
    ray_start = np.append(ray_start, len(origin))
    face_start = np.searchsorted(face_group[face_order], groups, side="left")
    face_end = np.searchsorted(face_group[face_order], groups, side="right")
    small_rays, small_faces, big = [], [], []
    for k in range(len(groups)):
        rays = ray_order[ray_start[k]:ray_start[k + 1]]
        mine = face_order[face_start[k]:face_end[k]]
        if len(mine) == 0:
            continue
        if len(rays) * len(mine) <= SMALL_PAIRS:
            small_rays.append(np.repeat(rays, len(mine)))
            small_faces.append(np.tile(mine, len(rays)))
        else:
            big.append((rays, mine))
    if small_rays:
        _first_hits_numpy(corners, centre, radius, origin, direction, reach, np.concatenate(small_rays),
                          np.concatenate(small_faces), result)
    if big:
        runtime.init()
        # Each group's faces sorted along the axis their centres spread most on: a ray scans
        # only those of its group whose centre lies within its reach plus the group's
        # largest face radius along that axis (a slab: about a fifth of a ring piece's faces).
        sorted_faces, scans, rays_all, first = [], [], [], 0
        for rays, mine in big:
            axis = int(np.argmax(np.ptp(centre[mine], axis=0)))
            mine = mine[np.argsort(centre[mine, axis], kind="stable")]
            along = centre[mine, axis]
            grown = reach[rays] + float(radius[mine].max())
            scans.append(np.column_stack([np.searchsorted(along, origin[rays, axis] - grown, side="left"),
                                          np.searchsorted(along, origin[rays, axis] + grown, side="right")])
                         + first)
            sorted_faces.append(mine)
            rays_all.append(rays)
            first += len(mine)
        mine = np.concatenate(sorted_faces)
        rays = np.concatenate(rays_all)
        hits = np.empty(len(rays))
        _first_hits(np.ascontiguousarray(corners[mine]), np.ascontiguousarray(np.column_stack([centre[mine],
                    radius[mine]])), np.ascontiguousarray(origin[rays]), np.ascontiguousarray(direction[rays]),
                    np.ascontiguousarray(reach[rays]), np.concatenate(scans).astype(np.int32), hits)
        result[rays] = hits
    return result


#: Up to this many ray-face pairs in a group, every pair in numpy: a fragment's chip (a few
#: rays, a few dozen faces) took ~0.6 ms through the kernel's launch and arguments, ~0.1 ms
#: in numpy.
SMALL_PAIRS = 4096


def _first_hits_numpy(corners, centre, radius, origin, direction, reach, ray, face, result):
    """``first_hits`` over the candidate ray-face pairs ``ray``, ``face`` (N,) (the same
    bounding test and Moller-Trumbore test as the kernel), into ``result`` (P,)."""
    gap = centre[face] - origin[ray]
    grown = reach[ray] + radius[face]
    near = rows.dot(gap, gap) <= grown * grown
    ray, face = ray[near], face[near]
    if len(ray) == 0:
        return
    o, d = origin[ray], direction[ray]
    v0 = corners[face, 0]
    e1, e2 = corners[face, 1] - v0, corners[face, 2] - v0
    p = rows.cross(d, e2)
    det = rows.dot(e1, p)
    ok = np.abs(det) > 1e-18
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - v0
    u = rows.dot(s, p) * inv
    q = rows.cross(s, e1)
    v = rows.dot(d, q) * inv
    t = rows.dot(e2, q) * inv
    hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0) & (t <= reach[ray])
    np.minimum.at(result, ray[hit], t[hit])
