"""Integration of the bodies (one pass over body slots per kernel).

Order in a substep (``World._substep``): integrate_velocities (gravity, wake requests,
this substep's solver masses) -> contacts solved -> integrate_positions (semi-implicit
Euler: positions from the new velocities; sleeping).

Rotation conserves angular momentum: torque-free, L = I_world w is constant, so after the
orientation update w is recomputed from L with the new world inertia (the gyroscopic term
exactly, without the energy growth of an explicit w x Iw step). The rotation uses the mean
of the start and predicted end angular velocity, which keeps the energy error at ~1e-4.
"""


from ..runtime import ti
from .. import runtime
from ..collision import surface
from ..kinematics import linalg3 as la
from ..kinematics.bounds import anchor_drift, fastest_point_speed, is_idle, motion_speed, near_statics
from ..kinematics.quaternion import quat_integrate, quat_to_matrix

vec3 = ti.math.vec3
mat3 = ti.math.mat3


@ti.func
def _integrate_velocity(bodies: ti.template(), gravity, b, dt):
    if bodies.active[b] == 1:
        bodies.touched[b] = 0
        bodies.pseudo_linear_velocity[b] = vec3(0.0)
        bodies.pseudo_angular_velocity[b] = vec3(0.0)
        if bodies.sleeping[b] == 1 or bodies.fixed[b] == 1:
            bodies.solver_inverse_mass[b] = 0.0
            bodies.solver_inverse_inertia[b] = mat3(0.0)
        else:
            rot = quat_to_matrix(bodies.orientation[b])
            bodies.solver_inverse_mass[b] = bodies.inverse_mass[b]
            bodies.solver_inverse_inertia[b] = la.mat_mat_t(la.mat_mat(rot, bodies.inverse_inertia_body[b]), rot)
            bodies.linear_velocity[b] += gravity * dt


@ti.func
def integrate_velocities(bodies: ti.template(), statics: ti.template(), dt):
    """Pass over bodies: gravity, this substep's solver masses."""
    gravity = statics.gravity[None]
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for b in range(bodies.slot_end[None]):
                _integrate_velocity(bodies, gravity, b, dt)
    else:
        for b in range(bodies.slot_end[None]):
            _integrate_velocity(bodies, gravity, b, dt)


@ti.func
def _integrate_position(bodies: ti.template(), gravity, b, dt, max_rotation, sleep_linear_speed, sleep_angular_speed,
                        max_correction_speed):
    if bodies.active[b] == 1 and bodies.sleeping[b] == 0 and bodies.fixed[b] == 0:
        v = bodies.linear_velocity[b]
        w = bodies.angular_velocity[b]
        # The split impulse's push-out, held to max_correction_speed at every point of the
        # body: each contact asks for at most that speed, but a body overlapped from all
        # sides (a fracture's piece inside its sibling's collision spheres) has push-outs
        # that fight, and solving them can pump its pseudo velocity far past that speed.
        v_pseudo = bodies.pseudo_linear_velocity[b]
        w_pseudo = bodies.pseudo_angular_velocity[b]
        fastest = la.norm(v_pseudo) + la.norm(w_pseudo) * bodies.bounding_radius[b]
        if fastest > max_correction_speed:
            v_pseudo *= max_correction_speed / fastest
            w_pseudo *= max_correction_speed / fastest
        step = (v + v_pseudo) * dt
        if bodies.touched[b] == 0:
            # No contact: the exact constant-gravity step x += v0 dt + g dt^2 / 2 (v is
            # already v0 + g dt), so free flight is exact at any substep length.
            step -= 0.5 * gravity * dt * dt
        bodies.position[b] += step
        # Rotation in as many pieces as keep each under max_rotation [rad]: a body spinning
        # fast (a steel ball leaving the glass at ~100 rad/s) turns accurately without
        # shortening every body's substep.
        q = bodies.orientation[b]
        rot = quat_to_matrix(q)
        momentum = la.mat_vec(rot, la.mat_vec(bodies.inertia_body[b], la.mat_t_vec(rot, w)))
        pieces = ti.max(1, ti.cast(ti.ceil(la.norm(w + w_pseudo) * dt / max_rotation), ti.i32))
        h = dt / pieces
        for _ in range(pieces):
            # Trapezoidal rotation: predict the end-of-piece w from L, rotate with the mean
            # (first-order rotation with the start w drifts the energy steadily).
            rot_end = quat_to_matrix(quat_integrate(q, w + w_pseudo, h))
            w_end = la.mat_vec(rot_end, la.mat_vec(bodies.inverse_inertia_body[b], la.mat_t_vec(rot_end, momentum)))
            q = quat_integrate(q, 0.5 * (w + w_end) + w_pseudo, h)
            rot = quat_to_matrix(q)
            w = la.mat_vec(rot, la.mat_vec(bodies.inverse_inertia_body[b], la.mat_t_vec(rot, momentum)))
        bodies.orientation[b] = q
        bodies.angular_velocity[b] = w
        # Sleep test on the fastest point (|v| + |w| R), so a small piece turning slowly
        # (2 cm fragment at 0.1 rad/s: 2 mm/s) sleeps like a large one.
        # (whether it sleeps is decided with the bodies it touches: sleep_together)
        # A substep a little over the sleep speeds (a jolt in a settling heap) costs the timer a
        # few substeps, not all it has: resetting it keeps whole heaps awake for one chip's jolts.
        # A body that stays within STILL_FRACTION of a particle radius of its anchor counts
        # as slow however fast it jitters: a resting contact made one substep and lost the
        # next drops a piece by one substep of free fall and lifts it back, and such jolts
        # would keep settled pieces awake to the end.
        spin = la.norm(w)
        speed = fastest_point_speed(bodies, b)
        still = anchor_drift(bodies, b) < STILL_FRACTION * bodies.mean_particle_radius[b]
        if not still:
            bodies.sleep_anchor[b] = bodies.position[b]
            bodies.sleep_anchor_orientation[b] = q
        if still or (speed < sleep_linear_speed and spin < sleep_angular_speed):
            bodies.sleep_timer[b] += dt
        elif speed < JOLT_FACTOR * sleep_linear_speed and spin < JOLT_FACTOR * sleep_angular_speed:
            bodies.sleep_timer[b] = ti.max(bodies.sleep_timer[b] - JOLT_PENALTY * dt, 0.0)
        else:
            bodies.sleep_timer[b] = 0.0


