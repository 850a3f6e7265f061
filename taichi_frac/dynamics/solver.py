"""Contact response: sequential impulses (projected Gauss-Seidel) with Coulomb friction,
split-impulse penetration correction and a restitution pass.

Why Gauss-Seidel and serial: a ring resting on the ground holds tens of particle contacts
on one body; Jacobi sweeps over them need averaging and many more iterations to stop
jitter, while Gauss-Seidel converges in ~10 sweeps (Catto, "Iterative Dynamics with
Temporal Coherence", GDC 2005). On the CPU backend a serial sweep over a few thousand
contacts costs tens of microseconds; a graph-coloured parallel sweep for GPUs can replace
``solve_contacts`` without changing its inputs or outputs.

Penetration: split impulses (Catto 2006; Bullet's ``splitImpulse``) push bodies apart
through pseudo-velocities integrated into positions only, so correcting overlap never adds
kinetic energy (bodies rest without jitter, deep overlaps separate gently).
Restitution: after the main sweeps, contacts that were approaching faster than a threshold
and carry impulse get a relative normal velocity of -e x their approach speed (Box2D v3,
``b2ApplyRestitution``), which also works with speculative contacts; unlike Box2D's pass,
these sweeps include every other contact with its non-penetration target.
"""


import taichi as ti

from .. import runtime

vec3 = ti.math.vec3
mat3 = ti.math.mat3


@ti.func
def _velocity_at(bodies: ti.template(), b, arm):
    v = vec3(0.0)
    if b >= 0:
        v = bodies.linear_velocity[b] + bodies.angular_velocity[b].cross(arm)
    return v


@ti.func
def _pseudo_velocity_at(bodies: ti.template(), b, arm):
    v = vec3(0.0)
    if b >= 0:
        v = bodies.pseudo_linear_velocity[b] + bodies.pseudo_angular_velocity[b].cross(arm)
    return v


@ti.func
def _inverse_mass_along(bodies: ti.template(), b, arm, direction):
    k = 0.0
    if b >= 0:
        rn = arm.cross(direction)
        k = bodies.solver_inverse_mass[b] + rn.dot(bodies.solver_inverse_inertia[b] @ rn)
    return k


@ti.func
def _apply(bodies: ti.template(), b, arm, impulse):
    if b >= 0:
        bodies.linear_velocity[b] += bodies.solver_inverse_mass[b] * impulse
        bodies.angular_velocity[b] += bodies.solver_inverse_inertia[b] @ arm.cross(impulse)


@ti.func
def _apply_pseudo(bodies: ti.template(), b, arm, impulse):
    if b >= 0:
        bodies.pseudo_linear_velocity[b] += bodies.solver_inverse_mass[b] * impulse
        bodies.pseudo_angular_velocity[b] += bodies.solver_inverse_inertia[b] @ arm.cross(impulse)


@ti.func
def prepare_contacts(bodies: ti.template(), contacts: ti.template(), warm_start):
    """Two serial passes over contacts: arms, normal effective mass, approach speed, body
    flags (no two contacts write one flag at once); then the warm start: each contact's
    impulses from the last substep (projected on its friction cone) applied to the bodies
    (Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        for c in range(ti.min(contacts.count[None], contacts.capacity)):
            _prepare_contact(bodies, contacts, c)
        for c in range(ti.min(contacts.count[None], contacts.capacity)):
            _warm_start(bodies, contacts, c, warm_start)


@ti.func
def _warm_start(bodies: ti.template(), contacts: ti.template(), c, warm_start):
    a = contacts.body_a[c]
    b = contacts.body_b[c]
    n = contacts.normal[c]
    jn = ti.max(contacts.normal_impulse[c], 0.0) * warm_start
    jt = contacts.tangent_impulse[c] * warm_start
    jt -= jt.dot(n) * n
    limit = contacts.friction[c] * jn
    if jt.norm() > limit:
        jt *= limit / jt.norm()
    contacts.normal_impulse[c] = jn
    contacts.tangent_impulse[c] = jt
    impulse = jn * n + jt
    _apply(bodies, a, contacts.arm_a[c], impulse)
    _apply(bodies, b, contacts.arm_b[c], -impulse)


@ti.func
def store_impulses(particles: ti.template(), contacts: ti.template()):
    """Serial passes: keep each contact's final impulses in its querying particle's half
    of the cache for the next substep, then flip the halves."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        following = 1 - particles.parity[None]
        epoch = particles.cache_epoch[None] + 1
        for c in range(ti.min(contacts.count[None], contacts.capacity)):
            i = contacts.query[c]
            if particles.cache_stamp[following, i] != epoch:
                particles.cache_stamp[following, i] = epoch
                particles.cache_count[following, i] = 0
            k = particles.cache_count[following, i]
            if k < particles.cache_key.shape[2]:
                particles.cache_key[following, i, k] = contacts.key[c]
                particles.cache_normal[following, i, k] = contacts.normal_impulse[c]
                particles.cache_tangent[following, i, k] = contacts.tangent_impulse[c]
                particles.cache_count[following, i] = k + 1
        particles.parity[None] = following
        particles.cache_epoch[None] = epoch


