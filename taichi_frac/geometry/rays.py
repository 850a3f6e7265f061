"""First hits of short rays against a triangle set, in one Taichi kernel (f64), and the
ray-triangle test (``ray_triangle``) that ``collision_centres``' kernel shares.

``first_hits`` answers how far each of a few hundred short rays runs through a body's
boundary faces (``ray_exit_distance``; ``collision_centres`` does the same for the
boundary spheres it moves inward). It is faster than a vectorised numpy KD-tree query
with a Moller-Trumbore test on the candidates. The faces are sorted along the axis their centres spread
most on, each ray scans the slab of them within its reach with a bounding-sphere test
first (a face whose centre lies beyond the ray's reach plus the face's own radius cannot
be hit within the reach), and runs the Moller-Trumbore test on the rest.
"""


import numpy as np

from ..runtime import ti
from .. import runtime
from . import rows

_vec3 = ti.types.vector(3, ti.f64)
_vec4 = ti.types.vector(4, ti.f64)


@ti.func
def ray_triangle(o, d, v0, v1, v2, limit):
    """Distance t [m] along the ray o + t d (f64 3-vectors, d unit) to the triangle
    (v0, v1, v2) when it crosses it at 0 < t <= ``limit``, else inf (Moller-Trumbore;
    a triangle seen edge-on, |det| <= 1e-18, is not hit)."""
    t_hit = ti.cast(ti.math.inf, ti.f64)
    e1 = v1 - v0
    e2 = v2 - v0
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
            t_hit = t
    return t_hit


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
                best = ti.min(best, ray_triangle(o, d, _vec3(corners[f, 0, 0], corners[f, 0, 1], corners[f, 0, 2]),
                                                 _vec3(corners[f, 1, 0], corners[f, 1, 1], corners[f, 1, 2]),
                                                 _vec3(corners[f, 2, 0], corners[f, 2, 1], corners[f, 2, 2]), limit))
        hit_out[r] = best


def face_bounds(corners: np.ndarray):
    """Each triangle's centre (F,3) [m] and the farthest its corners lie from it (F,) [m],
    for ``corners`` (F,3,3): a triangle comes within r of a point only if its centre does
    within r + that radius."""
    centre = rows.corner_mean(corners)
    offset = corners - centre[:, None, :]
    return centre, np.sqrt(np.einsum("fki,fki->fk", offset, offset).max(axis=1))


def first_hits(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, direction: np.ndarray,
               reach: np.ndarray) -> np.ndarray:
    """(P,) [m] distance along each ray (``origin`` (P,3) [m], unit ``direction`` (P,3)) to
    the first of the triangles ``faces`` (F,3) over ``vertices`` (V,3) [m] it crosses
    within ``reach`` (P,) [m]; inf when none does. Triangles seen edge-on (|det| <= 1e-18)
    are not hit."""
    origin = np.ascontiguousarray(origin, dtype=np.float64).reshape(-1, 3)
    result = np.full(len(origin), np.inf)
    if len(origin) == 0 or len(faces) == 0:
        return result
    direction = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, 3)
    reach = np.ascontiguousarray(reach, dtype=np.float64).reshape(-1)
    corners = np.asarray(vertices, dtype=np.float64)[faces]  # (F,3,3)
    centre, radius = face_bounds(corners)
    if len(origin) * len(corners) <= SMALL_PAIRS:
        return _first_hits_numpy(corners, centre, radius, origin, direction, reach)
    runtime.init()
    # Faces sorted along the axis their centres spread most on: a ray scans only those
    # whose centre lies within its reach plus the largest face radius of it along that
    # axis (a slab: about a fifth of a ring piece's faces).
    axis = int(np.argmax(np.ptp(centre, axis=0)))
    order = np.argsort(centre[:, axis], kind="stable")
    corners = np.ascontiguousarray(corners[order])
    bounds = np.ascontiguousarray(np.column_stack([centre[order], radius[order]]))
    grown = reach + float(radius.max())
    scan = np.empty((len(origin), 2), dtype=np.int32)
    scan[:, 0] = np.searchsorted(bounds[:, axis], origin[:, axis] - grown, side="left")
    scan[:, 1] = np.searchsorted(bounds[:, axis], origin[:, axis] + grown, side="right")
    _first_hits(corners, bounds, origin, direction, reach, scan, result)
    return result


#: Up to this many ray-face pairs, every pair in numpy: for a fragment's chip (a few rays, a
#: few dozen faces) the kernel's launch and arguments cost more than the work.
SMALL_PAIRS = 4096


def _first_hits_numpy(corners, centre, radius, origin, direction, reach):
    """``first_hits`` over every ray-face pair (the same bounding test and Moller-Trumbore
    test as the kernel)."""
    result = np.full(len(origin), np.inf)
    gap = centre[None, :, :] - origin[:, None, :]  # (P,F,3)
    grown = reach[:, None] + radius[None, :]
    ray, face = np.nonzero(np.einsum("pfx,pfx->pf", gap, gap) <= grown * grown)
    if len(ray) == 0:
        return result
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
    return result


def near_faces(vertices, faces, points, reach) -> np.ndarray:
    """(P,) bool: does any of ``faces`` (F,3) come within ``reach`` (P,) [m] of ``points``
    (P,3) [m] (the nearest face centre's distance less the largest face's own radius; a
    conservative test)."""
    from scipy.spatial import cKDTree

    if len(faces) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    centre, radius = face_bounds(vertices[faces])
    distance, _ = cKDTree(centre).query(points)
    return distance < reach + float(radius.max())


def ray_exit_distance(vertices, faces, origin, direction, reach):
    """Distance [m] along each ray (origin (P,3) [m], unit direction (P,3)) to the first
    boundary face (F,3) it crosses within ``reach`` (P,) [m]; inf when none does.

    ``geometry.rays.first_hits``: one kernel, each ray testing only the faces whose
    bounding sphere comes within its reach (Moller-Trumbore). The model build's own
    thickness rays run inside ``geometry.collision_centres``' kernel (the same triangle
    test); this is the general query, and the tests' reference for them.
    """
    return first_hits(vertices, faces, origin, direction, reach)