#: A substep under this many times the sleep speeds takes JOLT_PENALTY substeps off the sleep
#: timer instead of resetting it: a body must be slow over four fifths of its substeps to sleep.
JOLT_FACTOR = 3.0
JOLT_PENALTY = 4.0

#: A body whose points all stay within this fraction of its mean collision-sphere radius of
#: where they were (``kinematics.bounds.anchor_drift``) counts as slow for the sleep timer,
#: whatever its speed in a substep.
STILL_FRACTION = 0.1


@ti.func
def integrate_positions(bodies: ti.template(), statics: ti.template(), dt, max_rotation, sleep_linear_speed,
                        sleep_angular_speed, max_correction_speed):
    """Pass over bodies: positions and orientations from the new velocities (rotation in
    pieces of at most ``max_rotation`` [rad]); the sleep timers (``sleep_together`` then
    decides who sleeps)."""
    gravity = statics.gravity[None]
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for b in range(bodies.slot_end[None]):
                _integrate_position(bodies, gravity, b, dt, max_rotation, sleep_linear_speed, sleep_angular_speed,
                                    max_correction_speed)
    else:
        for b in range(bodies.slot_end[None]):
            _integrate_position(bodies, gravity, b, dt, max_rotation, sleep_linear_speed, sleep_angular_speed,
                                max_correction_speed)


@ti.func
def sleep_together(bodies: ti.template(), contacts: ti.template(), sleep_time):
    """One serial task: an awake body that has been slow for ``sleep_time`` [s] sleeps
    (velocities zeroed) when every awake body it touches this substep has been slow that
    long too (sleeping, fixed and static partners do not count). A body slept alone while
    its neighbours still settled: their contacts with it turned rigid, the jolt (~1 cm/s)
    reset their timers and woke it, and three ring pieces in a heap kept each other awake
    for the last 1.5 s of the 13 rings. Whole contact islands sleeping together (Box2D,
    Bullet) cured that but kept a pile of 64 blocks awake for as long as any one of them
    crept (0 of 64 asleep after 3 s in three drops of four)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        end = bodies.slot_end[None]
        for b in range(end):
            bodies.sleep_blocked[b] = 0
        for k in range(ti.min(contacts.count[None], contacts.capacity)):
            a = contacts.body_a[k]
            o = contacts.body_b[k]
            if o >= 0:
                if not is_idle(bodies, a) and not is_idle(bodies, o):
                    if bodies.sleep_timer[o] < sleep_time:
                        bodies.sleep_blocked[a] = 1
                    if bodies.sleep_timer[a] < sleep_time:
                        bodies.sleep_blocked[o] = 1
        for b in range(end):
            if bodies.active[b] == 1 and not is_idle(bodies, b) and bodies.sleep_timer[b] >= sleep_time \
                    and bodies.sleep_blocked[b] == 0:
                bodies.sleeping[b] = 1
                bodies.linear_velocity[b] = vec3(0.0)
                bodies.angular_velocity[b] = vec3(0.0)


#: After integration no collision sphere of an awake body is left deeper in a ground plane
#: than this fraction of its radius (the resting bound, 10 %): the body is lifted by
#: the excess. A backstop for what the solver cannot see coming: a 17 g chip struck by a
#: 2.6 kg ring piece spun from 7 to 105 rad/s in one substep and turned spheres that had
#: no contact yet 1.28 physics-particle radii into the floor.
GROUND_HOLD = 0.1


@ti.func
def hold_above_ground(bodies: ti.template(), particles: ti.template(), statics: ti.template(), dt):
    """Serial pass over the awake bodies near a static collider (this substep's broadphase
    flag): the deepest of their collision spheres below each ground plane after
    integration, and a vertical lift by what exceeds ``GROUND_HOLD`` of that sphere's
    radius. Velocities are untouched (the contacts of the next substep see the rest). A
    body that moved less than that fraction of half its mean sphere radius in the substep
    is skipped: it can have sunk no further (a resting pile costs nothing here)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        for b in range(bodies.slot_end[None]):
            moved = (la.norm(bodies.linear_velocity[b]) + la.norm(bodies.pseudo_linear_velocity[b])
                     + (la.norm(bodies.angular_velocity[b]) + la.norm(bodies.pseudo_angular_velocity[b]))
                     * bodies.bounding_radius[b]) * dt
            if bodies.active[b] == 1 and bodies.near_static[b] == 1 and not is_idle(bodies, b) \
                    and moved > 0.5 * GROUND_HOLD * bodies.mean_particle_radius[b]:
                rot = quat_to_matrix(bodies.orientation[b])
                up = vec3(rot[2, 0], rot[2, 1], rot[2, 2])  # world z of each body axis
                z0 = bodies.position[b][2]
                lift = 0.0
                start = bodies.particle_start[b]
                for p in range(start, start + bodies.particle_count[b]):
                    r = particles.radius[p]
                    bottom = z0 + la.dot(up, particles.offset[p]) - r
                    for k in range(statics.plane_count[None]):
                        if particles.point_count[p] > 0 and statics.plane_height[k] - bottom - GROUND_HOLD * r > 0.0:
                            # (the sphere's bottom may stand proud of its patch: the
                            # patch's own lowest point decides)
                            bottom = z0 + surface.lowest(particles, p, up)
                        lift = ti.max(lift, statics.plane_height[k] - bottom - GROUND_HOLD * r)
                if lift > 0.0:
                    bodies.position[b][2] += lift


