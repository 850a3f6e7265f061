"""Per-body bounds shared by the broadphase (each substep) and the substep count (each
frame): whether a body is idle, how fast any of its points can move, and whether a sphere
around it reaches a static collider."""


from ..runtime import ti
from . import linalg3 as la
from .quaternion import quat_mul

vec3 = ti.math.vec3


@ti.func
def is_idle(bodies: ti.template(), b):
    """Asleep or fixed: it neither moves nor makes contacts of its own."""
    return bodies.sleeping[b] == 1 or bodies.fixed[b] == 1


@ti.func
def fastest_point_speed(bodies: ti.template(), b):
    """|v| + |w| x bounding radius [m/s]: no point of body ``b`` moves faster now (the sleep
    test, and whether a touch wakes a sleeping body)."""
    return la.norm(bodies.linear_velocity[b]) + la.norm(bodies.angular_velocity[b]) * bodies.bounding_radius[b]


@ti.func
def anchor_drift(bodies: ti.template(), b):
    """How far [m] any point of body ``b`` may be from where it was at its sleep anchor
    (``sleep_anchor``, ``sleep_anchor_orientation``): the centre's distance plus the
    rotation angle x bounding radius. A body that stays within a small drift while its
    speed jumps is jittering in place, not moving (the sleep test)."""
    qa = bodies.sleep_anchor_orientation[b]
    turn = quat_mul(ti.math.vec4(qa[0], -qa[1], -qa[2], -qa[3]), bodies.orientation[b])
    # (|vector part| = sin(angle / 2): twice it is the angle to within 1 % up to 0.5 rad)
    angle = 2.0 * la.norm(ti.math.vec3(turn[1], turn[2], turn[3]))
    return la.norm(bodies.position[b] - bodies.sleep_anchor[b]) + angle * bodies.bounding_radius[b]


@ti.func
def motion_speed(bodies: ti.template(), statics: ti.template(), b, dt):
    """Bound on the speed of any point of body ``b`` over a step of ``dt`` [s]:
    |v| + |g| dt + |w| x bounding radius [m/s]."""
    return (la.norm(bodies.linear_velocity[b]) + la.norm(statics.gravity[None]) * dt
            + la.norm(bodies.angular_velocity[b]) * bodies.bounding_radius[b])


@ti.func
def pair_motion(bodies: ti.template(), statics: ti.template(), a, b, dt):
    """Bound on how far the gap between any point of body ``a`` and any point of body
    ``b`` closes over a step of ``dt`` [s] [m]: (|v_a - v_b| + |w_a| R_a + |w_b| R_b) dt
    (R: bounding radius) plus the rotations' departure from straight paths and gravity's
    velocity gain, ((|w_a|^2 R_a + |w_b|^2 R_b) / 2 + |g|) dt^2. An idle body counts as at
    rest. Two bodies falling side by side close nothing, where their two motion bounds add
    up to twice their fall; this keeps their grid cells and contact reach small."""
    va = vec3(0.0)
    vb = vec3(0.0)
    spin = 0.0
    curve = 0.0
    if not is_idle(bodies, a):
        va = bodies.linear_velocity[a]
        w = la.norm(bodies.angular_velocity[a])
        spin += w * bodies.bounding_radius[a]
        curve += 0.5 * w * w * bodies.bounding_radius[a]
    if not is_idle(bodies, b):
        vb = bodies.linear_velocity[b]
        w = la.norm(bodies.angular_velocity[b])
        spin += w * bodies.bounding_radius[b]
        curve += 0.5 * w * w * bodies.bounding_radius[b]
    return (la.norm(va - vb) + spin) * dt + (curve + la.norm(statics.gravity[None])) * dt * dt


@ti.func
def near_statics(statics: ti.template(), x, radius):
    """(plane, box): 1 each when the sphere at ``x`` [m] of ``radius`` [m] reaches a
    ground plane, resp. a static box, else 0."""
    plane = 0
    box = 0
    for k in range(statics.plane_count[None]):
        if x[2] - radius < statics.plane_height[k]:
            plane = 1
    for k in range(statics.box_count[None]):
        local = la.mat_t_vec(statics.box_rotation[k], x - statics.box_center[k])
        q = ti.math.clamp(local, -statics.box_half_extents[k], statics.box_half_extents[k])
        if la.norm_sqr(local - q) < radius * radius:
            box = 1
    return plane, box


@ti.func
def near_static(statics: ti.template(), x, radius):
    """1 when the sphere at ``x`` [m] of ``radius`` [m] reaches a ground plane or a static
    box, else 0."""
    plane, box = near_statics(statics, x, radius)
    return ti.max(plane, box)
