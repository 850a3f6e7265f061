"""Contacts from the true surface: the narrowphase's spheres say which parts of two bodies
may touch; this module says where, along which normal and how deep, from the surface
patches behind the spheres (``geometry.contact_patches.ContactPatches``: the vertices of the boundary
triangles of each sphere's member tets, in the body frame).

Depth along a normal n is the gap between the two patches' supports (the separating-axis
measure of their convex hulls):

    gap(n) = min_{p in A} p . n - max_{q in B} q . n      (n from B into A)

which depends on the surface alone, not on the sphere radius, so a flat face rests on the
ground at its own height and a patch seen by two overlapping spheres is as deep in both.
A patch's support along n extends over the plane through it, so a chip between two
patches of a flat body is held by whichever sphere sees it: no hole opens between them.
That plane is held only near the patch (``PLANE_REACH``): farther along the line between
the spheres' centres, the gap is at least the patches' gap along that line less the reach.

Where exactly one patch has a normal (a chip on a body's face) the normal is the
candidate with the largest gap (the least penetration, as in the separating-axis test):
B's patch normal or A's reversed (``pair``). Two patches that both have normals meet at
their hulls' distance: the largest gap over all directions, found by GJK's
closest-point search (``hulls.hull_pair``). Two without keep the spheres' contact
(``hulls.by_hulls``). Against the ground the normal is +Z; against a static box it is the sphere's (out of the box at the point
of the box nearest the sphere's centre, where the box's support along it is that point).

A sphere without a patch (``point_count`` 0) is its own surface: its support along n is
its centre's less its radius, so a sphere body meets a patch body consistently.
"""


from ..runtime import ti
from ..kinematics import linalg3 as la

vec3 = ti.math.vec3

#: A patch gap deeper than this fraction of the larger sphere's radius is not trusted: the
#: narrowphase keeps the spheres' contact instead (``narrowphase._test_pair``). Speculative
#: contacts keep real penetrations shallow; so deep a gap is a patch seen from behind (a
#: sphere on the far face of a body thinner than it, reaching through to a chip on the
#: near face), whose normal would push the chip through. The solver's own deep-overlap
#: rule (``solver.DEEP_OVERLAP``) has the same bound.
TRUSTED_DEPTH = 0.5

#: Points within this fraction of the sphere's radius of a patch's deepest point share the
#: contact: against a static collider they are its ``manifold``; against a chip, the
#: contact point is their mean (a flat patch touches over its face, not at whichever corner
#: comes first).
SUPPORT_BAND = 0.1

#: How far [fraction of the smaller sphere's radius] past a patch its facet's plane holds
#: the other patch at full depth (``pair``): where the two patches lie farther apart than
#: this along the line between their spheres' centres, the gap is at least that distance
#: less this reach. Within it, a chip resting on a body over a patch that no sphere of its
#: own is tested against (a one-tet chip's corners stand out of its sphere) is held by
#: the neighbouring patch's plane. Without a bound, a chip wedged between two pieces reads
#: deep into the plane of a face far from the other patch, its contacts' depths jump from
#: one substep to the next, and it keeps its neighbours awake.
PLANE_REACH = 0.5

#: A landing patch (``against``'s ``landing``: approaching a static collider faster than
#: the restitution threshold) touches at the mean of its points level with its lowest to
#: within this fraction of the sphere's radius: its lowest vertex, or the middle of a face
#: or edge lying level. That is where a rigid body struck at one point is struck, so a
#: tilted ring landing without friction takes the closed-form impulse at every tilt and
#: grouping n (the contact page measures it); the middle of a contact area would lie nearer
#: the body's centre and overstate the impulse.
LANDING_BAND = 0.001

#: A patch of a body of many spheres resting on a static collider (one contact a patch,
#: ``against``'s single point) touches at the mean of its points within this fraction of the
#: sphere's radius of its lowest: a contact area's middle, which stays put while the body
#: rocks by less than the band, where its lowest vertex hops from vertex to vertex. (The
#: 13 unbreakable rings settle about as fast either way: single runs of the pile differ
#: by more than the choice makes.)
SPOT_BAND = 0.14

