"""Narrowphase: sphere-sphere (particles of different bodies, each sphere looking in the
body-frame grid of each neighbouring body the broadphase listed, ``grid.py``), sphere-plane
(ground) and sphere-box (static walls). One pass over particles; each contact is appended
with an atomic counter into fixed-capacity ``Contacts``; contacts beyond the capacity are
counted in ``overflow`` (reported by the World), never silently lost.

Contacts are speculative: they are made when the gap is below ``margin`` x the mean radius
plus how far it can close in this substep, and the solver lets the gap close but not go
negative in one substep (Catto, "Speculative contacts", GDC 2013). So nothing tunnels,
however long the substep: a fast body makes its contact before it arrives. How far a gap
can close is measured per pair of points, along the contact normal (``_speculative``: the
two points' approach speed x dt, plus the rotations' curvature and gravity over dt^2), not
by the two bodies' whole motion bounds: a pair moving apart, or side by side, makes no
speculative contact. With the body bounds, most contacts would be speculative ones that
never carry an impulse.
"""


from ..runtime import ti
from ..kinematics import linalg3 as la
from ..kinematics.bounds import fastest_point_speed, is_idle, pair_motion
from . import hulls, surface
from .grid import CELLS_PER_SPHERE

vec3 = ti.math.vec3
mat3 = ti.math.mat3

GROUND = -1  # ``body_b`` of a contact with a ground plane
STATIC_BOX = -2  # ``body_b`` of a contact with a static box


#: Cache keys of one static collider's contacts with a particle: the collider's key less
#: the row, in the particle's patch, of the point the contact is made at. Keyed by the
#: point, a contact finds its own impulse of the last substep however ``surface.manifold``
#: ordered its points this time; keyed by that order, two nearly level points that traded
#: places traded impulses too, and a chip resting on a face rocked on them for good.
POINT_KEYS = 4096

#: The first static box's key (planes count down from -1, boxes from here).
BOX_KEYS = -(1 << 24)


@ti.data_oriented
class Contacts:
    """Per-substep contact buffer, shape (max_contacts,).

    Written by the narrowphase: body_a (i32, dynamic and awake), body_b (i32 body slot, or
    GROUND / STATIC_BOX), static_index (which plane / box), normal (vec3 unit world, from
    B into A), point (vec3 [m] world, middle of the overlap), separation ([m], gap; < 0 is
    penetration), radius ([m] smaller of the two spheres), friction, restitution (combined).
    Written by solver.prepare_contacts: arm_a, arm_b (vec3 [m] COM -> point), normal_mass
    ([kg], 1 / effective inverse mass along the normal), tangent1, tangent2 (vec3 unit,
    the friction directions), tangent_mass (vec2 [kg], along each), response_a, response_b
    ((capacity, 3) vec3 [rad/s per N s]: angular velocity change of each body per unit
    impulse along n, t1, t2), approach_speed ([m/s] normal
    relative velocity before the solve, < 0 approaching), restitution_target ([m/s] normal
    velocity the restitution sweeps aim for).
    query (i32 particle that made it), key (i32 partner key, see Particles' contact cache).
    Written by the narrowphase (the impulses the same pair had last substep: warm start)
    and the solver: normal_impulse ([N s] accumulated, >= 0), tangent_impulse (vec3
    [N s]), pseudo_impulse (split impulse, [N s]); rolling_impulse (vec3 [N m s], the
    rolling resistance's angular impulse on body_a, from zero each substep).
    Written by order_contacts: order (i32), the contact slots in the order the solver,
    the impulse cache and the impact records visit them (sorted by querying particle).
    Written by solver.solve_contacts: sweep_order (i32), ``order`` with the contacts
    between bodies first, then those with static colliders.
    Written by reduction.reduce_contacts: reduce_mark (i32, scratch: whether the
    contact is kept, then its slot after the compaction).
    Scalars: count (may exceed capacity: the excess is ``overflow``), overflow (summed over
    an advance, reset by the World), peak (largest count since the World reset it),
    order_epoch (sorts so far).
    """

    def __init__(self, capacity: int):
        self.capacity = capacity
        self.body_a = ti.field(ti.i32, shape=capacity)
        self.body_b = ti.field(ti.i32, shape=capacity)
        self.static_index = ti.field(ti.i32, shape=capacity)
        self.normal = vec3.field(shape=capacity)
        self.point = vec3.field(shape=capacity)
        self.separation = ti.field(ti.f32, shape=capacity)
        self.radius = ti.field(ti.f32, shape=capacity)
        self.friction = ti.field(ti.f32, shape=capacity)
        self.restitution = ti.field(ti.f32, shape=capacity)
        self.arm_a = vec3.field(shape=capacity)
        self.arm_b = vec3.field(shape=capacity)
        self.normal_mass = ti.field(ti.f32, shape=capacity)
        self.tangent1 = vec3.field(shape=capacity)
        self.tangent2 = vec3.field(shape=capacity)
        self.tangent_mass = ti.math.vec2.field(shape=capacity)
        self.response_a = vec3.field(shape=(capacity, 3))
        self.response_b = vec3.field(shape=(capacity, 3))
        self.approach_speed = ti.field(ti.f32, shape=capacity)
        self.restitution_target = ti.field(ti.f32, shape=capacity)
        self.normal_impulse = ti.field(ti.f32, shape=capacity)
        self.tangent_impulse = vec3.field(shape=capacity)
        self.pseudo_impulse = ti.field(ti.f32, shape=capacity)
        self.rolling_impulse = vec3.field(shape=capacity)
        self.query = ti.field(ti.i32, shape=capacity)
        self.key = ti.field(ti.i32, shape=capacity)
        self.order = ti.field(ti.i32, shape=capacity)
        self.sweep_order = ti.field(ti.i32, shape=capacity)
        self.reduce_mark = ti.field(ti.i32, shape=capacity)
        # (what ``_append`` writes: the fields that moving a contact to another slot moves)
        self.written_by_narrowphase = (self.query, self.key, self.body_a, self.body_b, self.static_index, self.normal,
                                       self.point, self.separation, self.radius, self.friction, self.restitution,
                                       self.normal_impulse, self.tangent_impulse)
        self.order_epoch = ti.field(ti.i32, shape=())
        self.count = ti.field(ti.i32, shape=())
        self.overflow = ti.field(ti.i32, shape=())
        self.peak = ti.field(ti.i32, shape=())


