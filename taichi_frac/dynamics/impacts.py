"""Impact records for the fracture stage: contact impulses summed per (body, other) pair
per substep, kept when the force |J| / dt exceeds a threshold.

The pairing runs serially (one task): a small open-addressing table keyed by (body, other,
static index), cleared through its list of used slots, so its cost follows the contact
count, not the table size.
"""


import taichi as ti

vec3 = ti.math.vec3


@ti.data_oriented
class Impacts:
    """Rows kept during one ``advance``, shape (max_impacts,).

    Fields (writer: record_impacts): body (i32), other (i32 body slot, -1 ground, -2 static
    box), point (vec3 [m] world, impulse-weighted mean contact point), normal (vec3 unit
    world, into ``body``), impulse (vec3 [N s] on ``body``), dt ([s] substep length),
    substep (i32 index within the advance). Scalars: count, overflow.
    Pair table, shape (table_size,): pair_a, pair_b, pair_static (keys, -9 = empty),
    pair_impulse, pair_normal, pair_point_sum (vec3), pair_weight; pair_used (slots in use).
    """

    def __init__(self, capacity: int, contact_capacity: int):
        self.capacity = capacity
        self.body = ti.field(ti.i32, shape=capacity)
        self.other = ti.field(ti.i32, shape=capacity)
        self.point = vec3.field(shape=capacity)
        self.normal = vec3.field(shape=capacity)
        self.impulse = vec3.field(shape=capacity)
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
        self.pair_used = ti.field(ti.i32, shape=contact_capacity)
        self.pair_a.fill(-9)


@ti.func
def _emit(impacts: ti.template(), body, other, point, normal, impulse, dt, substep):
    k = impacts.count[None]
    if k < impacts.capacity:
        impacts.body[k] = body
        impacts.other[k] = other
        impacts.point[k] = point
        impacts.normal[k] = normal
        impacts.impulse[k] = impulse
        impacts.dt[k] = dt
        impacts.substep[k] = substep
        impacts.count[None] = k + 1
    else:
        impacts.overflow[None] += 1


@ti.func
def record_impacts(contacts: ti.template(), impacts: ti.template(), dt, substep,
                   force_threshold):
    ti.loop_config(serialize=True)
    for _ in range(1):  # one serial task
        mask = impacts.table_size - 1
        used = 0
        for c in range(ti.min(contacts.count[None], contacts.capacity)):
            jn = contacts.normal_impulse[c]
            impulse = jn * contacts.normal[c] + contacts.tangent_impulse[c]
            weight = impulse.norm()
            if weight > 0.0:
                a = contacts.body_a[c]
                b = contacts.body_b[c]
                s = contacts.static_index[c]
                normal = jn * contacts.normal[c]
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
                    impacts.pair_used[used] = slot
                    used += 1
                impacts.pair_impulse[slot] += impulse
                impacts.pair_normal[slot] += normal
                impacts.pair_point_sum[slot] += weight * contacts.point[c]
                impacts.pair_weight[slot] += weight
        for u in range(used):
            slot = impacts.pair_used[u]
            impulse = impacts.pair_impulse[slot]
            if impulse.norm() > force_threshold * dt:
                a = impacts.pair_a[slot]
                b = impacts.pair_b[slot]
                point = impacts.pair_point_sum[slot] / impacts.pair_weight[slot]
                normal = impacts.pair_normal[slot].normalized(1e-30)
                _emit(impacts, a, b, point, normal, impulse, dt, substep)
                if b >= 0:
                    _emit(impacts, b, a, point, -normal, -impulse, dt, substep)
            impacts.pair_a[slot] = -9
