"""Narrowphase: sphere-sphere (particles of different bodies), sphere-plane (ground) and
sphere-box (static walls). One pass over particles per kernel; each contact is appended
with an atomic counter into fixed-capacity ``Contacts``; contacts beyond the capacity are
counted in ``overflow`` (reported by the World), never silently lost.

Contacts are speculative: they are made when the gap is below ``margin`` x the mean radius
plus how far it can close in this substep, and the solver lets the gap close but not go
negative in one substep (Catto, "Speculative contacts", GDC 2013). So nothing tunnels,
however long the substep: a fast body makes its contact before it arrives. How far a gap
can close is measured per pair of points, along the contact normal (``_speculative``: the
two points' approach speed x dt, plus the rotations' curvature and gravity over dt^2), not
by the two bodies' whole motion bounds: a pair moving apart, or side by side, makes no
speculative contact. With the body bounds, ~95 % of the contacts were speculative ones
that never carried an impulse (13 rings: response 0.14 -> 0.10 s per run, and 2 -> 0.3 ms
per substep at 6.7 ms substeps, where the body bounds made 10-15 thousand contacts).
"""


import taichi as ti

from .. import runtime
from ..dynamics.bounds import is_idle
from .grid import cell_hash

vec3 = ti.math.vec3
mat3 = ti.math.mat3

GROUND = -1  # ``body_b`` of a contact with a ground plane
STATIC_BOX = -2  # ``body_b`` of a contact with a static box


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
        v = bodies.linear_velocity[b] + w.cross(arm)
        curve = 0.5 * w.norm_sqr() * arm.norm()
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
    approach = -(va - vb).dot(n)
    return (ti.max(approach, 0.0) * dt
            + (curve_a + curve_b + statics.gravity[None].norm()) * dt * dt)


@ti.func
def _append(contacts: ti.template(), particles: ti.template(), query, key, a, b, static_index, normal, point,
            separation, radius, friction, restitution):
    c = ti.atomic_add(contacts.count[None], 1)
    if c < contacts.capacity:
        contacts.query[c] = query
        contacts.key[c] = key
        # Warm start: the impulses this pair carried at the end of the last substep.
        previous = particles.parity[None]
        jn = 0.0
        jt = vec3(0.0)
        if particles.cache_stamp[previous, query] == particles.cache_epoch[None]:
            for k in range(particles.cache_count[previous, query]):
                if particles.cache_key[previous, query, k] == key:
                    jn = particles.cache_normal[previous, query, k]
                    jt = particles.cache_tangent[previous, query, k]
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




@ti.func
def _sphere_contacts(bodies: ti.template(), particles: ti.template(), grid: ti.template(),
                     statics: ti.template(), contacts: ti.template(), margin, sleep_time, dt, i, a):
    """Sphere-sphere contacts of active particle ``i`` (awake body ``a``) with the active
    particles of other bodies in its cell box grown by one cell. A pair is made once: from
    the lower slot when both bodies are awake, from the awake side otherwise, and only in
    the cell of the partner's box nearest this particle's centre. An awake body that has
    not been still for ``sleep_time`` [s] wakes a sleeping body it touches; one just woken
    itself (its timer kept at ``sleep_time`` or more) does not, so a touch does not wake a
    whole pile."""
    xi = particles.world_position[i]
    ri = particles.radius[i]
    lower_i = particles.cell[i]
    upper_i = particles.cell_hi[i]
    if (lower_i == upper_i).all():  # the common case: 27 cells
        # No partner centre lies further than this: its radius is at most the typical one
        # beyond its own cell box, and the pair closes at most max_motion.
        reach = (ri + grid.typical_radius[None]) * (1.0 + 0.5 * margin) + grid.max_motion[None]
        # Plain nested loops, not unrolled: 27 inlined copies of the cell scan made this
        # kernel take ~90 s to compile on the CPU backend.
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                for dz in range(-1, 2):
                    _scan_cell(bodies, particles, grid, statics, contacts, margin, sleep_time, dt, i, a, xi, ri,
                               lower_i, lower_i + ti.math.ivec3(dx, dy, dz), reach)  # (home = lower_i)
    else:  # a large particle scans its whole box grown by one cell
        home = ti.floor(xi / grid.cell_size[None], ti.i32)  # the cell its centre is in
        for cx, cy, cz in ti.ndrange((lower_i[0] - 1, upper_i[0] + 2), (lower_i[1] - 1, upper_i[1] + 2),
                                     (lower_i[2] - 1, upper_i[2] + 2)):
            _scan_cell(bodies, particles, grid, statics, contacts, margin, sleep_time, dt, i, a, xi, ri, home,
                       ti.math.ivec3(cx, cy, cz), 1e30)