@ti.func
def _is_near(bodies: ti.template(), statics: ti.template(), b, grow, frame_dt, margin):
    """Whether body ``b``'s bounding sphere grown by ``grow`` [m] may reach another body
    (grown by its own margin and frame motion) or a static box this frame (1), only a
    ground plane (2), or nothing (0)."""
    xb = bodies.position[b]
    plane, box = near_statics(statics, xb, grow)
    near = box
    for o in range(bodies.slot_end[None]):
        if o != b and bodies.active[o] == 1 and near == 0:
            reach = grow + bodies.bounding_radius[o] + margin * bodies.max_particle_radius[o]
            if not is_idle(bodies, o):
                reach += motion_speed(bodies, statics, o, frame_dt) * frame_dt
            if la.norm_sqr(bodies.position[o] - xb) < reach * reach:
                near = 1
    if near == 0 and plane == 1:
        near = 2
    return near


@ti.func
def frame_substeps(f: ti.template(), margin, frame_dt, substeps, motion_fraction):
    """Substeps this frame needs: 0 when no body is awake, 1 when every awake body is in
    free flight (exact ballistic steps; fast spin is integrated in pieces by
    integrate_positions); otherwise the largest over the bodies that may touch something
    this frame (bounding sphere grown by a frame's motion reaches another body or a static
    collider) of ``substeps``, or more so that the body moves at most ``motion_fraction``
    of its mean particle radius per substep. ``f``: the World's ``stages.WorldFields``."""
    need = 0
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for b in range(f.bodies.slot_end[None]):
                need = ti.max(need, _substeps_of(f.bodies, f.statics, b, margin, frame_dt, substeps, motion_fraction))
    else:
        for b in range(f.bodies.slot_end[None]):
            ti.atomic_max(need, _substeps_of(f.bodies, f.statics, b, margin, frame_dt, substeps, motion_fraction))
    return need


@ti.func
def _substeps_of(bodies: ti.template(), statics: ti.template(), b, margin, frame_dt, substeps, motion_fraction):
    count = 0
    if bodies.active[b] == 1 and not is_idle(bodies, b):
        speed = motion_speed(bodies, statics, b, frame_dt)
        grow = bodies.bounding_radius[b] + margin * bodies.max_particle_radius[b] + speed * frame_dt
        count = 1
        near = _is_near(bodies, statics, b, grow, frame_dt, margin)
        if near != 0:
            closing = speed
            if near == 2:  # only a ground plane within reach: what closes on it is the fall
                closing = ti.max(-bodies.linear_velocity[b][2], 0.0) + la.norm(statics.gravity[None]) * frame_dt \
                    + la.norm(bodies.angular_velocity[b]) * bodies.bounding_radius[b]
            ratio = closing * frame_dt / (motion_fraction * bodies.mean_particle_radius[b])
            count = ti.max(count, ti.max(substeps, ti.cast(ti.ceil(ratio), ti.i32)))
    return count