@ti.func
def _point_velocity(bodies: ti.template(), b, x):
    """Velocity [m/s] of the point ``x`` [m] moving with body ``b`` (0 when idle), and
    the bound on how far the point strays from its straight path over a substep, per dt^2:
    |w|^2 |arm| / 2 (rotation) [m/s^2]."""
    v = vec3(0.0)
    curve = 0.0
    if not is_idle(bodies, b):
        arm = x - bodies.position[b]
        w = bodies.angular_velocity[b]
        v = bodies.linear_velocity[b] + la.cross(w, arm)
        curve = 0.5 * la.norm_sqr(w) * la.norm(arm)
    return v, curve


@ti.func
def _speculative(bodies: ti.template(), statics: ti.template(), a, xa, b, xb, n, dt):
    """How far [m] the gap between the point ``xa`` of body ``a`` and the point ``xb`` of
    body ``b`` (-1: a static collider) may close along ``n`` (from b into a) this substep:
    their approach speed x dt, plus the rotation's departure from straight paths and
    gravity's velocity gain over the substep (|g| dt^2). A receding pair closes nothing,
    so it makes no speculative contact: the contact is made only within the margin."""
    va, curve_a = _point_velocity(bodies, a, xa)
    vb = vec3(0.0)
    curve_b = 0.0
    if b >= 0:
        vb, curve_b = _point_velocity(bodies, b, xb)
    approach = -la.dot(va - vb, n)
    return (ti.max(approach, 0.0) * dt
            + (curve_a + curve_b + la.norm(statics.gravity[None])) * dt * dt)


@ti.func
def _cached(particles: ti.template(), query, key):
    """What the contact of particle ``query`` with partner ``key`` kept at the end of the
    last substep (zeros when it made none): (normal impulse [N s], tangent impulse (vec3
    [N s]))."""
    previous = particles.parity[None]
    jn = 0.0
    jt = vec3(0.0)
    if particles.cache_stamp[previous, query] == particles.cache_epoch[None]:
        for k in range(particles.cache_count[previous, query]):
            if particles.cache_key[previous, query, k] == key:
                jn = particles.cache_normal[previous, query, k]
                jt = particles.cache_tangent[previous, query, k]
    return jn, jt


