"""Integration of the bodies (one pass over body slots per kernel).

Order in a substep (``World._substep``): integrate_velocities (gravity, wake requests,
this substep's solver masses) -> contacts solved -> integrate_positions (semi-implicit
Euler: positions from the new velocities; sleeping).

Rotation conserves angular momentum: torque-free, L = I_world w is constant, so after the
orientation update w is recomputed from L with the new world inertia (the gyroscopic term
exactly, without the energy growth of an explicit w x Iw step). The rotation uses the mean
of the start and predicted end angular velocity, which keeps the energy error at ~1e-4.
"""


import taichi as ti

from .quaternion import quat_integrate, quat_to_matrix

vec3 = ti.math.vec3
mat3 = ti.math.mat3


@ti.func
def integrate_velocities(bodies: ti.template(), gravity, dt):
    for b in range(bodies.slot_end[None]):
        if bodies.active[b] == 1:
            if bodies.wake_request[b] == 1:
                bodies.sleeping[b] = 0
                bodies.sleep_timer[b] = 0.0
                bodies.wake_request[b] = 0
            bodies.pseudo_linear_velocity[b] = vec3(0.0)
            bodies.pseudo_angular_velocity[b] = vec3(0.0)
            if bodies.sleeping[b] == 1 or bodies.fixed[b] == 1:
                bodies.solver_inverse_mass[b] = 0.0
                bodies.solver_inverse_inertia[b] = mat3(0.0)
            else:
                rot = quat_to_matrix(bodies.orientation[b])
                bodies.solver_inverse_mass[b] = bodies.inverse_mass[b]
                bodies.solver_inverse_inertia[b] = rot @ bodies.inverse_inertia_body[b] @ rot.transpose()
                bodies.linear_velocity[b] += gravity * dt


@ti.func
def integrate_positions(bodies: ti.template(), dt, sleep_linear_speed,
                        sleep_angular_speed, sleep_time):
    for b in range(bodies.slot_end[None]):
        if bodies.active[b] == 1 and bodies.sleeping[b] == 0 and bodies.fixed[b] == 0:
            v = bodies.linear_velocity[b]
            w = bodies.angular_velocity[b]
            bodies.position[b] += (v + bodies.pseudo_linear_velocity[b]) * dt
            q = bodies.orientation[b]
            rot = quat_to_matrix(q)
            momentum = rot @ (bodies.inertia_body[b] @ (rot.transpose() @ w))
            # Trapezoidal rotation: predict the end-of-step w from L, rotate with the mean
            # (first-order rotation with the start w drifts energy by ~1 % per 1,000 steps).
            w_pseudo = bodies.pseudo_angular_velocity[b]
            rot_end = quat_to_matrix(quat_integrate(q, w + w_pseudo, dt))
            w_end = rot_end @ (bodies.inverse_inertia_body[b] @ (rot_end.transpose() @ momentum))
            q = quat_integrate(q, 0.5 * (w + w_end) + w_pseudo, dt)
            bodies.orientation[b] = q
            rot = quat_to_matrix(q)
            w = rot @ (bodies.inverse_inertia_body[b] @ (rot.transpose() @ momentum))
            bodies.angular_velocity[b] = w
            if v.norm() < sleep_linear_speed and w.norm() < sleep_angular_speed:
                bodies.sleep_timer[b] += dt
                if bodies.sleep_timer[b] >= sleep_time:
                    bodies.sleeping[b] = 1
                    bodies.linear_velocity[b] = vec3(0.0)
                    bodies.angular_velocity[b] = vec3(0.0)
            else:
                bodies.sleep_timer[b] = 0.0


@ti.kernel
def motion_ratio(bodies: ti.template()) -> ti.f32:
    """Largest (|v| + |w| x bounding radius) / smallest particle radius over awake
    bodies [1/s]: the substep must be short enough that this times dt stays below the
    allowed fraction (no tunnelling). -1 when no body is awake."""
    ratio = -1.0
    for b in range(bodies.slot_end[None]):
        if bodies.active[b] == 1 and bodies.sleeping[b] == 0 and bodies.fixed[b] == 0:
            speed = bodies.linear_velocity[b].norm() + bodies.angular_velocity[b].norm() * bodies.bounding_radius[b]
            ti.atomic_max(ratio, speed / bodies.min_particle_radius[b])
    return ratio
