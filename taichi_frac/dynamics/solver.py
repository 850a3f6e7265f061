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


from ..runtime import ti
from ..collision.narrowphase import GROUND
from ..kinematics import linalg3 as la
from ..kinematics.frames import tangent_basis

vec3 = ti.math.vec3
mat3 = ti.math.mat3

# Sphere pairs overlapping deeper than this fraction of the smaller radius get no velocity
# constraint (no normal impulse, so no friction), only the split impulse's push-out. The
# centre-to-centre normal of so deep an overlap says little about the surfaces, and the
# pieces of a fracture are born so: the collision spheres on both sides of a crack face
# overlap by up to two radii (an impact's penetration stays below ~0.3 of a radius).
# Measured on the 13 rings with fracture (40 frames, worst depth below the floor in
# physics-particle radii, three runs): 0.23-0.35 with, 0.43-0.64 without.
DEEP_OVERLAP = 0.5


@ti.func
def _held_speed(contacts: ti.template(), c, dt):
    """Normal relative speed [m/s] contact ``c`` holds the bodies to: a speculative
    contact may close its gap this substep, no more (-gap / dt); a penetrating one may not
    close further (0); a deep overlap (DEEP_OVERLAP) holds nothing (-1e30: it may close
    freely, only the split impulse pushes it out)."""
    gap = contacts.separation[c]
    return ti.select(gap > -DEEP_OVERLAP * contacts.radius[c], -ti.max(gap, 0.0) / dt, -1e30)


@ti.func
def _velocity_at(bodies: ti.template(), b, arm):
    v = vec3(0.0)
    if b >= 0:
        v = bodies.linear_velocity[b] + la.cross(bodies.angular_velocity[b], arm)
    return v


@ti.func
def _pseudo_velocity_at(bodies: ti.template(), b, arm):
    v = vec3(0.0)
    if b >= 0:
        v = bodies.pseudo_linear_velocity[b] + la.cross(bodies.pseudo_angular_velocity[b], arm)
    return v


@ti.func
def _apply(bodies: ti.template(), b, arm, impulse):
    if b >= 0:
        bodies.linear_velocity[b] += bodies.solver_inverse_mass[b] * impulse
        bodies.angular_velocity[b] += la.mat_vec(bodies.solver_inverse_inertia[b], la.cross(arm, impulse))


@ti.func
def _body_response(bodies: ti.template(), b, arm, n, t1, t2):
    """Body ``b``'s angular velocity change per unit impulse along n, t1 and t2 at ``arm``
    [rad/s per N s], and its inverse effective mass along each (vec3: 1/m + (r x d) .
    I^-1 (r x d)) [1/kg]; zeros for a static collider. Each I^-1 (r x d) is formed once
    and serves both (formed twice, the mat-vecs doubled Taichi's front-end work on the
    respond kernel, paid in every new process)."""
    rn = vec3(0.0)
    r1 = vec3(0.0)
    r2 = vec3(0.0)
    k = vec3(0.0)
    if b >= 0:
        inverse_inertia = bodies.solver_inverse_inertia[b]
        cn = la.cross(arm, n)
        c1 = la.cross(arm, t1)
        c2 = la.cross(arm, t2)
        rn = la.mat_vec(inverse_inertia, cn)
        r1 = la.mat_vec(inverse_inertia, c1)
        r2 = la.mat_vec(inverse_inertia, c2)
        m = bodies.solver_inverse_mass[b]
        k = vec3(m + la.dot(cn, rn), m + la.dot(c1, r1), m + la.dot(c2, r2))
    return rn, r1, r2, k


@ti.func
def _push(bodies: ti.template(), b, linear, angular):
    """Add a precomputed velocity change to body ``b`` (nothing for a static collider)."""
    if b >= 0:
        bodies.linear_velocity[b] += bodies.solver_inverse_mass[b] * linear
        bodies.angular_velocity[b] += angular


@ti.func
def _push_pseudo(bodies: ti.template(), b, linear, angular):
    if b >= 0:
        bodies.pseudo_linear_velocity[b] += bodies.solver_inverse_mass[b] * linear
        bodies.pseudo_angular_velocity[b] += angular