@ti.func
def _prepare_contact(bodies: ti.template(), contacts: ti.template(), c):
    a = contacts.body_a[c]
    b = contacts.body_b[c]
    bodies.touched[a] = 1
    if b >= 0:
        bodies.touched[b] = 1
    n = contacts.normal[c]
    arm_a = contacts.point[c] - bodies.position[a]
    arm_b = vec3(0.0)
    if b >= 0:
        arm_b = contacts.point[c] - bodies.position[b]
    contacts.arm_a[c] = arm_a
    contacts.arm_b[c] = arm_b
    k = _inverse_mass_along(bodies, a, arm_a, n) + _inverse_mass_along(bodies, b, arm_b, n)
    contacts.normal_mass[c] = 1.0 / k if k > 0.0 else 0.0
    contacts.approach_speed[c] = (_velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)).dot(n)
    contacts.pseudo_impulse[c] = 0.0


@ti.func
def solve_contacts(bodies: ti.template(), contacts: ti.template(), iterations,
                   restitution_iterations, dt, position_correction,
                   allowed_penetration, max_correction_speed,
                   restitution_threshold):
    """Serial Gauss-Seidel sweeps over the contacts (one task, see the module docstring)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        count = ti.min(contacts.count[None], contacts.capacity)
        for sweep in range(iterations):
            for c in range(count):
                a = contacts.body_a[c]
                b = contacts.body_b[c]
                n = contacts.normal[c]
                arm_a = contacts.arm_a[c]
                arm_b = contacts.arm_b[c]
                mass_n = contacts.normal_mass[c]
                gap = contacts.separation[c]
                # Normal: a speculative contact may close its gap this substep, no more.
                v_rel = _velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)
                target = -ti.max(gap, 0.0) / dt
                old = contacts.normal_impulse[c]
                new = ti.max(old + mass_n * (target - v_rel.dot(n)), 0.0)
                contacts.normal_impulse[c] = new
                _apply(bodies, a, arm_a, (new - old) * n)
                _apply(bodies, b, arm_b, -(new - old) * n)
                # Friction: Coulomb cone, the tangential impulse opposes sliding, |jt| <= mu jn.
                # Skipped while the contact carries no impulse at all (most speculative
                # contacts: their cone is a point and they hold no friction to undo).
                v_rel = vec3(0.0)
                if new > 0.0 or contacts.tangent_impulse[c].norm_sqr() > 0.0:
                    v_rel = _velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)
                v_t = v_rel - v_rel.dot(n) * n
                speed_t = v_t.norm()
                if speed_t > 1e-12:
                    t = v_t / speed_t
                    k_t = _inverse_mass_along(bodies, a, arm_a, t) + _inverse_mass_along(bodies, b, arm_b, t)
                    if k_t > 0.0:
                        old_t = contacts.tangent_impulse[c]
                        new_t = old_t - (speed_t / k_t) * t
                        limit = contacts.friction[c] * new
                        mag = new_t.norm()
                        if mag > limit:
                            new_t *= limit / mag
                        contacts.tangent_impulse[c] = new_t
                        _apply(bodies, a, arm_a, new_t - old_t)
                        _apply(bodies, b, arm_b, old_t - new_t)
                # Split impulse: push-out speed proportional to the penetration beyond slop.
                depth = -gap - allowed_penetration * contacts.radius[c]
                if depth > 0.0:
                    vp = (_pseudo_velocity_at(bodies, a, arm_a) - _pseudo_velocity_at(bodies, b, arm_b)).dot(n)
                    target_p = ti.min(position_correction * depth / dt, max_correction_speed)
                    old_p = contacts.pseudo_impulse[c]
                    new_p = ti.max(old_p + mass_n * (target_p - vp), 0.0)
                    contacts.pseudo_impulse[c] = new_p
                    _apply_pseudo(bodies, a, arm_a, (new_p - old_p) * n)
                    _apply_pseudo(bodies, b, arm_b, -(new_p - old_p) * n)
        # Restitution: a contact that was approaching faster than the threshold and carries
        # impulse gets the target normal velocity -e x its approach speed. The sweeps run
        # over every contact, the others holding their non-penetration target, so a bounce
        # is not bought by pushing a struck body into the floor (a bounce-only pass pushed
        # a resting ring struck by a falling one up to a particle radius into the ground).
        bouncing = 0
        for c in range(count):
            target = -ti.max(contacts.separation[c], 0.0) / dt
            v0 = contacts.approach_speed[c]
            if contacts.restitution[c] > 0.0 and v0 < -restitution_threshold and contacts.normal_impulse[c] > 0.0:
                target = -contacts.restitution[c] * v0
                bouncing = 1
            contacts.restitution_target[c] = target
        if bouncing == 1:
            for sweep in range(restitution_iterations):
                for c in range(count):
                    a = contacts.body_a[c]
                    b = contacts.body_b[c]
                    n = contacts.normal[c]
                    arm_a = contacts.arm_a[c]
                    arm_b = contacts.arm_b[c]
                    vn = (_velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)).dot(n)
                    old = contacts.normal_impulse[c]
                    new = ti.max(old + contacts.normal_mass[c] * (contacts.restitution_target[c] - vn), 0.0)
                    contacts.normal_impulse[c] = new
                    _apply(bodies, a, arm_a, (new - old) * n)
                    _apply(bodies, b, arm_b, -(new - old) * n)