#: Contacts a patch makes at most with one static collider: its manifold, spread over the
#: points within ``SUPPORT_BAND`` of its deepest (``manifold``). One contact at the
#: band's mean left a one-sphere chip lying on a face balanced on one point under its
#: middle: it rocked from corner to corner and never slept; three or four corners hold it
#: like a face.
MANIFOLD_POINTS = 4

#: Bodies of more collision spheres than this make one contact per patch with a static
#: collider (under the middle of its band, ``contact_spot``), not a manifold: their many
#: patches already hold them at many points, and four contacts a patch made a resting ring
#: five times the contacts of its spheres, which the serial solver paid for in every
#: iteration. A chip of a few spheres keeps its manifold (``MANIFOLD_POINTS``).
MANIFOLD_MAX_SPHERES = 16

#: The id (``manifold``'s ids) of the one contact a patch makes at the middle of its band
#: (``against``'s single point): past any patch's points.
SPOT_ID = 4095

#: Manifold points closer than this fraction of the sphere's radius to the ones already
#: kept (or to their line) add nothing: the manifold stops there.
MANIFOLD_SPREAD = 0.05


@ti.func
def lowest(particles: ti.template(), p, axis):
    """min over sphere ``p``'s patch points of point . ``axis`` (body frame) [m]; the
    sphere's own (centre . axis - radius |axis|) when it has no patch (``lowest3``'s
    arithmetic along one axis)."""
    low = la.dot(particles.offset[p], axis) - particles.radius[p] * ti.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    count = particles.point_count[p]
    if count > 0:
        low = 1e30
        start = particles.point_start[p]
        for k in range(start, start + count):
            low = ti.min(low, la.dot(particles.surface_point[k], axis))
    return low


@ti.func
def lowest3(particles: ti.template(), p, axes):
    """``lowest`` along each row of ``axes`` (mat3, body frame) at once: vec3 [m] (one
    pass over the points; the narrowphase's candidate normals share it)."""
    count = particles.point_count[p]
    reach = vec3(0.0)
    for r in ti.static(range(3)):
        reach[r] = ti.sqrt(axes[r, 0] ** 2 + axes[r, 1] ** 2 + axes[r, 2] ** 2)
    low = la.mat_vec(axes, particles.offset[p]) - particles.radius[p] * reach
    if count > 0:
        low = vec3(1e30)
        start = particles.point_start[p]
        for k in range(start, start + count):
            low = ti.min(low, la.mat_vec(axes, particles.surface_point[k]))
    return low


@ti.func
def contact_spot(particles: ti.template(), p, axis, low, band_fraction=SUPPORT_BAND):
    """Body-frame mean of sphere ``p``'s patch points within ``band_fraction`` of its radius
    of the lowest level ``low`` along ``axis`` (the sphere's lowest point when it has no
    patch)."""
    count = particles.point_count[p]
    spot = particles.offset[p] - particles.radius[p] * axis
    if count > 0:
        band = low + band_fraction * particles.radius[p]
        total = vec3(0.0)
        weight = 0.0
        start = particles.point_start[p]
        for k in range(start, start + count):
            x = particles.surface_point[k]
            if la.dot(x, axis) <= band:
                total += x
                weight += 1.0
        spot = total / weight
    return spot


