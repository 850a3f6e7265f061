"""Per-body bounds shared by the broadphase (each substep) and the substep count (each
frame): whether a body is idle, how fast any of its points can move, and whether a sphere
around it reaches a static collider."""

import taichi as ti


@ti.func
def is_idle(bodies: ti.template(), b):
    """Asleep or fixed: it neither moves nor makes contacts of its own."""
    return bodies.sleeping[b] == 1 or bodies.fixed[b] == 1


@ti.func
def motion_speed(bodies: ti.template(), statics: ti.template(), b, dt):
    """Bound on the speed of any point of body ``b`` over a step of ``dt`` [s]:
    |v| + |g| dt + |w| x bounding radius [m/s]."""
    return (bodies.linear_velocity[b].norm() + statics.gravity[None].norm() * dt
            + bodies.angular_velocity[b].norm() * bodies.bounding_radius[b])


@ti.func
def near_static(statics: ti.template(), x, radius):
    """1 when the sphere at ``x`` [m] of ``radius`` [m] reaches a ground plane or a static
    box, else 0."""
    near = 0
    for k in range(statics.plane_count[None]):
        if x[2] - radius < statics.plane_height[k]:
            near = 1
    for k in range(statics.box_count[None]):
        local = statics.box_rotation[k].transpose() @ (x - statics.box_center[k])
        q = ti.math.clamp(local, -statics.box_half_extents[k], statics.box_half_extents[k])
        if (local - q).norm_sqr() < radius * radius:
            near = 1
    return near
