"""Contact reduction: a body resting on the ground through its true surface touches it at
every patch along its contact area (a ring's flat bottom, a cube's face: tens of contacts;
a small piece at up to four points a patch), where its boundary spheres touched at a few;
two bodies resting on each other touch at every pair of patches that meet (two rings
crossing: forty and more). The serial solver pays for each in every sweep, and a rigid
body needs no more than its contact area's outline to stand on.

So a body's patch contacts with one static collider, or with one other body, are reduced
to representatives, the way a physics engine reduces a face-face manifold (Bullet's
``btPersistentManifold::sortCachedPoints``, PhysX's patch reduction): the deepest contact,
and the contact farthest out along each of ``DIRECTIONS`` directions across the deepest
contact's normal among the contacts that touch (gap within ``TOUCHING_BAND`` of their
sphere's radius of the deepest gap), and among those near (within the contact margin, as
the narrowphase makes a resting body's contacts). Against a plane a body's gap is an
affine function of the point (for the small rotation of one substep), so the
representatives holding their gaps hold every point inside their outline; between two
curved bodies it is so only across a contact area small against their curvature, which
the touching band keeps to. Contacts farther away (speculative contacts of a tilting
body's far side, made because they approach) are kept as they are: they stop the parts
that will touch next. A landing body (a contact approaching faster than the restitution
threshold, relative to the other body's point there) keeps all its contacts with that
collider or body: they share the impact's impulse, and where it acts decides how the body
turns. A ring resting flat on another keeps 16 of its 228 contacts with it.

The choice depends on the contacts' geometry and their (particle, key) order alone, not
on the order the parallel narrowphase appended them, so runs stay reproducible; a body
resting still keeps the same representatives from substep to substep, so their impulses
warm-start. A pair of bodies' contacts all lie in one body's run of the order: the
narrowphase makes a pair's contacts from one side only.
"""

import math


from ..runtime import ti
from ..kinematics import linalg3 as la
from ..kinematics.frames import tangent_basis


#: Directions across the contact normal along which the outermost contact is kept: eight
#: (every 45 degrees) outline a ring's circle of contacts within 8 % of its radius.
DIRECTIONS = 8

#: Contacts whose gap lies within this fraction of their sphere's radius of the deepest gap
#: touch (``_layer``). A dropped contact lies inside the outline kept, which holds it only
#: to within the spread of the layer's gaps, so a wide band lets a curved chip lose the
#: contacts it stands on and rock.
TOUCHING_BAND = 0.02

#: ``contacts.reduce_mark`` values.
UNSEEN, KEEP, DROP = 0, 1, 2


@ti.func
def _reducible(particles: ti.template(), contacts: ti.template(), c):
    """Whether contact ``c`` is a patch contact: with a static collider, or between two
    bodies' patches (its key is the other body's sphere)."""
    reducible = particles.point_count[contacts.query[c]] > 0
    if contacts.body_b[c] >= 0:
        reducible = reducible and particles.point_count[contacts.key[c]] > 0
    return reducible


@ti.func
def _same_collider(contacts: ti.template(), c, d):
    """Whether contacts ``c`` and ``d`` are with the same static collider or body."""
    return contacts.body_b[c] == contacts.body_b[d] and contacts.static_index[c] == contacts.static_index[d]


@ti.func
def _layer(contacts: ti.template(), c, low, margin):
    """Which layer of the contact area contact ``c`` lies in, by its gap above the deepest
    gap ``low`` [m] in its sphere's radii: 0 within ``TOUCHING_BAND`` (touching),
    1 within ``margin`` (near), 2 beyond (made because it approaches: never reduced)."""
    rise = contacts.separation[c] - low
    r = contacts.radius[c]
    return ti.select(rise <= ti.static(TOUCHING_BAND) * r, 0, ti.select(rise <= margin * r, 1, 2))