@ti.func
def _carries_with(particles: ti.template(), query, o):
    """Whether particle ``query``'s contact with some sphere of body ``o`` carried load at
    the end of the last substep (``_cached``'s rows). Read once for all of o's candidate
    spheres: most particles carried nothing against o, and then none of its candidates
    needs the per-pair lookup."""
    previous = particles.parity[None]
    carried = False
    if particles.cache_stamp[previous, query] == particles.cache_epoch[None]:
        for k in range(particles.cache_count[previous, query]):
            key = particles.cache_key[previous, query, k]
            if key >= 0 and particles.cache_normal[previous, query, k] > 0.0:
                if particles.body[key] == o:
                    carried = True
    return carried


@ti.func
def _hull_warm(particles: ti.template(), query, key):
    """The normal (vec3 unit, partner body's frame) and simplex (ivec3) the hull search of
    particle ``query`` with particle ``key`` found last substep, contact or not (zero and
    -1 when there was none): where this substep's search starts (``hulls.hull_pair``'s
    ``warm`` and ``simplex``)."""
    previous = particles.parity[None]
    direction = vec3(0.0)
    simplex = ti.Vector([-1, -1, -1], dt=ti.i32)
    if particles.hull_stamp[previous, query] == particles.cache_epoch[None]:
        for k in range(particles.hull_count[previous, query]):
            if particles.hull_key[previous, query, k] == key:
                direction = particles.hull_direction[previous, query, k]
                simplex = particles.hull_simplex[previous, query, k]
    return direction, simplex


@ti.func
def _keep_hull(particles: ti.template(), query, key, direction, simplex):
    """Keep the hull search's normal of particle ``query`` with particle ``key``
    (``direction``, partner body's frame) and its simplex for the next substep's ``_hull_warm``. Only the
    thread of ``query`` writes its rows (``particle_contacts``): no atomics."""
    following = 1 - particles.parity[None]
    k = particles.hull_count[following, query]
    if k < particles.hull_key.shape[2]:
        particles.hull_key[following, query, k] = key
        particles.hull_direction[following, query, k] = direction
        particles.hull_simplex[following, query, k] = simplex
        particles.hull_count[following, query] = k + 1


@ti.func
def _append(contacts: ti.template(), particles: ti.template(), query, key, a, b, static_index, normal, point,
            separation, radius, friction, restitution):
    c = ti.atomic_add(contacts.count[None], 1)
    if c < contacts.capacity:
        contacts.query[c] = query
        contacts.key[c] = key
        # Warm start: the impulses this pair carried at the end of the last substep.
        jn, jt = _cached(particles, query, key)
        contacts.normal_impulse[c] = jn
        contacts.tangent_impulse[c] = jt
        contacts.body_a[c] = a
        contacts.body_b[c] = b
        contacts.static_index[c] = static_index
        contacts.normal[c] = normal
        contacts.point[c] = point
        contacts.separation[c] = separation
        contacts.radius[c] = radius
        contacts.friction[c] = friction
        contacts.restitution[c] = restitution
    else:
        ti.atomic_add(contacts.overflow[None], 1)


@ti.func
def clear_contacts(contacts: ti.template()):
    contacts.peak[None] = ti.max(contacts.peak[None], contacts.count[None])
    contacts.count[None] = 0


#: A body wakes a sleeping one it touches only when its fastest point moves faster than this
#: many times the sleep speed (``DynamicsOptions.sleep_linear_speed``): a chip creeping or
#: settling in a heap at a few mm/s leans on its sleeping neighbours as on the ground.
WAKE_SPEED_FACTOR = 3.0


