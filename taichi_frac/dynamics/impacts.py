"""Impact records for the fracture stage: contact impulses summed per (body, other) pair
per substep, with the contact force they stand for, kept when it exceeds a threshold.

The force must not depend on the solver's substep: a rigid solver delivers an impact's
impulse J within one or two substeps, whatever their length, so J / dt grows without
bound as substeps shrink (and how J splits between two substeps of a speculative contact
is arbitrary). An *impact* (the pair approached faster than ``impact_speed``) is instead
given the peak force of a Hertzian impact of two elastic spheres at its approach speed v
(Johnson, Contact Mechanics, 1985, sec. 11.4):

    delta = (15 m* v^2 / (16 E* sqrt(R*)))^(2/5),  F = 4/3 E* sqrt(R*) delta^(3/2),
    t_c = 2.94 delta / v  (contact duration, reported),

with m* the reduced mass, R* the reduced contact radius (each body impacts like the
sphere of its own volume; a static collider is flat) and E* = 1 / sum((1 - nu^2) / E) (a
static collider is rigid). The row's force points along its impulse. A *sustained*
contact (slower) has force J / dt, its true mean over the substep. When both sides are
rigid, or neither can move, J / dt is used throughout.

The pairing runs serially (one task): a small open-addressing table keyed by (body, other,
static index), cleared through its list of used slots, so its cost follows the contact
count, not the table size.
"""


from ..runtime import ti
from ..kinematics import linalg3 as la

vec3 = ti.math.vec3


@ti.data_oriented
class Impacts:
    """Rows kept during one ``advance``, shape (max_impacts,).

    Fields (writer: record_impacts): body (i32), other (i32 body slot, -1 ground, -2 static
    box), point (vec3 [m] world, impulse-weighted mean contact point), normal (vec3 unit
    world, into ``body``, impulse-weighted mean contact normal), impulse (vec3 [N s] on
    ``body``), force (vec3 [N] on ``body``, see the module docstring), duration ([s]
    Hertz contact time, 0 for a sustained contact), speed ([m/s] approach speed), dt ([s]
    substep length), substep (i32 index within the advance); point_body, normal_body,
    force_body (vec3): point [m], normal and force [N] in ``body``'s frame at that substep
    (the body may move far in the rest of the frame: a glass wall struck by a 25 m/s ball
    moved 17 mm, and the point converted with its end-of-frame pose lay 3.8 cm off its
    surface). Scalars: count, overflow.
    Pair table, shape (table_size,): pair_a, pair_b, pair_static (keys, -9 = empty),
    pair_impulse, pair_normal, pair_point_sum (vec3), pair_weight, pair_speed (largest
    approach speed of its contacts); pair_used (slots in use).
    """

    def __init__(self, capacity: int, contact_capacity: int):
        self.capacity = capacity
        self.body = ti.field(ti.i32, shape=capacity)
        self.other = ti.field(ti.i32, shape=capacity)
        self.point = vec3.field(shape=capacity)
        self.normal = vec3.field(shape=capacity)
        self.point_body = vec3.field(shape=capacity)
        self.normal_body = vec3.field(shape=capacity)
        self.force_body = vec3.field(shape=capacity)
        self.impulse = vec3.field(shape=capacity)
        self.force = vec3.field(shape=capacity)
        self.duration = ti.field(ti.f32, shape=capacity)
        self.speed = ti.field(ti.f32, shape=capacity)
        self.dt = ti.field(ti.f32, shape=capacity)
        self.substep = ti.field(ti.i32, shape=capacity)
        self.count = ti.field(ti.i32, shape=())
        self.overflow = ti.field(ti.i32, shape=())
        size = 1
        while size < 2 * contact_capacity:
            size *= 2
        self.table_size = size
        self.pair_a = ti.field(ti.i32, shape=size)
        self.pair_b = ti.field(ti.i32, shape=size)
        self.pair_static = ti.field(ti.i32, shape=size)
        self.pair_impulse = vec3.field(shape=size)
        self.pair_normal = vec3.field(shape=size)
        self.pair_point_sum = vec3.field(shape=size)
        self.pair_weight = ti.field(ti.f32, shape=size)
        self.pair_speed = ti.field(ti.f32, shape=size)
        self.pair_used = ti.field(ti.i32, shape=contact_capacity)
        self.pair_a.fill(-9)


@ti.func
def _emit(bodies: ti.template(), impacts: ti.template(), body, other, point, normal, impulse, force, duration,
          speed, dt, substep):
    k = impacts.count[None]
    if k < impacts.capacity:
        rot = bodies.rotation[body]  # this substep's pose (broadphase)
        impacts.point_body[k] = la.mat_t_vec(rot, point - bodies.position[body])
        impacts.normal_body[k] = la.mat_t_vec(rot, normal)
        impacts.force_body[k] = la.mat_t_vec(rot, force)
        impacts.body[k] = body
        impacts.other[k] = other
        impacts.point[k] = point
        impacts.normal[k] = normal
        impacts.impulse[k] = impulse
        impacts.force[k] = force
        impacts.duration[k] = duration
        impacts.speed[k] = speed
        impacts.dt[k] = dt
        impacts.substep[k] = substep
        impacts.count[None] = k + 1
    else:
        impacts.overflow[None] += 1


