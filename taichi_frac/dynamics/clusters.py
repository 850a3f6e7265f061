"""Cluster spheres: a few body-frame spheres that each enclose a group of a body's
collision spheres (``Bodies.cluster``), computed when the body is added. The
narrowphase's pre-test reads a body's sphere grid only where a sphere of the other body
comes near one of them (``narrowphase._pair_contacts``)."""


from ..runtime import ti
from ..kinematics import linalg3 as la
from .state import MAX_CLUSTERS

_vec3d = ti.types.vector(3, ti.f64)


@ti.func
def _centre(spheres: ti.template(), k):
    return _vec3d(spheres[k, 0], spheres[k, 1], spheres[k, 2])


@ti.func
def cluster_spheres(bodies: ti.template(), slot, spheres: ti.template(), begin, end, wanted,
                    nearest: ti.template()):
    """Body ``slot``'s cluster spheres (``Bodies.cluster``) over its collision spheres (rows
    ``begin`` to ``end`` of ``spheres`` (N,4) f64: body-frame centre [m], radius [m]), in
    f64: at most ``wanted`` seeds by farthest-point sampling (the first the sphere
    farthest from their mean), each cluster sphere at the mean of the spheres nearest its
    seed, its radius reaching the far side of every member (|offset - centre| + radius).
    ``nearest`` (N,) f64 is scratch (each sphere's squared distance to the nearest seed,
    then its cluster). Ties go to the lower index, as numpy's argmax/argmin."""
    mean = _vec3d(0.0)
    for k in range(begin, end):
        mean += _centre(spheres, k)
    mean /= ti.cast(end - begin, ti.f64)
    first = begin
    far = ti.cast(-1.0, ti.f64)
    for k in range(begin, end):
        d = _centre(spheres, k) - mean
        if la.dot(d, d) > far:
            far = la.dot(d, d)
            first = k
    seed_index = ti.Vector([0] * MAX_CLUSTERS, dt=ti.i32)
    seed_index[0] = first
    for k in range(begin, end):
        d = _centre(spheres, k) - _centre(spheres, first)
        nearest[k] = la.dot(d, d)
    seeds = 1
    while seeds < wanted:
        pick = begin
        for k in range(begin, end):
            if nearest[k] > nearest[pick]:
                pick = k
        if nearest[pick] <= 0.0:  # (coincident centres: fewer seeds)
            break
        seed_index[seeds] = pick
        seeds += 1
        for k in range(begin, end):
            d = _centre(spheres, k) - _centre(spheres, pick)
            nearest[k] = ti.min(nearest[k], la.dot(d, d))
    # Each sphere's cluster (its nearest seed), then each cluster's mean, then its reach.
    for k in range(begin, end):
        label = 0
        best = ti.cast(1e300, ti.f64)
        for m in range(seeds):
            d = _centre(spheres, k) - _centre(spheres, seed_index[m])
            if la.dot(d, d) < best:
                best = la.dot(d, d)
                label = m
        nearest[k] = label
    sums = ti.Matrix([[0.0] * 4 for _ in range(MAX_CLUSTERS)], ti.f64)  # centre sum, count; then centre, reach
    for k in range(begin, end):
        m = ti.cast(nearest[k], ti.i32)
        for x in ti.static(range(3)):
            sums[m, x] += spheres[k, x]
        sums[m, 3] += 1.0
    for m in range(seeds):
        for x in ti.static(range(3)):
            sums[m, x] /= sums[m, 3]
        sums[m, 3] = 0.0
    for k in range(begin, end):
        m = ti.cast(nearest[k], ti.i32)
        centre = _vec3d(sums[m, 0], sums[m, 1], sums[m, 2])
        sums[m, 3] = ti.max(sums[m, 3], la.norm(_centre(spheres, k) - centre) + spheres[k, 3])
    for m in range(seeds):
        bodies.cluster[slot, m] = ti.Vector([ti.cast(sums[m, c], ti.f32) for c in ti.static(range(4))], dt=ti.f32)
    bodies.cluster_count[slot] = seeds