@ti.func
def _pair_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                   contacts: ti.template(), patches: ti.template(), margin, sleep_time, wake_speed, dt, i, a, xi,
                   ri, o, closing):
    """Sphere-sphere contacts of particle ``i`` (awake body ``a``, world centre ``xi`` [m],
    radius ``ri`` [m]) with the spheres of body ``o``, whose gap may close by ``closing``
    [m] this substep (``bounds.pair_motion``, or the broadphase's value for the pair).

    No contact can be made unless ``xi`` lies within ``grow`` = (ri + o's largest radius)
    (1 + margin / 2) + closing of one of o's spheres, so three cheap tests come first:
    o's bounding sphere, then (in o's frame) its box, then its cluster spheres (each
    enclosing a group of its spheres: they leave out a ring's hole, which the box holds).
    Then the cells of o's grid within ``grow`` of the point, and in them each sphere j
    whose gap is below the margin plus the pair's closing; the speculative test of that
    pair of points (``_speculative``) decides. An awake body that has not been still for
    ``sleep_time`` [s] and moves faster than ``wake_speed`` [m/s] at its fastest point wakes
    a sleeping body it touches; one just woken itself (its timer kept at ``sleep_time`` or
    more) does not, so a touch does not wake a whole pile, and neither does a body creeping
    or settling against it (one of a heap's chips kept waking its neighbours)."""
    grow = (ri + bodies.max_particle_radius[o]) * (1.0 + 0.5 * margin) + closing
    gap = xi - bodies.position[o]
    bound = bodies.bounding_radius[o] + grow
    if la.norm_sqr(gap) < bound * bound:
        rot = bodies.rotation[o]
        local = la.mat_t_vec(rot, gap)
        q = ti.math.clamp(local, bodies.local_lower[o], bodies.local_upper[o])
        if la.norm_sqr(local - q) < grow * grow:
            near = 0
            reach = ri * (1.0 + 0.5 * margin) + 0.5 * margin * bodies.max_particle_radius[o] + closing
            for m in range(bodies.cluster_count[o]):
                if near == 0:
                    sphere = bodies.cluster[o, m]
                    limit = sphere[3] + reach
                    if la.norm_sqr(local - vec3(sphere[0], sphere[1], sphere[2])) < limit * limit:
                        near = 1
            if near == 1:
                carried = False
                if ti.static(patches):
                    carried = _carries_with(particles, i, o)
                edge = bodies.grid_edge[o]
                dims = bodies.grid_dims[o]
                rel = local - bodies.grid_origin[o]
                # (a hair wider than grow: a centre on a cell face is never lost to the f32
                # rounding of the cell bounds)
                wide = grow * 1.0001
                lo = ti.max(ti.floor((rel - wide) / edge, ti.i32), 0)
                hi = ti.min(ti.floor((rel + wide) / edge, ti.i32), dims - 1)
                base = ti.static(CELLS_PER_SPHERE) * bodies.particle_start[o]
                for cx in range(lo[0], hi[0] + 1):
                    for cy in range(lo[1], hi[1] + 1):
                        for cz in range(lo[2], hi[2] + 1):
                            corner = ti.math.vec3(cx, cy, cz) * edge
                            nearest = ti.math.clamp(rel, corner, corner + edge)
                            if la.norm_sqr(nearest - rel) < wide * wide:
                                cell = (cx * dims[1] + cy) * dims[2] + cz
                                for k in range(particles.cell_first[base + cell], particles.cell_first[base + cell + 1]):
                                    _test_pair(bodies, particles, statics, contacts, patches, margin, sleep_time,
                                               wake_speed, dt, i, a, xi, ri, o, rot, local, closing, carried, k)


#: Two collision spheres overlapping by more than this many times the larger radius belong to
#: bodies that interpenetrate there (two bodies placed overlapping): their sphere contact is
#: kept under surface contact too. The patches of such bodies meet only where their surfaces
#: cross, a few millimetres deep, and would hold them together; a body resting on another
#: overlaps its spheres by a fraction of a radius (they stand proud of its surface).
INTERPENETRATING = 1.0