@ti.func
def _scan_cell(bodies: ti.template(), particles: ti.template(), grid: ti.template(), statics: ti.template(),
               contacts: ti.template(), margin, sleep_time, dt, i, a, xi, ri, home, cell, reach):
    """Candidates of particle ``i`` in one cell (skipped when the cell lies beyond ``reach``).

    A partner j of another body is wanted when j > i (both awake: the lower slot makes the
    pair) or its body is idle. Body ``a`` holds the slots [start, end) and i lies in them,
    so the first kind are exactly the entries with j >= end and the second the idle ones
    with j < start or j >= end. Where the bucket is in ascending slot order (serial
    scatter, the CPU) the scan reads only those: backwards from the bucket's end down to
    the first j < end, then, when ``a`` has an idle neighbour, forwards from its start up
    to the first j >= start. Most of a bucket is ``a``'s own particles (63 % of the
    candidates of the 13-ring pile), which so are never read. Elsewhere every entry is
    read and filtered."""
    size = grid.cell_size[None]
    nearest = ti.math.clamp(xi, ti.cast(cell, ti.f32) * size, ti.cast(cell + 1, ti.f32) * size)
    if (nearest - xi).norm_sqr() < reach * reach:
        h = cell_hash(cell, grid.table_size[None])
        first = grid.bucket_start[h]
        last = ti.min(grid.bucket_start[h + 1], grid.entry_capacity)
        if ti.static(runtime.SERIAL_SMALL_LOOPS):
            start = bodies.particle_start[a]
            end = start + bodies.particle_count[a]
            lower_too = bodies.idle_neighbor[a]
            k = last - 1
            step = -1
            while True:
                if step == -1 and (k < first or grid.sorted_particle[k] < end):
                    if lower_too == 0:
                        break
                    k = first
                    step = 1
                if step == 1 and (k >= last or grid.sorted_particle[k] >= start):
                    break
                b = grid.sorted_body[k]
                if step == -1 or is_idle(bodies, b):
                    _test_pair(bodies, particles, statics, contacts, margin, sleep_time, dt, grid.max_motion[None],
                               i, a, xi, ri, home, cell, grid.sorted_particle[k], b, grid.sorted_offset[k])
                k += step
        else:
            for k in range(first, last):
                b = grid.sorted_body[k]
                j = grid.sorted_particle[k]
                if b != a and (j > i or is_idle(bodies, b)):
                    _test_pair(bodies, particles, statics, contacts, margin, sleep_time, dt, grid.max_motion[None],
                               i, a, xi, ri, home, cell, j, b, grid.sorted_offset[k])


@ti.func
def _test_pair(bodies: ti.template(), particles: ti.template(), statics: ti.template(), contacts: ti.template(),
               margin, sleep_time, dt, max_motion,
               i, a, xi, ri, home, cell, j, b, offset):
    """Contact of particle ``i`` (body ``a``) with candidate ``j`` (body ``b``) found in
    ``cell`` by its entry for the cell ``offset`` of its box, when their gap is within the
    speculative reach."""
    rj = particles.radius[j]
    d = xi - particles.world_position[j]
    mean_r = 0.5 * (ri + rj)
    # gap = |d| - ri - rj < margin mean_r + max_motion, squared: no square root for the
    # candidates it rejects (~99 % of them in the 13-ring pile)
    limit = ri + rj + margin * mean_r + max_motion
    if d.norm_sqr() < limit * limit:
        dist = d.norm()
        gap = dist - ri - rj
        lower_j = particles.cell[j]
        n = vec3(0.0, 0.0, 1.0)
        if dist > 1e-9:
            n = d / dist
        # The entry is j's for this very cell (not another cell of j's box hashed to the
        # same bucket: the pair was made again for each), this is the cell of j's box
        # nearest i's centre (``home``: the cell it lies in, clamped to j's box; unique,
        # within the cells i scans, and the last of them the reach test would skip: the
        # first cell both boxes share, the rule before, could be skipped while a nearer
        # one was scanned, and the pair was lost), and the gap may close within the margin
        # this substep (the body bounds above are the cheap, coarser test).
        upper_j = particles.cell_hi[j]
        span = upper_j - lower_j + 1
        registered = lower_j + ti.math.ivec3(offset // (span[1] * span[2]), (offset // span[2]) % span[1],
                                             offset % span[2])
        if ((registered == cell).all()
                and (ti.math.clamp(home, lower_j, upper_j) == cell).all()
                and gap < margin * mean_r
                + _speculative(bodies, statics, a, xi, b, particles.world_position[j], n, dt)):
            point = particles.world_position[j] + n * (rj + 0.5 * gap)
            mu = ti.sqrt(bodies.friction[a] * bodies.friction[b])
            e = ti.max(bodies.restitution[a], bodies.restitution[b])
            _append(contacts, particles, i, j, a, b, -1, n, point, gap, ti.min(ri, rj), mu, e)
            if bodies.sleeping[b] == 1 and bodies.sleep_timer[a] < sleep_time:
                bodies.wake_request[b] = 1