@ti.func
def hertz_impact(bodies: ti.template(), a, b, speed):
    """(peak force [N], contact time [s]) of body ``a`` hitting body ``b`` (< 0: a static
    collider) at approach ``speed`` [m/s]; (0, 0) when undefined (both rigid or both
    immovable)."""
    inverse_mass = bodies.inverse_mass[a]
    compliance = bodies.contact_compliance[a]
    inverse_radius = 1.0 / bodies.contact_radius[a]
    if b >= 0:
        inverse_mass += bodies.inverse_mass[b]
        compliance += bodies.contact_compliance[b]
        inverse_radius += 1.0 / bodies.contact_radius[b]
    peak = 0.0
    duration = 0.0
    if inverse_mass > 0.0 and compliance > 0.0 and speed > 0.0:
        mass = 1.0 / inverse_mass
        modulus = 1.0 / compliance
        root_radius = ti.sqrt(1.0 / inverse_radius)
        depth = ti.pow(15.0 * mass * speed * speed / (16.0 * modulus * root_radius), 0.4)
        peak = 4.0 / 3.0 * modulus * root_radius * depth * ti.sqrt(depth)
        duration = 2.94 * depth / speed
    return peak, duration


@ti.func
def record_impacts(bodies: ti.template(), contacts: ti.template(), impacts: ti.template(), dt, substep,
                   force_threshold, impact_speed):
    ti.loop_config(serialize=True)
    for _ in range(1):  # one serial task
        mask = impacts.table_size - 1
        used = 0
        for m in range(ti.min(contacts.count[None], contacts.capacity)):
            c = contacts.order[m]  # (the solver's order: sums reproducible run to run)
            jn = contacts.normal_impulse[c]
            impulse = jn * contacts.normal[c] + contacts.tangent_impulse[c]
            weight = la.norm(impulse)
            if weight > 0.0:
                a = contacts.body_a[c]
                b = contacts.body_b[c]
                s = contacts.static_index[c]
                # Weighted by the whole impulse, not jn alone: the restitution sweeps may
                # leave a contact with friction impulse and jn = 0, and a pair of only such
                # contacts summed to a zero normal (a NaN normal in the fracture stage).
                normal = weight * contacts.normal[c]
                if b >= 0 and b < a:  # one key per body pair: lower slot first
                    a, b = b, a
                    impulse = -impulse
                    normal = -normal
                slot = ((a * 73856093) ^ (b * 19349663) ^ (s * 83492791)) & mask
                while impacts.pair_a[slot] != -9 and not (
                    impacts.pair_a[slot] == a and impacts.pair_b[slot] == b and impacts.pair_static[slot] == s
                ):
                    slot = (slot + 1) & mask
                if impacts.pair_a[slot] == -9:
                    impacts.pair_a[slot] = a
                    impacts.pair_b[slot] = b
                    impacts.pair_static[slot] = s
                    impacts.pair_impulse[slot] = vec3(0.0)
                    impacts.pair_normal[slot] = vec3(0.0)
                    impacts.pair_point_sum[slot] = vec3(0.0)
                    impacts.pair_weight[slot] = 0.0
                    impacts.pair_speed[slot] = 0.0
                    impacts.pair_used[used] = slot
                    used += 1
                impacts.pair_impulse[slot] += impulse
                impacts.pair_normal[slot] += normal
                impacts.pair_point_sum[slot] += weight * contacts.point[c]
                impacts.pair_weight[slot] += weight
                impacts.pair_speed[slot] = ti.max(impacts.pair_speed[slot], -contacts.approach_speed[c])
        for u in range(used):
            slot = impacts.pair_used[u]
            impulse = impacts.pair_impulse[slot]
            a = impacts.pair_a[slot]
            b = impacts.pair_b[slot]
            speed = impacts.pair_speed[slot]
            peak = 0.0
            duration = 0.0
            if speed > impact_speed:
                peak, duration = hertz_impact(bodies, a, b, speed)
            force = impulse / dt
            if duration > 0.0:
                force = impulse.normalized(1e-30) * peak
            if la.norm(force) > force_threshold:
                point = impacts.pair_point_sum[slot] / impacts.pair_weight[slot]
                normal = impacts.pair_normal[slot].normalized(1e-30)
                _emit(bodies, impacts, a, b, point, normal, impulse, force, duration, speed, dt, substep)
                if b >= 0:
                    _emit(bodies, impacts, b, a, point, -normal, -impulse, -force, duration, speed, dt, substep)
            impacts.pair_a[slot] = -9