@ti.func
def _test_pair(bodies: ti.template(), particles: ti.template(), statics: ti.template(), contacts: ti.template(),
               patches: ti.template(), margin, sleep_time, wake_speed, dt, i, a, xi, ri, o, rot, local, closing,
               carried, k):
    """Contact of particle ``i`` (body ``a``) with grid entry ``k`` of body ``o`` (its
    centre ``local`` [m] in o's frame, rotation ``rot`` o -> world; ``carried``: whether
    i carried load against a sphere of o last substep, ``_carries_with``), when their gap is
    within the margin plus the pair's closing (squared: no square root for the ~90 % of
    candidates it rejects) and then the speculative reach of the two points. When either
    sphere has a contact patch, the contact's normal, depth and point are the patches'
    (``surface.pair`` where one has facets, ``hulls.hull_pair``'s hull distance where
    both have and the pair closes slower than ``hulls.HULL_APPROACH``) and the
    speculative reach is that of their contact spots."""
    sphere = particles.grid_sphere[k]
    rj = sphere[3]
    j = particles.grid_slot[k]
    d = local - vec3(sphere[0], sphere[1], sphere[2])
    mean_r = 0.5 * (ri + rj)
    limit = ri + rj + margin * mean_r + closing
    d2 = la.norm_sqr(d)
    near = d2 < limit * limit
    if ti.static(patches):
        # A patch may stand out of its sphere (``Particles.overhang``): a pair that carried
        # load last substep is kept while its patches may still touch, or a resting contact
        # is made and lost as the closing bound varies, and the body on it falls a substep.
        if not near and carried:
            reach = limit + particles.overhang[i] + particles.overhang[j]
            if d2 < reach * reach:
                load, _ = _cached(particles, i, j)
                near = load > 0.0
    if near:
        dist = la.norm(d)
        gap = dist - ri - rj
        n = vec3(0.0, 0.0, 1.0)
        if dist > 1e-9:
            n = la.mat_vec(rot, d / dist)
        xj = xi - n * dist
        point = xj + n * (rj + 0.5 * gap)
        x_a, x_o = xi, xj
        scale = ti.min(ri, rj)
        if ti.static(patches):
            patched = surface.by_patches(particles, i, j)
            on_hulls = hulls.by_hulls(particles, i, j) and closing <= ti.static(hulls.HULL_APPROACH) * mean_r
            if patched or on_hulls:
                n_patch = n
                gap_patch = gap
                spot_a = x_a
                spot_o = x_o
                if on_hulls:
                    warm, simplex = _hull_warm(particles, i, j)
                    n_patch, gap_patch, spot_a, spot_o, simplex = hulls.hull_pair(
                        bodies, particles, a, i, o, j, n, margin * mean_r + closing, la.mat_vec(rot, warm), simplex)
                    _keep_hull(particles, i, j, la.mat_t_vec(rot, n_patch), simplex)
                else:
                    n_patch, gap_patch, spot_a, spot_o = surface.pair(bodies, particles, a, i, o, j, n)
                # (spheres overlapping by more than the larger radius: bodies interpenetrating,
                # whose patches meet only where the surfaces cross; the spheres push them apart)
                if gap_patch >= -ti.static(surface.TRUSTED_DEPTH) * ti.max(ri, rj) \
                        and gap >= -ti.static(INTERPENETRATING) * ti.max(ri, rj):
                    n, gap, x_a, x_o = n_patch, gap_patch, spot_a, spot_o
                    # Where along the surfaces: the smaller patch's spot (a chip on a wide
                    # patch touches under itself; the two spots' mean lay off the chip and
                    # spun it), half the gap across.
                    point = x_a - 0.5 * gap * n if ri <= rj else x_o + 0.5 * gap * n
                    # (the depth scale of a patch contact is the larger sphere's: a chip 2 mm
                    # into a slab is no deep overlap of the two)
                    scale = ti.max(ri, rj)
        if gap < margin * mean_r + _speculative(bodies, statics, a, x_a, o, x_o, n, dt):
            mu = ti.sqrt(bodies.friction[a] * bodies.friction[o])
            e = ti.max(bodies.restitution[a], bodies.restitution[o])
            _append(contacts, particles, i, j, a, o, -1, n, point, gap, scale, mu, e)
            if bodies.sleeping[o] == 1 and bodies.sleep_timer[a] < sleep_time \
                    and fastest_point_speed(bodies, a) > wake_speed:
                bodies.wake_request[o] = 1


