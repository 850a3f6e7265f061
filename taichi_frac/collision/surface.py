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

Where exactly one patch has a normal (a chip on a body's face) the normal is the
candidate with the largest gap (the least penetration, as in the separating-axis test):
B's patch normal or A's reversed (``pair``). Two patches that both have normals meet at
their hulls' distance: the largest gap over all directions, found by GJK's
closest-point search (``hull_pair``). Two without keep the spheres' contact
(``by_hulls``). Against the ground
the normal is +Z; against a static box it is the sphere's (out of the box at the point
of the box nearest the sphere's centre, where the box's support along it is that point).

A sphere without a patch (``point_count`` 0) is its own surface: its support along n is
its centre's less its radius, so a sphere body meets a patch body consistently.
"""

import taichi as ti

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

#: A patch that touches a static collider at one point (``against``'s ``single``: a landing,
#: or a body of many spheres) touches at the mean of its points within this fraction of
#: the sphere's radius of its lowest: a spot a little inside its lowest point, as a contact
#: area's middle is. It sets where a landing's impulse acts, and so how a tilted body
#: landing on one side turns: with it the report's ring drop matches the single-scale
#: reference's rebound and first impulse (``taichi-frac bench dynamics --contact-only``);
#: bands of 0.125-0.15 do, 0.1 and 0.175 or more turn the ring too much or too little.
SPOT_BAND = 0.14

#: Contacts a patch makes at most with one static collider: its manifold, spread over the
#: points within ``SUPPORT_BAND`` of its deepest (``manifold``). One contact at the
#: band's mean left a one-sphere chip lying on a face balanced on one point under its
#: middle: it rocked from corner to corner and never slept (22 of 36 one-tet chips awake
#: after 3 s); three or four corners hold it like a face.
MANIFOLD_POINTS = 4

#: Bodies of more collision spheres than this make one contact per patch with a static
#: collider (under the middle of its band, ``contact_spot``), not a manifold: their many
#: patches already hold them at many points, and four contacts a patch made a resting ring
#: five times the contacts of its spheres, which the serial solver paid for in every
#: iteration. A chip of a few spheres keeps its manifold (``MANIFOLD_POINTS``).
MANIFOLD_MAX_SPHERES = 16

#: The id (``manifold``'s ids) of the one contact a patch makes at the middle of its band
#: (``against``'s ``single``): past any patch's points.
SPOT_ID = 4095

#: Manifold points closer than this fraction of the sphere's radius to the ones already
#: kept (or to their line) add nothing: the manifold stops there.
MANIFOLD_SPREAD = 0.05


@ti.func
def lowest(particles: ti.template(), p, axis):
    """min over sphere ``p``'s patch points of point . ``axis`` (body frame) [m]; the
    sphere's own (centre . axis - radius |axis|) when it has no patch (``lowest3``'s
    arithmetic along one axis)."""
    low = particles.offset[p].dot(axis) - particles.radius[p] * ti.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    count = particles.point_count[p]
    if count > 0:
        low = 1e30
        start = particles.point_start[p]
        for k in range(start, start + count):
            low = ti.min(low, particles.surface_point[k].dot(axis))
    return low


@ti.func
def lowest3(particles: ti.template(), p, axes):
    """``lowest`` along each row of ``axes`` (mat3, body frame) at once: vec3 [m] (one
    pass over the points; the narrowphase's candidate normals share it)."""
    count = particles.point_count[p]
    reach = vec3(0.0)
    for r in ti.static(range(3)):
        reach[r] = ti.sqrt(axes[r, 0] ** 2 + axes[r, 1] ** 2 + axes[r, 2] ** 2)
    low = axes @ particles.offset[p] - particles.radius[p] * reach
    if count > 0:
        low = vec3(1e30)
        start = particles.point_start[p]
        for k in range(start, start + count):
            low = ti.min(low, axes @ particles.surface_point[k])
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
            if x.dot(axis) <= band:
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
        first_level = first.dot(axis)
        for k in range(start, start + count):
            x = particles.surface_point[k]
            level = x.dot(axis)
            if level < first_level:
                first = x
                first_level = level
                ids[0] = k - start
        # Second: farthest from the first.
        second = first
        best = spread2
        for k in range(start, start + count):
            x = particles.surface_point[k]
            if x.dot(axis) <= band and (x - first).norm_sqr() > best:
                best = (x - first).norm_sqr()
                second = x
                ids[1] = k - start
        edge = second - first
        third = first
        fourth = first
        if best > spread2:
            kept = 2
            # Third: farthest from the line first-second (largest triangle).
            best3 = spread2 * edge.norm_sqr()
            for k in range(start, start + count):
                x = particles.surface_point[k]
                area = (x - first).cross(edge).norm_sqr()
                if x.dot(axis) <= band and area > best3:
                    best3 = area
                    third = x
                    ids[2] = k - start
            if best3 > spread2 * edge.norm_sqr():
                kept = 3
                # Fourth: farthest from that line on the other side of it.
                side = (third - first).cross(edge)
                best4 = spread2 * edge.norm() * side.norm()
                for k in range(start, start + count):
                    x = particles.surface_point[k]
                    away = -(x - first).cross(edge).dot(side)
                    if x.dot(axis) <= band and away > best4:
                        best4 = away
                        fourth = x
                        ids[3] = k - start
                if best4 > spread2 * edge.norm() * side.norm():
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
    return particles.point_count[p] > 0 and particles.patch_facet[p, 0].norm_sqr() > 0.25


@ti.func
def _facet_rows(particles: ti.template(), p):
    """Sphere ``p``'s facets as the rows of a mat3 (body frame; zero rows unused)."""
    return ti.Matrix.rows([particles.patch_facet[p, 0], particles.patch_facet[p, 1], particles.patch_facet[p, 2]])


@ti.func
def pair(bodies: ti.template(), particles: ti.template(), a, i, o, j, centre_line):
    """The contact of sphere ``i`` of body ``a`` with sphere ``j`` of body ``o``: (normal
    from o into a (world, unit), gap [m] (< 0: penetration), a's contact spot, o's contact
    spot (world [m])). ``centre_line``: unit world direction from j's centre to i's."""
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
        candidates = _facet_rows(particles, j) @ rot_o.transpose()
    elif has_facets(particles, i):
        candidates = -(_facet_rows(particles, i) @ rot_a.transpose())
    for c in ti.static(range(3)):
        if candidates[c, 0] ** 2 + candidates[c, 1] ** 2 + candidates[c, 2] ** 2 > 0.25:
            usable[c] = 1.0
    low_a = lowest3(particles, i, candidates @ rot_a)
    low_o = lowest3(particles, j, -(candidates @ rot_o))
    gaps = candidates @ (x_a - x_o) + low_a + low_o
    best = 0
    best_gap = -1e30
    for c in range(3):
        if usable[c] > 0.0 and gaps[c] > best_gap:
            best_gap = gaps[c]
            best = c
    n = vec3(candidates[best, 0], candidates[best, 1], candidates[best, 2])
    spot_a = x_a + rot_a @ contact_spot(particles, i, rot_a.transpose() @ n, low_a[best])
    spot_o = x_o + rot_o @ contact_spot(particles, j, -(rot_o.transpose() @ n), low_o[best])
    return n, best_gap, spot_a, spot_o


#: Most directions the closest-point search of two patches' hulls tries (``hull_pair``):
#: each one pass over both patches' points. The support gap along a direction never exceeds
#: the hulls' true separation, so more directions only bring the gap closer to it. The
#: search resumes from the pair's simplex of the last substep and stops once converged
#: (``HULL_TOLERANCE``): 1.3 steps a search on average in the unbroken 13 rings, where
#: restarting each substep from the last normal took all of four. Tilted rings resting on
#: each other read their hulls' distance to 0.002 mm at the 90th percentile, 0.13 mm at
#: worst; a cap of four steps left one search in thirty off by over 0.6 mm (a resumed
#: simplex far from the new closest features), restarting from the last normal 0.37 mm at
#: the 90th percentile.
HULL_ITERATIONS = 6

#: The search runs on the hulls moved apart along the first direction by their overlap
#: plus this fraction of the larger sphere's radius (``hull_pair``): moved apart, they
#: have a closest-point direction even where they overlap.
HULL_SHIFT = 0.1

#: The search stops once no point of the hulls can lie nearer than its closest point by
#: more than this fraction of the larger sphere's radius (a few micrometres).
HULL_TOLERANCE = 1e-3


#: Two patches apart along a direction farther than this angle (its cosine, 60 degrees)
#: from either patch's normal do not touch (``_faces``; ``hull_pair`` reports them
#: ``APART``): they lie side by side on the surfaces, as the patches of two faces resting
#: on each other do, and a contact along their sideways gap would hold the faces from
#: sliding (a cube landing on a cube was thrown off it). A ring's patch spans 45 degrees
#: of its tube, so the top of a tube can be the rim of a patch whose normal leans 45
#: degrees: still a contact.
HULL_CONE = 0.5

#: Two bodies whose gap may close by more than this fraction of their spheres' mean radius
#: in a substep (the broadphase's bound of the pair's approach) meet on their spheres, not
#: their hulls (``narrowphase._test_pair``): so fast a pair reaches every sphere of the
#: other within that closing, and a closest-point search for each of those pairs made the
#: collision stage five times slower while the 13 rings fell on each other. At rest (the
#: closing is gravity's |g| dt^2 alone, a tenth of a radius) and at a slow landing the
#: hulls decide; a pair that meets on its spheres at speed settles onto its surfaces as it
#: slows. A patch may stand out of its sphere (``Particles.overhang``; half a radius in the
#: median for the 13 rings' pieces), so two patches can touch while their spheres are
#: still apart; between bodies the spheres are tested without the overhangs (with them,
#: so many more pairs were tested that the unbroken 13 rings took three times as long),
#: except a pair whose contact carried load in the last substep (``narrowphase._test_pair``).
HULL_APPROACH = 0.5

#: The gap [m] ``hull_pair`` reports for two patches side by side (``HULL_CONE``): too
#: wide for any contact.
APART = 1e3


@ti.func
def _support_pair(bodies: ti.template(), particles: ti.template(), a, i, o, j, n):
    """World points of sphere ``i``'s patch (body ``a``) lowest along ``n`` and of sphere
    ``j``'s (body ``o``) highest along it, and their rows in the two patches packed into one
    id (``_corner``; -1 where a sphere has no patch and is its own surface)."""
    rot_a = bodies.rotation[a]
    rot_o = bodies.rotation[o]
    p, row_a = _extreme(particles, i, rot_a.transpose() @ n)
    q, row_o = _extreme(particles, j, -(rot_o.transpose() @ n))
    packed = -1
    if row_a >= 0 and row_o >= 0:
        packed = row_a + row_o * ti.static(CORNER_BASE)
    return bodies.position[a] + rot_a @ p, bodies.position[o] + rot_o @ q, packed


#: Rows of two patches packed into one id: row in i's patch + CORNER_BASE x row in j's.
#: A patch holds tens of points.
CORNER_BASE = 1 << 15


@ti.func
def _corner(bodies: ti.template(), particles: ti.template(), a, i, o, j, packed):
    """The point of the Minkowski difference A - B (world [m]) that ``packed`` names
    (``_support_pair``), and whether it names one of the patches' present points."""
    row_a = packed % ti.static(CORNER_BASE)
    row_o = packed // ti.static(CORNER_BASE)
    valid = packed >= 0 and row_a < particles.point_count[i] and row_o < particles.point_count[j]
    point = vec3(0.0)
    if valid:
        point = (bodies.position[a] + bodies.rotation[a] @ particles.surface_point[particles.point_start[i] + row_a]
                 - bodies.position[o] - bodies.rotation[o] @ particles.surface_point[particles.point_start[j] + row_o])
    return point, valid


@ti.func
def _extreme(particles: ti.template(), p, axis):
    """Body-frame point of sphere ``p``'s patch lowest along the unit ``axis`` and its row
    in the patch (the sphere's own lowest point and -1 when it has no patch)."""
    point = particles.offset[p] - particles.radius[p] * axis
    row = -1
    count = particles.point_count[p]
    if count > 0:
        start = particles.point_start[p]
        point = particles.surface_point[start]
        row = 0
        low = point.dot(axis)  # (the best level kept: one dot product a point)
        for k in range(start + 1, start + count):
            x = particles.surface_point[k]
            level = x.dot(axis)
            if level < low:
                point = x
                low = level
                row = k - start
    return point, row


@ti.func
def _closest_on_triangle(a, b, c):
    """The point of triangle ``abc`` nearest the origin (Ericson, "Real-Time Collision
    Detection", 5.1.5: by the Voronoi regions of its corners and edges)."""
    ab = b - a
    ac = c - a
    d1 = -ab.dot(a)
    d2 = -ac.dot(a)
    d3 = -ab.dot(b)
    d4 = -ac.dot(b)
    d5 = -ab.dot(c)
    d6 = -ac.dot(c)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    tiny = 1e-30
    y = vec3(0.0)
    # (each weight clamped to the triangle: on a nearly degenerate triangle the f32
    # ratios of near-zero terms could put the point anywhere)
    if d1 <= 0.0 and d2 <= 0.0:
        y = a
    elif d3 >= 0.0 and d4 <= d3:
        y = b
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        y = a + ti.math.clamp(d1 / ti.max(d1 - d3, tiny), 0.0, 1.0) * ab
    elif d6 >= 0.0 and d5 <= d6:
        y = c
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        y = a + ti.math.clamp(d2 / ti.max(d2 - d6, tiny), 0.0, 1.0) * ac
    elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        y = b + ti.math.clamp((d4 - d3) / ti.max(d4 - d3 + d5 - d6, tiny), 0.0, 1.0) * (c - b)
    else:
        scale = 1.0 / ti.max(va + vb + vc, tiny)
        v = ti.math.clamp(vb * scale, 0.0, 1.0)
        w = ti.math.clamp(vc * scale, 0.0, 1.0 - v)
        y = a + ab * v + ac * w
    return y


@ti.func
def _faces(n, facets_i, facets_j):
    """Whether the contact normal ``n`` (from j's patch into i's) leaves j's patch or
    enters i's within ``HULL_CONE`` of one of its facets (rows of the world mat3s)."""
    return (facets_j @ n).max() >= ti.static(HULL_CONE) or (-(facets_i @ n)).max() >= ti.static(HULL_CONE)


@ti.func
def _better(bodies: ti.template(), particles: ti.template(), a, i, o, j, candidates, best_gap, n, low_a, low_o):
    """The best of the candidate normals (rows of ``candidates``, world; zero rows
    skipped) and the best so far (``best_gap`` [m] along ``n``, the patches' lowest levels
    ``low_a``, ``low_o`` along it): (gap, n, low_a, low_o) of the widest gap."""
    rot_a = bodies.rotation[a]
    rot_o = bodies.rotation[o]
    lows_a = lowest3(particles, i, candidates @ rot_a)
    lows_o = lowest3(particles, j, -(candidates @ rot_o))
    gaps = candidates @ (bodies.position[a] - bodies.position[o]) + lows_a + lows_o
    for c in ti.static(range(3)):
        row = vec3(candidates[c, 0], candidates[c, 1], candidates[c, 2])
        if row.norm_sqr() > 0.25 and gaps[c] > best_gap:
            best_gap = gaps[c]
            low_a = lows_a[c]
            low_o = lows_o[c]
            n = row
    return best_gap, n, low_a, low_o


@ti.func
def hull_pair(bodies: ti.template(), particles: ti.template(), a, i, o, j, centre_line, reach, warm, simplex):
    """``pair`` for two patches that both have a normal (two curved or flat surfaces):
    the signed distance of their convex hulls, max over unit
    n of the support gap

        gap(n) = min_{p in A} p . n - max_{q in B} q . n,

    the separation of separated hulls and minus the least overlap of overlapping ones (the
    separating-axis value), and the n that reaches it. Every gap(n) is a lower bound of
    it, so the search keeps the largest found: the centre line's and the normals' (as
    ``pair``), then the directions of GJK's search for the point of the Minkowski
    difference A - B nearest the origin (Gilbert, Johnson and Keerthi 1988: each step a
    pair of support points and the nearest point of a triangle; ``HULL_ITERATIONS``). So two
    stacked rings touch where their tubes meet, whatever the sphere radius. The hulls are
    moved apart along the first direction by their overlap (plus ``HULL_SHIFT`` of a
    radius) so that overlapping hulls have a closest-point direction too; the gaps are
    measured unmoved. Two patches side by side (``HULL_CONE``) are ``APART``. Once a gap
    exceeds ``reach`` [m] (the most a contact may be made at: the margin and the pair's
    closing) the search stops: the hulls are at least that far apart, and no contact
    spots are computed. ``warm`` (unit, world; zero for none): the pair's normal of the
    last substep, which replaces the centre line as the first candidate; ``simplex``
    (ivec3 of ``_corner`` ids, -1 for none): the pair's simplex of the last substep, where
    the search resumes (a resting pair's closest features are the same from substep to
    substep, so one step confirms them where a search from a single point took four).
    Returns ``pair``'s (normal from o into a, gap [m], a's spot, o's spot) and the
    simplex to resume from next substep."""
    rot_a = bodies.rotation[a]
    rot_o = bodies.rotation[o]
    x_a = bodies.position[a]
    x_o = bodies.position[o]
    # (both patches have facets, ``by_hulls``: each is a candidate, the separating axes of
    # their planes; a patch's first facet is its normal where it has one)
    facets_i = _facet_rows(particles, i) @ rot_a.transpose()
    facets_j = _facet_rows(particles, j) @ rot_o.transpose()
    warmed = warm.norm_sqr() > 0.25
    first = centre_line
    if warmed:
        first = warm
    # (each patch's lowest level along the best n so far, body frame: its contact spot's band)
    best_gap, n, low_a, low_o = _better(bodies, particles, a, i, o, j, ti.Matrix.rows(
        [first, vec3(facets_j[0, 0], facets_j[0, 1], facets_j[0, 2]),
         -vec3(facets_i[0, 0], facets_i[0, 1], facets_i[0, 2])]), -1e30, first, 0.0, 0.0)
    if particles.patch_normal[i].norm_sqr() < 0.25 or particles.patch_normal[j].norm_sqr() < 0.25:
        # A folded patch: its other facets too.
        best_gap, n, low_a, low_o = _better(bodies, particles, a, i, o, j, ti.Matrix.rows(
            [vec3(facets_j[1, 0], facets_j[1, 1], facets_j[1, 2]), vec3(facets_j[2, 0], facets_j[2, 1], facets_j[2, 2]),
             -vec3(facets_i[1, 0], facets_i[1, 1], facets_i[1, 2])]), best_gap, n, low_a, low_o)
        best_gap, n, low_a, low_o = _better(bodies, particles, a, i, o, j, ti.Matrix.rows(
            [-vec3(facets_i[2, 0], facets_i[2, 1], facets_i[2, 2]), vec3(0.0), vec3(0.0)]), best_gap, n, low_a, low_o)
    shift = (ti.max(-best_gap, 0.0) + ti.static(HULL_SHIFT) * ti.max(particles.radius[i], particles.radius[j])) * n
    steps = ti.static(HULL_ITERATIONS)
    searching = best_gap <= reach
    # GJK's simplex (up to a triangle of points of the moved hulls' Minkowski difference)
    # and its point closest to the origin.
    x = vec3(0.0)
    corner_a = x
    corner_b = x
    corner_c = x
    ids = ti.Vector([-1, -1, -1], dt=ti.i32)
    if searching:
        resumed = False
        if warmed:
            corner_a, valid_a = _corner(bodies, particles, a, i, o, j, simplex[0])
            corner_b, valid_b = _corner(bodies, particles, a, i, o, j, simplex[1])
            corner_c, valid_c = _corner(bodies, particles, a, i, o, j, simplex[2])
            if valid_a and valid_b and valid_c:
                resumed = True
                corner_a += shift
                corner_b += shift
                corner_c += shift
                ids = simplex
                x = _closest_on_triangle(corner_c, corner_a, corner_b)
        if not resumed:
            p, q, first_id = _support_pair(bodies, particles, a, i, o, j, n)
            x = p - q + shift
            corner_a = x
            corner_b = x
            corner_c = x
            ids = ti.Vector([first_id, first_id, first_id], dt=ti.i32)
    tolerance = ti.static(HULL_TOLERANCE) * ti.max(particles.radius[i], particles.radius[j])
    for step in range(steps):  # (dynamic: unrolled, each support pass was inlined)
        length = x.norm()
        if searching and length > 1e-12:
            d = x / length
            p, q, new_id = _support_pair(bodies, particles, a, i, o, j, d)
            gap = (p - q).dot(d)
            if gap > best_gap:
                best_gap = gap
                low_a = (p - x_a).dot(d)
                low_o = (x_o - q).dot(d)
                n = d
            new = p - q + shift
            # (no support point nearer the origin than x along d: x is the closest point;
            # a gap past ``reach`` already rules the contact out, a longer search only widens it)
            # (x . (x - new) / |x| bounds how much nearer the hulls may be than |x|: under
            # the tolerance, x is their closest point)
            searching = x.dot(x - new) > tolerance * length and best_gap <= reach and step + 1 < steps
            if searching:
                # The nearest to the origin of the faces the new point makes with the simplex.
                corners = (corner_a, corner_b, corner_c)
                closest = x
                near = 1e30
                kept = ids
                for u_index, v_index in ti.static(((0, 1), (0, 2), (1, 2))):
                    u = corners[u_index]
                    v = corners[v_index]
                    y = _closest_on_triangle(new, u, v)  # (new first: exact on a segment when u = v)
                    if y.norm_sqr() < near:
                        near = y.norm_sqr()
                        closest = y
                        corner_a = u
                        corner_b = v
                        corner_c = new
                        ids = ti.Vector([kept[u_index], kept[v_index], new_id], dt=ti.i32)
                x = closest
    if best_gap > 0.0 and not _faces(n, facets_i, facets_j):
        best_gap = ti.static(APART)
    spot_a = x_a
    spot_o = x_o
    if best_gap <= reach:  # (past it the caller makes no contact: its spots are not needed)
        spot_a = x_a + rot_a @ contact_spot(particles, i, rot_a.transpose() @ n, low_a)
        spot_o = x_o + rot_o @ contact_spot(particles, j, -(rot_o.transpose() @ n), low_o)
    return n, best_gap, spot_a, spot_o, ids


@ti.func
def by_hulls(particles: ti.template(), i, j):
    """Whether the contact of spheres ``i`` and ``j`` is their patches' hulls' distance
    (``hull_pair``): both have facets (two bodies' surfaces: a face's, a curved patch's
    normal, or the planes of a patch folded round a block's edge or corner). Along the patch
    normals alone the gap of two curved patches that do not face each other squarely is
    under-measured: five stacked rings stood 6.7 mm apart each. Two without (two small
    pieces facing every way) keep the spheres' contact: with their hulls' distance a chip
    among chips dropped at 10 m/s onto a slab was pushed 3.4 mm into it."""
    return has_facets(particles, i) and has_facets(particles, j)


@ti.func
def by_patches(particles: ti.template(), i, j):
    """Whether the contact of spheres ``i`` and ``j`` comes from their patches along the
    facets of one of them (``pair``): exactly one of the two has facets (a chip on a body's
    face or edge). Two with facets meet at their hulls' distance instead (``by_hulls``);
    two without keep the spheres' contact."""
    has_patch = particles.point_count[i] > 0 or particles.point_count[j] > 0
    faceted = ti.cast(has_facets(particles, i), ti.i32) + ti.cast(has_facets(particles, j), ti.i32)
    return has_patch and faceted == 1


@ti.func
def against(bodies: ti.template(), particles: ti.template(), a, i, n, level, single):
    """Sphere ``i`` of body ``a`` against a static collider whose support along the world
    normal ``n`` (out of the collider, into a) is ``level`` [m]: (gap [m] of the deepest
    point, and ``manifold``'s count, points (world [m]), levels along n and ids; the
    single point's id is ``SPOT_ID``). ``single``:
    one point instead, the middle of its ``SPOT_BAND`` (``contact_spot``), for an impact
    (the patch approaches faster than the restitution threshold) and for a body of more
    than ``MANIFOLD_MAX_SPHERES`` spheres (whose contacts ``reduction`` then thins out).
    Spread over four contacts, an impact's restitution was shared unevenly: the ring
    drop's rebound fell to 12.9 % under single-scale's, its first impulse to 4.1 % under."""
    rot_a = bodies.rotation[a]
    axis = rot_a.transpose() @ n
    low = lowest(particles, i, axis)
    count = 1
    points = ti.Matrix.zero(ti.f32, ti.static(MANIFOLD_POINTS), 3)
    levels = ti.Vector.zero(ti.f32, ti.static(MANIFOLD_POINTS))
    ids = ti.Vector([SPOT_ID] * MANIFOLD_POINTS, dt=ti.i32)
    if single:
        spot = contact_spot(particles, i, axis, low, SPOT_BAND)
        for c in ti.static(range(3)):
            points[0, c] = spot[c]
    else:
        count, points, levels, ids = manifold(particles, i, axis, low)
    points = points @ rot_a.transpose()
    for m in ti.static(range(MANIFOLD_POINTS)):
        for c in ti.static(range(3)):
            points[m, c] += bodies.position[a][c]
    return bodies.position[a].dot(n) + low - level, count, points, levels, ids