@ti.func
def _reduce_group(bodies: ti.template(), particles: ti.template(), contacts: ti.template(), end, first, margin,
                  bounce_speed):
    """Mark the contacts of ``order[first:end]`` (one body's, sorted by particle) with the
    static collider or body of contact ``order[first]``: KEEP the deepest, the outermost in
    each direction of each layer (``_layer``: touching, near) and those beyond the margin,
    DROP the rest; KEEP all while the body lands (a contact approaches faster than
    ``bounce_speed`` [m/s], the restitution threshold, relative to the other body). A
    layer's outline is its own: the touching contacts' outline holds the body up, the near
    ones' (a ring's next row of vertices, further out and a few millimetres up) would not."""
    lead = contacts.order[first]
    a = contacts.body_a[lead]
    # Deepest (the first in order on a tie).
    deepest = lead
    landing = False
    for k in range(first, end):
        c = contacts.order[k]
        if _reducible(particles, contacts, c) and _same_collider(contacts, c, lead):
            if contacts.separation[c] < contacts.separation[deepest]:
                deepest = c
            p = contacts.point[c]
            v = bodies.linear_velocity[a] + la.cross(bodies.angular_velocity[a], p - bodies.position[a])
            o = contacts.body_b[c]
            if o >= 0:
                v -= bodies.linear_velocity[o] + la.cross(bodies.angular_velocity[o], p - bodies.position[o])
            if -la.dot(v, contacts.normal[c]) > bounce_speed:
                landing = True
    low = contacts.separation[deepest]
    n = contacts.normal[deepest]
    t1, t2 = tangent_basis(n)
    best = ti.Matrix([[deepest] * DIRECTIONS] * 2, dt=ti.i32)
    score = ti.Matrix([[-1e30] * DIRECTIONS] * 2, dt=ti.f32)
    for k in range(first, end):
        c = contacts.order[k]
        if _reducible(particles, contacts, c) and _same_collider(contacts, c, lead):
            layer = _layer(contacts, c, low, margin)
            if layer < 2:
                p = contacts.point[c]
                u = la.dot(p, t1)
                v = la.dot(p, t2)
                for m in ti.static(range(DIRECTIONS)):
                    s = u * ti.static(math.cos(2.0 * math.pi * m / DIRECTIONS)) \
                        + v * ti.static(math.sin(2.0 * math.pi * m / DIRECTIONS))
                    if s > score[layer, m]:
                        score[layer, m] = s
                        best[layer, m] = c
    for k in range(first, end):
        c = contacts.order[k]
        if _reducible(particles, contacts, c) and _same_collider(contacts, c, lead):
            keep = landing or c == deepest or _layer(contacts, c, low, margin) == 2
            for layer, m in ti.static(ti.ndrange(2, DIRECTIONS)):
                keep = keep or c == best[layer, m]
            contacts.reduce_mark[c] = KEEP if keep else DROP


@ti.func
def reduce_contacts(bodies: ti.template(), particles: ti.template(), contacts: ti.template(), margin, bounce_speed):
    """Serial: reduce each body's patch contacts with each static collider and each other
    body (module docstring) and compact the kept contacts to the front of the buffer, in
    their slot order. Reads ``contacts.order`` (sorted by particle, so one body's contacts
    are consecutive in it) and leaves it so for the kept contacts. Skipped when the
    buffer overflowed (the overflow is reported; its contacts are not all here).
    ``margin``: the contact margin (fraction of a sphere's radius); ``bounce_speed``
    [m/s]: the restitution threshold (a landing keeps all its contacts)."""
    ti.loop_config(serialize=True)
    for _ in range(1):
        n = contacts.count[None]
        if n <= contacts.capacity:
            for c in range(n):
                contacts.reduce_mark[c] = UNSEEN
            start = 0
            dropped = 0
            while start < n:
                a = contacts.body_a[contacts.order[start]]
                end = start + 1
                while end < n and contacts.body_a[contacts.order[end]] == a:
                    end += 1
                for k in range(start, end):
                    c = contacts.order[k]
                    if contacts.reduce_mark[c] == UNSEEN and _reducible(particles, contacts, c):
                        _reduce_group(bodies, particles, contacts, end, k, margin, bounce_speed)
                start = end
            for c in range(n):
                dropped += ti.cast(contacts.reduce_mark[c] == DROP, ti.i32)
            if dropped > 0:
                # Compact, each kept contact's new slot left in its old slot's mark (-1:
                # dropped); then ``order`` with the dropped left out and the slots renamed,
                # which is the order sorting the kept contacts again gives (the compaction
                # keeps the slots' order).
                kept = 0
                for c in range(n):
                    if contacts.reduce_mark[c] != DROP:
                        if kept != c:
                            for field in ti.static(contacts.written_by_narrowphase):
                                field[kept] = field[c]
                        contacts.reduce_mark[c] = kept
                        kept += 1
                    else:
                        contacts.reduce_mark[c] = -1
                contacts.count[None] = kept
                m = 0
                for k in range(n):
                    slot = contacts.reduce_mark[contacts.order[k]]
                    if slot >= 0:
                        contacts.order[m] = slot
                        m += 1