@ti.func
def _static_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                     contacts: ti.template(), patches: ti.template(), margin, dt, bounce_speed, i, a, x):
    """Sphere-plane and sphere-box contacts of particle ``i`` of awake body ``a`` (normal
    out of the collider, i.e. into the body); ``x`` [m] its world centre. The sphere
    finds the contact; with a contact patch, its gap and points are the patch's
    (``_collider_contacts``; ``bounce_speed`` [m/s]: the restitution threshold)."""
    r = particles.radius[i]
    patch = False
    if ti.static(patches):
        patch = particles.point_count[i] > 0
    planes = statics.plane_count[None]
    # (one loop over planes and boxes: each call of _collider_contacts is inlined whole)
    for s in range(planes + statics.box_count[None]):
        n = vec3(0.0, 0.0, 1.0)
        gap = 0.0
        point = vec3(0.0)
        level = 0.0
        kind = GROUND
        k = s
        key = -1 - k * ti.static(POINT_KEYS)
        mu = 0.0
        e = 0.0
        if s < planes:
            level = statics.plane_height[k]
            gap = x[2] - r - level
            point = vec3(x[0], x[1], level)
            mu = ti.sqrt(bodies.friction[a] * statics.plane_friction[k])
            e = ti.max(bodies.restitution[a], statics.plane_restitution[k])
        else:
            k = s - planes
            kind = STATIC_BOX
            key = ti.static(BOX_KEYS) - k * ti.static(POINT_KEYS)
            rot = statics.box_rotation[k]
            half = statics.box_half_extents[k]
            local = la.mat_t_vec(rot, x - statics.box_center[k])
            q = ti.math.clamp(local, -half, half)
            d = local - q
            dist = la.norm(d)
            n_local = vec3(0.0, 0.0, 1.0)
            if dist > 1e-9:  # centre outside the box
                n_local = d / dist
                gap = dist - r
            else:  # centre inside: leave through the nearest face
                depth = half - ti.abs(local)
                axis = 0
                if depth[1] < depth[axis]:
                    axis = 1
                if depth[2] < depth[axis]:
                    axis = 2
                n_local = vec3(0.0, 0.0, 0.0)
                for m in ti.static(range(3)):
                    if m == axis:
                        side = 1.0 if local[m] >= 0.0 else -1.0
                        n_local[m] = side
                        q[m] = half[m] * side
                        gap = -depth[m] - r
            n = la.mat_vec(rot, n_local)
            point = statics.box_center[k] + la.mat_vec(rot, q)
            level = la.dot(point, n)
            mu = ti.sqrt(bodies.friction[a] * statics.box_friction[k])
            e = ti.max(bodies.restitution[a], statics.box_restitution[k])
        # A patch may stand out of its sphere (``Particles.overhang``): a chip's corner past
        # it touches the floor, and without the overhang its contact comes and goes as the
        # motion bound varies, so the chip rocks on it for good.
        over = 0.0
        if ti.static(patches):
            over = particles.overhang[i]
        if gap - over < margin * r + bodies.motion[a]:
            if ti.static(patches):
                _collider_contacts(bodies, particles, statics, contacts, margin, dt, bounce_speed, i, a, x, patch, n,
                                   gap, point, level, kind, k, key, mu, e)
            elif gap < margin * r + _speculative(bodies, statics, a, x, -1, x, n, dt):
                _append(contacts, particles, i, key, a, kind, k, n, point, gap, r, mu, e)


@ti.func
def _collider_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                       contacts: ti.template(), margin, dt, bounce_speed, i, a, x, patch, n, gap, point, level, kind, k,
                       key, mu, e):
    """Contacts of particle ``i`` (body ``a``, world centre ``x`` [m]) with static collider
    ``k`` (``kind``: GROUND or STATIC_BOX) along its normal ``n`` (out of the collider):
    the sphere's (``gap`` [m], at the collider's ``point`` nearest it) or, with a patch,
    one per ``surface.manifold`` point (the collider's support along n is ``level`` [m]),
    or one for an impact (approaching faster than ``bounce_speed`` [m/s], the restitution
    threshold) or a body of many spheres (``surface.against``). ``key``: the collider's
    cache key; a patch point's contact is keyed ``key`` less the point's row in the patch
    (``POINT_KEYS``)."""
    count = 1
    points = ti.Matrix.zero(ti.f32, ti.static(surface.MANIFOLD_POINTS), 3)
    levels = ti.Vector.zero(ti.f32, ti.static(surface.MANIFOLD_POINTS))
    ids = ti.Vector.zero(ti.i32, ti.static(surface.MANIFOLD_POINTS))
    if patch:
        v, _ = _point_velocity(bodies, a, x)
        gap, count, points, levels, ids = surface.against(bodies, particles, a, i, n, level,
                                                          -la.dot(v, n) > bounce_speed)
    r = particles.radius[i]
    for m in range(count):  # (a dynamic loop: unrolled, each _append was inlined four times)
        g = gap + levels[m]
        spot = x
        at = point
        if patch:  # (a point on the patch, the contact half the gap below it)
            spot = vec3(points[m, 0], points[m, 1], points[m, 2])
            at = spot - 0.5 * g * n
        if g < margin * r + bodies.motion[a] and g < margin * r + _speculative(bodies, statics, a, spot, -1, spot, n,
                                                                              dt):
            _append(contacts, particles, i, key - ids[m] % ti.static(POINT_KEYS), a, kind, k, n, at, g, r, mu, e)


