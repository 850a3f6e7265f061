"""Broadphase: which bodies may touch which this substep.

``body_cull`` gives every body its rotation matrix and motion bound for the substep, its
list of neighbouring bodies (grown bounding spheres overlap, at least one of the two awake)
with how far each pair can close, and whether it reaches a static collider. The narrowphase
then looks for sphere contacts only between neighbours, in each partner's body-frame grid
(``grid.py``).
"""

import taichi as ti

from .. import runtime
from ..dynamics.bounds import is_idle, motion_speed, near_static, pair_motion
from ..dynamics.quaternion import quat_to_matrix


@ti.func
def _grown_radius(bodies: ti.template(), b, margin):
    """Bounding radius grown by the contact margin and this substep's motion [m]."""
    return bodies.bounding_radius[b] + margin * bodies.max_particle_radius[b] + bodies.motion[b]


@ti.func
def _body_motion(bodies: ti.template(), statics: ti.template(), b, dt):
    if bodies.active[b] == 1:
        if bodies.wake_request[b] == 1:
            # Woken by a moving body's touch in the last substep. Woken here, before this
            # substep's contacts are made, so it also gets its contacts with sleeping
            # neighbours (woken later, it fell through its sleeping supports for a
            # substep, hit them at g dt and woke them in turn: a pile never slept). Its
            # sleep timer is kept (>= sleep_time): it sleeps again at the end of the
            # substep unless the touch set it moving, and until then wakes no one (the
            # narrowphase wakes only from bodies whose timer is below sleep_time).
            bodies.sleeping[b] = 0
            bodies.wake_request[b] = 0
        bodies.rotation[b] = quat_to_matrix(bodies.orientation[b])
        motion = 0.0
        if not is_idle(bodies, b):
            motion = motion_speed(bodies, statics, b, dt) * dt
        bodies.motion[b] = motion


@ti.func
def _body_neighbors(bodies: ti.template(), statics: ti.template(), b, margin, dt):
    count = 0
    near = 0
    if bodies.active[b] == 1:
        xb = bodies.position[b]
        rb = bodies.bounding_radius[b] + margin * bodies.max_particle_radius[b]
        b_idle = is_idle(bodies, b)
        for o in range(bodies.slot_end[None]):
            if o != b and bodies.active[o] == 1 and count >= 0:
                if not (b_idle and is_idle(bodies, o)):
                    closing = pair_motion(bodies, statics, b, o, dt)
                    reach = rb + bodies.bounding_radius[o] + margin * bodies.max_particle_radius[o] + closing
                    if (bodies.position[o] - xb).norm_sqr() < reach * reach:
                        if count < bodies.max_neighbors:
                            bodies.neighbors[b, count] = o
                            bodies.neighbor_motion[b, count] = closing
                            count += 1
                        else:
                            count = -1
        if not b_idle:
            near = near_static(statics, xb, _grown_radius(bodies, b, margin))
    bodies.neighbor_count[b] = count
    bodies.near_body[b] = 1 if count != 0 else 0
    bodies.near_static[b] = near


@ti.func
def body_cull(bodies: ti.template(), statics: ti.template(), margin, dt):
    """Two passes over bodies. First: rotation matrix and motion bound of each body this
    substep. Second: its neighbour list (grown bounding spheres overlap, at least one of
    the two awake, grown by how far the pair can close this substep, ``bounds.pair_motion``;
    O(bodies^2), fine for the thousand-odd bodies a scene holds; more than
    ``max_neighbors`` neighbours set the count to -1 and the narrowphase then tries every
    body) and whether it reaches a static collider.
    Serial on the CPU (see ``runtime.SERIAL_SMALL_LOOPS``), parallel elsewhere."""
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for b in range(bodies.slot_end[None]):
                _body_motion(bodies, statics, b, dt)
            for b in range(bodies.slot_end[None]):
                _body_neighbors(bodies, statics, b, margin, dt)
    else:
        for b in range(bodies.slot_end[None]):
            _body_motion(bodies, statics, b, dt)
        for b in range(bodies.slot_end[None]):
            _body_neighbors(bodies, statics, b, margin, dt)