@ti.func
def prepare_contacts(bodies: ti.template(), contacts: ti.template(), warm_start):
    """Two serial passes over contacts: arms, normal effective mass, approach speed, body
    flags (no two contacts write one flag at once); then the warm start: each contact's
    impulses from the last substep (projected on its friction cone) applied to the bodies
    (Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        for k in range(ti.min(contacts.count[None], contacts.capacity)):
            _prepare_contact(bodies, contacts, contacts.order[k])
        for k in range(ti.min(contacts.count[None], contacts.capacity)):
            _warm_start(bodies, contacts, contacts.order[k], warm_start)


@ti.func
def _warm_start(bodies: ti.template(), contacts: ti.template(), c, warm_start):
    a = contacts.body_a[c]
    b = contacts.body_b[c]
    n = contacts.normal[c]
    jn = ti.max(contacts.normal_impulse[c], 0.0) * warm_start
    jt = contacts.tangent_impulse[c] * warm_start
    jt -= la.dot(jt, n) * n
    limit = contacts.friction[c] * jn
    if la.norm(jt) > limit:
        jt *= limit / la.norm(jt)
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
        for m in range(ti.min(contacts.count[None], contacts.capacity)):
            c = contacts.order[m]
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
    # Friction directions t1, t2 (any orthonormal pair across n) and every direction's
    # angular response, so a sweep needs no inertia matrix (Catto 2005; Box2D, Bullet).
    t1, t2 = tangent_basis(n)
    contacts.tangent1[c] = t1
    contacts.tangent2[c] = t2
    ra_n, ra_1, ra_2, ka = _body_response(bodies, a, arm_a, n, t1, t2)
    rb_n, rb_1, rb_2, kb = _body_response(bodies, b, arm_b, n, t1, t2)
    contacts.response_a[c, 0] = ra_n
    contacts.response_a[c, 1] = ra_1
    contacts.response_a[c, 2] = ra_2
    contacts.response_b[c, 0] = rb_n
    contacts.response_b[c, 1] = rb_1
    contacts.response_b[c, 2] = rb_2
    k = ka + kb  # inverse effective masses along n, t1, t2
    contacts.normal_mass[c] = 1.0 / k[0] if k[0] > 0.0 else 0.0
    contacts.tangent_mass[c] = ti.math.vec2(1.0 / k[1] if k[1] > 0.0 else 0.0, 1.0 / k[2] if k[2] > 0.0 else 0.0)
    contacts.approach_speed[c] = la.dot(_velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b), n)
    contacts.pseudo_impulse[c] = 0.0
    contacts.rolling_impulse[c] = vec3(0.0)


@ti.func
def _inverse_inertia_times(bodies: ti.template(), b, u):
    r = vec3(0.0)
    if b >= 0:
        r = la.mat_vec(bodies.solver_inverse_inertia[b], u)
    return r


@ti.func
def _roll(bodies: ti.template(), contacts: ti.template(), c, a, b, limit):
    """Rolling resistance: an angular impulse against the two bodies' relative angular
    velocity, its accumulated size held to ``limit`` [N m s] (a vec3 kept like the
    friction impulse; Box2D v3's rolling resistance, in 3D)."""
    w_rel = bodies.angular_velocity[a]
    if b >= 0:
        w_rel -= bodies.angular_velocity[b]
    speed = la.norm(w_rel)
    if speed > 0.0:
        u = w_rel / speed
        ia = _inverse_inertia_times(bodies, a, u)
        ib = _inverse_inertia_times(bodies, b, u)
        k = la.dot(u, ia) + la.dot(u, ib)  # relative angular speed change per unit angular impulse
        old_r = contacts.rolling_impulse[c]
        new_r = old_r - (speed / k) * u
        size = la.norm(new_r)
        if size > limit:
            new_r *= limit / size
        contacts.rolling_impulse[c] = new_r
        d = new_r - old_r
        bodies.angular_velocity[a] += _inverse_inertia_times(bodies, a, d)
        if b >= 0:
            bodies.angular_velocity[b] -= _inverse_inertia_times(bodies, b, d)


@ti.func
def _solve_contact(bodies: ti.template(), contacts: ti.template(), c, dt, position_correction,
                   allowed_penetration, max_correction_speed, rolling_resistance):
    """One Gauss-Seidel update of contact ``c``: normal, friction, rolling resistance,
    split impulse."""
    a = contacts.body_a[c]
    b = contacts.body_b[c]
    n = contacts.normal[c]
    arm_a = contacts.arm_a[c]
    arm_b = contacts.arm_b[c]
    mass_n = contacts.normal_mass[c]
    gap = contacts.separation[c]
    # Normal: a speculative contact may close its gap this substep, no more.
    v_rel = _velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)
    target = _held_speed(contacts, c, dt)
    old = contacts.normal_impulse[c]
    new = ti.max(old + mass_n * (target - la.dot(v_rel, n)), 0.0)
    contacts.normal_impulse[c] = new
    dj = new - old
    if dj != 0.0:  # (most contacts are speculative ones that stay at zero: 70-85 % in the 13 rings' pile)
        _push(bodies, a, dj * n, dj * contacts.response_a[c, 0])
        _push(bodies, b, -dj * n, -dj * contacts.response_b[c, 0])
    # Friction: Coulomb cone |jt| <= mu jn, along t1 and t2, clamped jointly.
    # Skipped while the contact carries no impulse at all (most speculative
    # contacts: their cone is a point and they hold no friction to undo).
    old_t = contacts.tangent_impulse[c]
    if new > 0.0 or la.norm_sqr(old_t) > 0.0:
        v_rel = _velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b)
        t1 = contacts.tangent1[c]
        t2 = contacts.tangent2[c]
        m_t = contacts.tangent_mass[c]
        l1 = la.dot(old_t, t1) - m_t[0] * la.dot(v_rel, t1)
        l2 = la.dot(old_t, t2) - m_t[1] * la.dot(v_rel, t2)
        limit = contacts.friction[c] * new
        mag = ti.sqrt(l1 * l1 + l2 * l2)
        if mag > limit:
            l1 *= limit / mag
            l2 *= limit / mag
        new_t = l1 * t1 + l2 * t2
        contacts.tangent_impulse[c] = new_t
        d1 = l1 - la.dot(old_t, t1)
        d2 = l2 - la.dot(old_t, t2)
        _push(bodies, a, new_t - old_t, d1 * contacts.response_a[c, 1] + d2 * contacts.response_a[c, 2])
        _push(bodies, b, old_t - new_t, -d1 * contacts.response_b[c, 1] - d2 * contacts.response_b[c, 2])
    if rolling_resistance > 0.0 and new > 0.0:
        _roll(bodies, contacts, c, a, b, rolling_resistance * contacts.radius[c] * new)
    # Split impulse: push-out speed proportional to the penetration beyond slop. Against a
    # ground plane it also holds the pseudo-velocity to the gap (no deeper than now), so
    # other bodies' push-outs may not drive a body into the floor: a chip born inside a
    # heavy sibling's spheres, pushed out of them at max_correction_speed, went from
    # touching the floor to well into it in one substep. Not against static boxes: blocks
    # dropped into a box of four walls settle less well with the walls holding too.
    depth = -gap - allowed_penetration * contacts.radius[c]
    if depth > 0.0 or b == GROUND:
        vp = la.dot(_pseudo_velocity_at(bodies, a, arm_a) - _pseudo_velocity_at(bodies, b, arm_b), n)
        target_p = ti.select(depth > 0.0, ti.min(position_correction * depth / dt, max_correction_speed),
                             -ti.max(gap, 0.0) / dt)
        old_p = contacts.pseudo_impulse[c]
        new_p = ti.max(old_p + mass_n * (target_p - vp), 0.0)
        contacts.pseudo_impulse[c] = new_p
        dp = new_p - old_p
        if dp != 0.0:
            _push_pseudo(bodies, a, dp * n, dp * contacts.response_a[c, 0])
            _push_pseudo(bodies, b, -dp * n, -dp * contacts.response_b[c, 0])


