"""Two surface patches that both have a normal meet at their convex hulls' distance: the
largest support gap over all directions (``surface``'s gap(n)), found by GJK's search for the
point of the hulls' Minkowski difference nearest the origin (``hull_pair``). So two stacked
rings touch where their tubes meet, whatever the sphere radius; ``surface.pair`` handles a
patch with a normal against one without, and ``surface.against`` the static colliders.
"""


from ..runtime import ti
from ..kinematics import linalg3 as la
from .surface import _facet_rows, contact_spot, has_facets, lowest3

vec3 = ti.math.vec3


#: Most directions the closest-point search of two patches' hulls tries (``hull_pair``):
#: each one pass over both patches' points. The support gap along a direction never exceeds
#: the hulls' true separation, so more directions only bring the gap closer to it. The
#: search resumes from the pair's simplex of the last substep and stops once converged
#: (``HULL_TOLERANCE``), so most searches take one or two steps; the cap bounds the rare
#: search whose resumed simplex lies far from the new closest features
#: (``test_contact_surface``'s tilted tori check the distances).
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
#: median for broken pieces), so two patches can touch while their spheres are still
#: apart; between bodies the spheres are tested without the overhangs (with them, far more
#: pairs are tested), except a pair whose contact carried load in the last substep
#: (``narrowphase._test_pair``).
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
    p, row_a = _extreme(particles, i, la.mat_t_vec(rot_a, n))
    q, row_o = _extreme(particles, j, -(la.mat_t_vec(rot_o, n)))
    packed = -1
    if row_a >= 0 and row_o >= 0:
        packed = row_a + row_o * ti.static(CORNER_BASE)
    return bodies.position[a] + la.mat_vec(rot_a, p), bodies.position[o] + la.mat_vec(rot_o, q), packed


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
        point_a = particles.surface_point[particles.point_start[i] + row_a]
        point_o = particles.surface_point[particles.point_start[j] + row_o]
        point = (bodies.position[a] + la.mat_vec(bodies.rotation[a], point_a)
                 - bodies.position[o] - la.mat_vec(bodies.rotation[o], point_o))
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
        low = la.dot(point, axis)  # (the best level kept: one dot product a point)
        for k in range(start + 1, start + count):
            x = particles.surface_point[k]
            level = la.dot(x, axis)
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
    d1 = -la.dot(ab, a)
    d2 = -la.dot(ac, a)
    d3 = -la.dot(ab, b)
    d4 = -la.dot(ac, b)
    d5 = -la.dot(ab, c)
    d6 = -la.dot(ac, c)
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
    return (la.mat_vec(facets_j, n).max() >= ti.static(HULL_CONE)
            or (-la.mat_vec(facets_i, n)).max() >= ti.static(HULL_CONE))


@ti.func
def _better(bodies: ti.template(), particles: ti.template(), a, i, o, j, candidates, best_gap, n, low_a, low_o):
    """The best of the candidate normals (rows of ``candidates``, world; zero rows
    skipped) and the best so far (``best_gap`` [m] along ``n``, the patches' lowest levels
    ``low_a``, ``low_o`` along it): (gap, n, low_a, low_o) of the widest gap."""
    rot_a = bodies.rotation[a]
    rot_o = bodies.rotation[o]
    lows_a = lowest3(particles, i, la.mat_mat(candidates, rot_a))
    lows_o = lowest3(particles, j, -la.mat_mat(candidates, rot_o))
    gaps = la.mat_vec(candidates, bodies.position[a] - bodies.position[o]) + lows_a + lows_o
    for c in ti.static(range(3)):
        row = vec3(candidates[c, 0], candidates[c, 1], candidates[c, 2])
        if la.norm_sqr(row) > 0.25 and gaps[c] > best_gap:
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
    facets_i = la.mat_mat_t(_facet_rows(particles, i), rot_a)
    facets_j = la.mat_mat_t(_facet_rows(particles, j), rot_o)
    warmed = la.norm_sqr(warm) > 0.25
    first = centre_line
    if warmed:
        first = warm
    # (each patch's lowest level along the best n so far, body frame: its contact spot's band)
    best_gap, n, low_a, low_o = _better(bodies, particles, a, i, o, j, ti.Matrix.rows(
        [first, vec3(facets_j[0, 0], facets_j[0, 1], facets_j[0, 2]),
         -vec3(facets_i[0, 0], facets_i[0, 1], facets_i[0, 2])]), -1e30, first, 0.0, 0.0)
    if la.norm_sqr(particles.patch_normal[i]) < 0.25 or la.norm_sqr(particles.patch_normal[j]) < 0.25:
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
        length = la.norm(x)
        if searching and length > 1e-12:
            d = x / length
            p, q, new_id = _support_pair(bodies, particles, a, i, o, j, d)
            gap = la.dot(p - q, d)
            if gap > best_gap:
                best_gap = gap
                low_a = la.dot(p - x_a, d)
                low_o = la.dot(x_o - q, d)
                n = d
            new = p - q + shift
            # (no support point nearer the origin than x along d: x is the closest point;
            # a gap past ``reach`` already rules the contact out, a longer search only widens it)
            # (x . (x - new) / |x| bounds how much nearer the hulls may be than |x|: under
            # the tolerance, x is their closest point)
            searching = la.dot(x, x - new) > tolerance * length and best_gap <= reach and step + 1 < steps
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
                    if la.norm_sqr(y) < near:
                        near = la.norm_sqr(y)
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
        spot_a = x_a + la.mat_vec(rot_a, contact_spot(particles, i, la.mat_t_vec(rot_a, n), low_a))
        spot_o = x_o + la.mat_vec(rot_o, contact_spot(particles, j, -(la.mat_t_vec(rot_o, n)), low_o))
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
