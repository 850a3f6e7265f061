"""Narrowphase: sphere-sphere (particles of different bodies), sphere-plane (ground) and
sphere-box (static walls). One pass over particles per kernel; each contact is appended
with an atomic counter into fixed-capacity ``Contacts``; contacts beyond the capacity are
counted in ``overflow`` (reported by the World), never silently lost.

Contacts are speculative: they are made when the gap is below ``margin`` x the mean radius,
and the solver lets the gap close but not go negative in one substep (Catto, "Speculative
contacts", GDC 2013).
"""


import taichi as ti

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
    ([kg], 1 / effective inverse mass along the normal), approach_speed ([m/s] normal
    relative velocity before the solve, < 0 approaching).
    Written by the solver: normal_impulse ([N s] accumulated, >= 0), tangent_impulse
    (vec3 [N s]), pseudo_impulse (split impulse, [N s]).
    Scalars: count (may exceed capacity: the excess is ``overflow``), overflow (summed over
    an advance, reset by the World), peak (largest count since the World reset it).
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
        self.approach_speed = ti.field(ti.f32, shape=capacity)
        self.normal_impulse = ti.field(ti.f32, shape=capacity)
        self.tangent_impulse = vec3.field(shape=capacity)
        self.pseudo_impulse = ti.field(ti.f32, shape=capacity)
        self.count = ti.field(ti.i32, shape=())
        self.overflow = ti.field(ti.i32, shape=())
        self.peak = ti.field(ti.i32, shape=())


@ti.func
def _append(contacts: ti.template(), a, b, static_index, normal, point, separation, radius, friction, restitution):
    c = ti.atomic_add(contacts.count[None], 1)
    if c < contacts.capacity:
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
def _is_idle(bodies: ti.template(), b):
    return bodies.sleeping[b] == 1 or bodies.fixed[b] == 1


@ti.func
def particle_contacts(bodies: ti.template(), particles: ti.template(), grid: ti.template(),
                      contacts: ti.template(), margin):
    """Pass over particles of awake bodies near another body: sphere-sphere contacts with
    particles of other bodies in the 27 surrounding cells. A pair is made once: from the
    lower slot when both bodies are awake, from the awake side otherwise. An awake body
    that is still moving (sleep timer at zero) wakes a sleeping body it touches."""
    for i in range(particles.slot_end[None]):
        a = particles.body[i]
        if a >= 0:
            if bodies.near_body[a] == 1 and not _is_idle(bodies, a):
                xi = particles.world_position[i]
                ri = particles.radius[i]
                ci = particles.cell[i]
                table_size = grid.table_size[None]
                for dx, dy, dz in ti.static(ti.ndrange((-1, 2), (-1, 2), (-1, 2))):
                    cell = ci + ti.math.ivec3(dx, dy, dz)
                    h = cell_hash(cell, table_size)
                    for k in range(grid.bucket_start[h], grid.bucket_end[h]):
                        j = grid.sorted_particle[k]
                        b = particles.body[j]
                        if b != a and (particles.cell[j] == cell).all():
                            if j > i or _is_idle(bodies, b):
                                rj = particles.radius[j]
                                d = xi - particles.world_position[j]
                                dist = d.norm()
                                mean_r = 0.5 * (ri + rj)
                                gap = dist - ri - rj
                                if gap < margin * mean_r:
                                    n = vec3(0.0, 0.0, 1.0)
                                    if dist > 1e-9:
                                        n = d / dist
                                    point = particles.world_position[j] + n * (rj + 0.5 * gap)
                                    mu = ti.sqrt(bodies.friction[a] * bodies.friction[b])
                                    e = ti.max(bodies.restitution[a], bodies.restitution[b])
                                    _append(contacts, a, b, -1, n, point, gap, ti.min(ri, rj), mu, e)
                                    if bodies.sleeping[b] == 1 and bodies.sleep_timer[a] == 0.0:
                                        bodies.wake_request[b] = 1


@ti.func
def static_contacts(bodies: ti.template(), particles: ti.template(), statics: ti.template(),
                    contacts: ti.template(), margin):
    """Pass over particles of awake bodies near a static collider: sphere-plane and
    sphere-box contacts (normal out of the collider, i.e. into the body)."""
    for i in range(particles.slot_end[None]):
        a = particles.body[i]
        if a >= 0:
            if bodies.near_static[a] == 1 and not _is_idle(bodies, a):
                x = particles.world_position[i]
                r = particles.radius[i]
                for k in range(statics.plane_count[None]):
                    gap = x[2] - r - statics.plane_height[k]
                    if gap < margin * r:
                        point = vec3(x[0], x[1], statics.plane_height[k])
                        mu = ti.sqrt(bodies.friction[a] * statics.plane_friction[k])
                        e = ti.max(bodies.restitution[a], statics.plane_restitution[k])
                        _append(contacts, a, -1, k, vec3(0.0, 0.0, 1.0), point, gap, r, mu, e)
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
                    if gap < margin * r:
                        n = rot @ n_local
                        point = statics.box_center[k] + rot @ q
                        mu = ti.sqrt(bodies.friction[a] * statics.box_friction[k])
                        e = ti.max(bodies.restitution[a], statics.box_restitution[k])
                        _append(contacts, a, -2, k, n, point, gap, r, mu, e)