@ti.func
def particle_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                      contacts: ti.template(), patches: ti.template(), margin, sleep_time, wake_speed, dt,
                      bounce_speed):
    """One pass over the particles of awake bodies near something: each particle's world
    centre, its sphere-sphere contacts with each neighbour o of its body a that it makes
    (o > a when both are awake, so a pair is made once; every idle neighbour, which makes
    none of its own) in o's grid, and its sphere-plane and sphere-box contacts when a is
    near a static collider. When a's neighbour list overflowed, every body is tried with
    the pair's closing computed here. A parallel task on every arch, unlike the small
    passes: a particle's contacts are appended by one thread in program order
    (neighbours, cells, entries), and ``order_contacts`` sorts them by particle.
    ``wake_speed`` [m/s]: how fast a body must move to wake a sleeping one it touches
    (``_pair_contacts``). ``bounce_speed`` [m/s]: the restitution threshold
    (``_collider_contacts``). ``patches``
    (static bool): whether any body has contact patches; without, the patch code is not
    compiled (a third of the kernel's build time) and every contact is the spheres'."""
    for i in range(particles.slot_end[None]):
        a = particles.body[i]
        if a >= 0:
            if not is_idle(bodies, a) and (bodies.near_body[a] == 1 or bodies.near_static[a] == 1):
                xi = bodies.position[a] + la.mat_vec(bodies.rotation[a], particles.offset[i])
                ri = particles.radius[i]
                if ti.static(patches):  # (this thread's rows of the hull searches kept for next substep)
                    following = 1 - particles.parity[None]
                    particles.hull_stamp[following, i] = particles.cache_epoch[None] + 1
                    particles.hull_count[following, i] = 0
                count = bodies.neighbor_count[a]
                listed = count >= 0
                # (one call site for both cases: each is inlined whole, and compiling the
                # narrowphase twice over doubled the kernel's build time)
                for k in range(count if listed else bodies.slot_end[None]):
                    o = k
                    closing = 0.0
                    if listed:
                        o = bodies.neighbors[a, k]
                        closing = bodies.neighbor_motion[a, k]
                    if o != a and bodies.active[o] == 1 and (o > a or is_idle(bodies, o)):
                        if not listed:
                            closing = pair_motion(bodies, statics, a, o, dt)
                        _pair_contacts(bodies, particles, statics, contacts, patches, margin, sleep_time, wake_speed,
                                       dt, i, a, xi, ri, o, closing)
                if bodies.near_static[a] == 1:
                    _static_contacts(bodies, particles, statics, contacts, patches, margin, dt, bounce_speed, i, a,
                                     xi)


@ti.func
def order_contacts(particles: ti.template(), contacts: ti.template()):
    """Serial counting sort of the contacts by querying particle into ``contacts.order``,
    the order the solver visits them. The parallel narrowphase appends them in whatever
    order its threads run, and a Gauss-Seidel solve depends on the visiting order, so two
    runs of a scene differed. A particle's own contacts are appended by one thread in
    program order, so a stable sort by particle makes the order, and the run, reproducible.
    Particles are counted under a per-sort stamp, so no array is cleared; the cost is one
    serial pass over the particle slots and three over the contacts."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        n = ti.min(contacts.count[None], contacts.capacity)
        epoch = contacts.order_epoch[None] + 1
        contacts.order_epoch[None] = epoch
        for c in range(n):
            q = contacts.query[c]
            if particles.order_stamp[q] != epoch:
                particles.order_stamp[q] = epoch
                particles.order_start[q] = 0
            particles.order_start[q] += 1
        running = 0
        for p in range(particles.slot_end[None]):
            if particles.order_stamp[p] == epoch:
                k = particles.order_start[p]
                particles.order_start[p] = running
                running += k
        for c in range(n):
            q = contacts.query[c]
            contacts.order[particles.order_start[q]] = c
            particles.order_start[q] += 1