@ti.func
def manifold(particles: ti.template(), p, axis, low):
    """Up to ``MANIFOLD_POINTS`` of sphere ``p``'s patch points within ``SUPPORT_BAND`` of
    its radius of the lowest level ``low`` along ``axis`` (body frame), spread over that
    band the way a box's contact face is reduced to its corners (Bullet's
    ``btPersistentManifold::sortCachedPoints`` keeps the largest area): the deepest point,
    the band point farthest from it, the one farthest from their line, and the one
    farthest on the other side of that line. Returns (count, points (mat 4x3, body frame
    [m], rows past ``count`` unused), levels (vec4 [m]: each point's height above ``low``
    along ``axis``), ids (ivec4: each point's row in the patch, which names its contact
    for warm starting whatever order the points are picked in)). A sphere without a
    patch: its lowest point, count 1, id 0."""
    points = ti.Matrix.zero(ti.f32, ti.static(MANIFOLD_POINTS), 3)
    levels = ti.Vector.zero(ti.f32, ti.static(MANIFOLD_POINTS))
    ids = ti.Vector.zero(ti.i32, ti.static(MANIFOLD_POINTS))
    kept = 1
    start = particles.point_start[p]
    count = particles.point_count[p]
    radius = particles.radius[p]
    first = particles.offset[p] - radius * axis
    if count > 0:
        band = low + SUPPORT_BAND * radius
        spread2 = (MANIFOLD_SPREAD * radius) ** 2
        first = particles.surface_point[start]
        first_level = la.dot(first, axis)
        for k in range(start, start + count):
            x = particles.surface_point[k]
            level = la.dot(x, axis)
            if level < first_level:
                first = x
                first_level = level
                ids[0] = k - start
        # Second: farthest from the first.
        second = first
        best = spread2
        for k in range(start, start + count):
            x = particles.surface_point[k]
            if la.dot(x, axis) <= band and la.norm_sqr(x - first) > best:
                best = la.norm_sqr(x - first)
                second = x
                ids[1] = k - start
        edge = second - first
        third = first
        fourth = first
        if best > spread2:
            kept = 2
            # Third: farthest from the line first-second (largest triangle).
            best3 = spread2 * la.norm_sqr(edge)
            for k in range(start, start + count):
                x = particles.surface_point[k]
                area = la.norm_sqr(la.cross(x - first, edge))
                if la.dot(x, axis) <= band and area > best3:
                    best3 = area
                    third = x
                    ids[2] = k - start
            if best3 > spread2 * la.norm_sqr(edge):
                kept = 3
                # Fourth: farthest from that line on the other side of it.
                side = la.cross(third - first, edge)
                best4 = spread2 * la.norm(edge) * la.norm(side)
                for k in range(start, start + count):
                    x = particles.surface_point[k]
                    away = -la.dot(la.cross(x - first, edge), side)
                    if la.dot(x, axis) <= band and away > best4:
                        best4 = away
                        fourth = x
                        ids[3] = k - start
                if best4 > spread2 * la.norm(edge) * la.norm(side):
                    kept = 4
        rows = ti.Matrix.rows([first, second, third, fourth])
        for m in ti.static(range(MANIFOLD_POINTS)):
            for d in ti.static(range(3)):
                points[m, d] = rows[m, d]
            levels[m] = rows[m, 0] * axis[0] + rows[m, 1] * axis[1] + rows[m, 2] * axis[2] - low
    else:
        for d in ti.static(range(3)):
            points[0, d] = first[d]
    return kept, points, levels, ids


@ti.func
def has_facets(particles: ti.template(), p):
    """Whether sphere ``p``'s patch lies in a few planes (``ContactPatches.facets``): a
    face's patch, or one folded round a block's edge or corner."""
    return particles.point_count[p] > 0 and la.norm_sqr(particles.patch_facet[p, 0]) > 0.25


@ti.func
def _facet_rows(particles: ti.template(), p):
    """Sphere ``p``'s facets as the rows of a mat3 (body frame; zero rows unused)."""
    return ti.Matrix.rows([particles.patch_facet[p, 0], particles.patch_facet[p, 1], particles.patch_facet[p, 2]])