@ti.func
def _static_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                     contacts: ti.template(), margin, dt, i, a):
    """Sphere-plane and sphere-box contacts of particle ``i`` of awake body ``a`` (normal
    out of the collider, i.e. into the body)."""
    x = particles.world_position[i]
    r = particles.radius[i]
    for k in range(statics.plane_count[None]):
        gap = x[2] - r - statics.plane_height[k]
        if gap < margin * r + bodies.motion[a] and gap < margin * r + _speculative(
                bodies, statics, a, x, -1, x, vec3(0.0, 0.0, 1.0), dt):
            point = vec3(x[0], x[1], statics.plane_height[k])
            mu = ti.sqrt(bodies.friction[a] * statics.plane_friction[k])
            e = ti.max(bodies.restitution[a], statics.plane_restitution[k])
            _append(contacts, particles, i, -1 - k, a, GROUND, k, vec3(0.0, 0.0, 1.0), point, gap, r, mu, e)
    for k in range(statics.box_count[None]):
        rot = statics.box_rotation[k]
        half = statics.box_half_extents[k]
        local = rot.transpose() @ (x - statics.box_center[k])
        q = ti.math.clamp(local, -half, half)
        d = local - q
        dist = d.norm()
        n_local = vec3(0.0, 0.0, 1.0)
        gap = 0.0
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
        n = rot @ n_local
        if gap < margin * r + bodies.motion[a] and gap < margin * r + _speculative(bodies, statics, a, x, -1, x, n, dt):
            point = statics.box_center[k] + rot @ q
            mu = ti.sqrt(bodies.friction[a] * statics.box_friction[k])
            e = ti.max(bodies.restitution[a], statics.box_restitution[k])
            _append(contacts, particles, i, -1000 - k, a, STATIC_BOX, k, n, point, gap, r, mu, e)


@ti.func
def particle_contacts(bodies: ti.template(), particles: ti.template(), grid: ti.template(),
                      statics: ti.template(), contacts: ti.template(), margin, sleep_time, dt):
    """One pass over the particles of awake bodies: sphere-sphere contacts of active
    particles, sphere-plane and sphere-box contacts of bodies near a static collider.
    A parallel task on every arch, unlike the small passes. Serial, on this 2-core CPU
    (Taichi 1.7.4, `taichi-frac bench dynamics`, three alternating runs each, ms/frame avg
    / max): 13 rings two-scale 2.0-2.3 / 10.9-12.9 against 2.2-2.3 / 10.4-10.6 parallel,
    the 216-fragment pile 10.9-12.5 against 9.9-11.3; only single-scale gained (6.7-7.5
    against 9.5-10.5)."""
    for i in range(particles.slot_end[None]):
        a = particles.body[i]
        if a >= 0:
            if not is_idle(bodies, a):
                if particles.active[i] == 1:
                    _sphere_contacts(bodies, particles, grid, statics, contacts, margin, sleep_time, dt, i, a)
                if bodies.near_static[a] == 1:
                    _static_contacts(bodies, particles, statics, contacts, margin, dt, i, a)


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