@ti.func
def solve_contacts(bodies: ti.template(), contacts: ti.template(), iterations,
                   restitution_iterations, dt, position_correction,
                   allowed_penetration, max_correction_speed,
                   restitution_threshold, rolling_resistance):
    """Serial Gauss-Seidel sweeps over the contacts (one task, see the module docstring)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        count = ti.min(contacts.count[None], contacts.capacity)
        # Contacts between bodies first, then those with static colliders, which so have
        # the last word in every sweep: a small piece pressed into the floor by a heavy one
        # (mass ratio ~500 in the 13-ring pile) is held by the floor rather than by the
        # converging pair, and sinks less. The sweep order is built once per substep, so a
        # sweep scans the contacts once.
        filled = 0
        for k in range(2 * count):
            c = contacts.order[k % count]
            if (contacts.body_b[c] < 0) == (k >= count):
                contacts.sweep_order[filled] = c
                filled += 1
        for sweep in range(iterations):
            # (One loop over both kinds: two inlined copies of the update doubled the
            # respond kernel's compile time, which every new process pays.)
            for k in range(count):
                _solve_contact(bodies, contacts, contacts.sweep_order[k], dt, position_correction,
                               allowed_penetration, max_correction_speed, rolling_resistance)
        # Restitution: a contact that was approaching faster than the threshold and carries
        # impulse gets the target normal velocity -e x its approach speed. The sweeps run
        # over every contact, the others holding their non-penetration target, so a bounce
        # is not bought by pushing a struck body into the floor (a bounce-only pass pushed
        # a resting ring struck by a falling one up to a particle radius into the ground).
        bouncing = 0
        for m in range(count):
            c = contacts.order[m]
            target = _held_speed(contacts, c, dt)
            v0 = contacts.approach_speed[c]
            if contacts.restitution[c] > 0.0 and v0 < -restitution_threshold and contacts.normal_impulse[c] > 0.0:
                target = -contacts.restitution[c] * v0
                bouncing = 1
            contacts.restitution_target[c] = target
        if bouncing == 1:
            for sweep in range(restitution_iterations):
                for m in range(count):
                    c = contacts.order[m]
                    a = contacts.body_a[c]
                    b = contacts.body_b[c]
                    n = contacts.normal[c]
                    arm_a = contacts.arm_a[c]
                    arm_b = contacts.arm_b[c]
                    vn = la.dot(_velocity_at(bodies, a, arm_a) - _velocity_at(bodies, b, arm_b), n)
                    old = contacts.normal_impulse[c]
                    new = ti.max(old + contacts.normal_mass[c] * (contacts.restitution_target[c] - vn), 0.0)
                    contacts.normal_impulse[c] = new
                    dj = new - old
                    _push(bodies, a, dj * n, dj * contacts.response_a[c, 0])
                    _push(bodies, b, -dj * n, -dj * contacts.response_b[c, 0])