@ti.func
def pair(bodies: ti.template(), particles: ti.template(), a, i, o, j, centre_line):
    """The contact of sphere ``i`` of body ``a`` with sphere ``j`` of body ``o``: (normal
    from o into a (world, unit), gap [m] (< 0: penetration), a's contact spot, o's contact
    spot (world [m])). ``centre_line``: unit world direction from j's centre to i's. The
    gap is the largest of the candidates' and, where the patches lie apart along the
    centre line, that separation less ``PLANE_REACH``: a facet's plane holds what lies near
    its patch, not a patch of another body far beside it."""
    rot_a = bodies.rotation[a]
    rot_o = bodies.rotation[o]
    x_a = bodies.position[a]
    x_o = bodies.position[o]
    # Rows: the candidate normals (world): the facets of the patch that has them (j's, or
    # i's reversed), the separating axes of its planes; the centre line only when neither
    # has: a patch is backed by its body, and an oblique line past its rim would let a
    # chip that sank into it out sideways.
    usable = vec3(0.0)
    candidates = ti.Matrix.rows([centre_line, vec3(0.0), vec3(0.0)])
    if has_facets(particles, j):
        candidates = la.mat_mat_t(_facet_rows(particles, j), rot_o)
    elif has_facets(particles, i):
        candidates = -la.mat_mat_t(_facet_rows(particles, i), rot_a)
    for c in ti.static(range(3)):
        if candidates[c, 0] ** 2 + candidates[c, 1] ** 2 + candidates[c, 2] ** 2 > 0.25:
            usable[c] = 1.0
    low_a = lowest3(particles, i, la.mat_mat(candidates, rot_a))
    low_o = lowest3(particles, j, -la.mat_mat(candidates, rot_o))
    gaps = la.mat_vec(candidates, x_a - x_o) + low_a + low_o
    best = 0
    best_gap = -1e30
    for c in range(3):
        if usable[c] > 0.0 and gaps[c] > best_gap:
            best_gap = gaps[c]
            best = c
    n = vec3(candidates[best, 0], candidates[best, 1], candidates[best, 2])
    # (the patches' gap along the centre line is a lower bound of their hulls' distance)
    apart = la.dot(centre_line, x_a - x_o) + lowest(particles, i, la.mat_t_vec(rot_a, centre_line)) \
        + lowest(particles, j, -(la.mat_t_vec(rot_o, centre_line)))
    best_gap = ti.max(best_gap, apart - ti.static(PLANE_REACH) * ti.min(particles.radius[i], particles.radius[j]))
    spot_a = x_a + la.mat_vec(rot_a, contact_spot(particles, i, la.mat_t_vec(rot_a, n), low_a[best]))
    spot_o = x_o + la.mat_vec(rot_o, contact_spot(particles, j, -(la.mat_t_vec(rot_o, n)), low_o[best]))
    return n, best_gap, spot_a, spot_o


@ti.func
def by_patches(particles: ti.template(), i, j):
    """Whether the contact of spheres ``i`` and ``j`` comes from their patches along the
    facets of one of them (``pair``): exactly one of the two has facets (a chip on a body's
    face or edge). Two with facets meet at their hulls' distance instead (``hulls.by_hulls``);
    two without keep the spheres' contact."""
    has_patch = particles.point_count[i] > 0 or particles.point_count[j] > 0
    faceted = ti.cast(has_facets(particles, i), ti.i32) + ti.cast(has_facets(particles, j), ti.i32)
    return has_patch and faceted == 1


@ti.func
def against(bodies: ti.template(), particles: ti.template(), a, i, n, level, landing):
    """Sphere ``i`` of body ``a`` against a static collider whose support along the world
    normal ``n`` (out of the collider, into a) is ``level`` [m]: (gap [m] of the deepest
    point, and ``manifold``'s count, points (world [m]), levels along n and ids; the
    single point's id is ``SPOT_ID``). One point instead (``contact_spot``) for an impact
    (``landing``: the patch approaches faster than the restitution threshold; at its lowest
    point, ``LANDING_BAND``) and for a body of more than ``MANIFOLD_MAX_SPHERES`` spheres
    (whose contacts ``reduction`` then thins out; at the middle of its ``SPOT_BAND``).
    Spread over four contacts, an impact's restitution was shared unevenly: the ring
    drop's rebound fell to 12.9 % under single-scale's, its first impulse to 4.1 % under."""
    rot_a = bodies.rotation[a]
    axis = la.mat_t_vec(rot_a, n)
    low = lowest(particles, i, axis)
    count = 1
    points = ti.Matrix.zero(ti.f32, ti.static(MANIFOLD_POINTS), 3)
    levels = ti.Vector.zero(ti.f32, ti.static(MANIFOLD_POINTS))
    ids = ti.Vector([SPOT_ID] * MANIFOLD_POINTS, dt=ti.i32)
    if landing or bodies.particle_count[a] > ti.static(MANIFOLD_MAX_SPHERES):
        spot = contact_spot(particles, i, axis, low, ti.select(landing, LANDING_BAND, SPOT_BAND))
        for c in ti.static(range(3)):
            points[0, c] = spot[c]
    else:
        count, points, levels, ids = manifold(particles, i, axis, low)
    points = points @ rot_a.transpose()
    for m in ti.static(range(MANIFOLD_POINTS)):
        for c in ti.static(range(3)):
            points[m, c] += bodies.position[a][c]
    return la.dot(bodies.position[a], n) + low - level, count, points, levels, ids
