"""Uniform hashed grid over the collision particles, rebuilt every substep.

Three passes (one kernel each): ``particle_cells`` (world positions, cell, count per
bucket), ``bucket_scan`` (exclusive prefix sum; serial, because Taichi's PrefixSumExecutor
does not run on the CPU backend and a few thousand buckets scan in microseconds) and
``bucket_scatter``. Cells are hashed into a table (Teschner et al. 2003, "Optimized spatial
hashing for collision detection of deformable objects"), so the domain is unbounded; a
bucket may hold particles of several cells, so a query checks each candidate's true cell.

Cells are sized for the *typical* particle (``typical_particle_radius``: a body's median
radius), not the largest, so one outsized boundary sphere does not inflate every cell,
plus the farthest any neighbouring pair of bodies can close in the substep
(``bounds.pair_motion``, relative: two rings falling side by side close nothing, where the
sum of their own motion bounds doubled the cells' edge at every first impact). A particle
larger than the typical one occupies the box of cells its extra reach covers
(``cell`` .. ``cell_hi``); a query scans its own box grown by one cell, and a pair seen in
several cells is kept only in the cell of the partner's box nearest the query's centre
(the cell the centre lies in, clamped to the box), so every pair is made exactly once.
Only *active* particles enter the grid: those of a body with a neighbour (``body_cull``)
that lie inside that neighbour's grown body-frame box and one of its grown cluster spheres
(``particle_cells``; up to ``MAX_CLUSTERS`` spheres that each enclose a group of the body's
collision spheres, see ``World.add_body``), so two rings touching at one spot grid and
test only the particles around that spot. (The box alone holds a ring's hole: on the
13-ring pile's first impacts 1,990 of 5,733 particles were active with the box, ~1,000 with
16 cluster spheres.)
"""


import taichi as ti

from .. import runtime
from ..dynamics.bounds import is_idle, motion_speed, near_static, pair_motion
from ..dynamics.quaternion import quat_to_matrix


@ti.data_oriented
class HashGrid:
    """Bucket arrays, shape (table_capacity,) (a power of two >= 2 x particle capacity).

    Fields:
        bucket_count: i32 entries per bucket; zeroed again by bucket_scan.
        bucket_start: (table_capacity + 1,) i32: bucket h holds the entries
            bucket_start[h] .. bucket_start[h + 1] of ``sorted_particle`` (one array, so a
            query reads both ends from one cache line).
        bucket_cursor: i32 scatter cursor.
        sorted_particle: (entry_capacity,) i32 particle slots ordered by bucket (a large
            particle has one entry per cell it occupies); within a bucket in ascending slot
            order where the scatter is serial (the CPU: ``runtime.SERIAL_SMALL_LOOPS``),
            which the narrowphase uses to skip a body's own particles without reading
            them; sorted_body: its body, beside it
            (the narrowphase skips same-body candidates without a random read);
            sorted_offset: which cell of the particle's box the entry is for (its index in
            the box, x-major), since two cells of one large particle's box can hash to one
            bucket and the pair must be made in one cell only; entries beyond the capacity are
            counted in ``overflow`` (reported by the World), never silently dropped.
        table_size: scalar, the power of two in use this substep (<= capacity).
        cell_size: scalar [m], edge of a grid cell. typical_radius: scalar [m], largest
            typical particle radius among bodies with neighbours. max_motion: scalar [m],
            largest ``pair_motion`` over neighbouring bodies.
        overflow: scalar i32, entries lost this advance.
    """

    def __init__(self, particle_capacity: int):
        size = 1
        while size < 2 * particle_capacity:
            size *= 2
        self.table_capacity = size
        self.bucket_count = ti.field(ti.i32, shape=size)
        self.bucket_start = ti.field(ti.i32, shape=size + 1)
        self.bucket_cursor = ti.field(ti.i32, shape=size)
        self.entry_capacity = 2 * particle_capacity
        self.sorted_particle = ti.field(ti.i32, shape=self.entry_capacity)
        self.sorted_body = ti.field(ti.i32, shape=self.entry_capacity)
        self.sorted_offset = ti.field(ti.i32, shape=self.entry_capacity)
        self.table_size = ti.field(ti.i32, shape=())
        self.cell_size = ti.field(ti.f32, shape=())
        self.typical_radius = ti.field(ti.f32, shape=())
        self.max_motion = ti.field(ti.f32, shape=())
        self.overflow = ti.field(ti.i32, shape=())


@ti.func
def cell_hash(cell, table_size):
    h = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (cell[2] * 83492791)
    return h & (table_size - 1)


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
def _body_neighbors(bodies: ti.template(), statics: ti.template(), grid: ti.template(), b, margin, dt):
    count = 0
    near = 0
    idle_neighbor = 0
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
                            if is_idle(bodies, o):
                                idle_neighbor = 1
                            ti.atomic_max(grid.max_motion[None], closing)
                        else:
                            count = -1
                            idle_neighbor = 1
        if not b_idle:
            near = near_static(statics, xb, _grown_radius(bodies, b, margin))
        if count != 0:
            ti.atomic_max(grid.typical_radius[None], bodies.typical_particle_radius[b])
            if count < 0:  # neighbour list overflowed: every pair may be tested
                ti.atomic_max(grid.max_motion[None], 2.0 * bodies.motion[b])
    bodies.neighbor_count[b] = count
    bodies.idle_neighbor[b] = idle_neighbor
    bodies.near_body[b] = 1 if count != 0 else 0
    bodies.near_static[b] = near


@ti.func
def body_cull(bodies: ti.template(), statics: ti.template(), grid: ti.template(), margin, dt):
    """Two passes over bodies. First: rotation matrix and motion bound of each body this
    substep. Second: its neighbour list (grown bounding spheres overlap, at least one of
    the two awake, grown by how far the pair can close this substep; O(bodies^2), fine for
    the thousand-odd bodies a scene holds), whether it reaches a static collider, and the
    grid cell size (the reach of two typical particles among bodies that have a neighbour:
    2 r_typical (1 + margin / 2) + the largest pair closing).
    Serial on the CPU (see ``runtime.SERIAL_SMALL_LOOPS``), parallel elsewhere."""
    grid.typical_radius[None] = 1e-6
    grid.max_motion[None] = 0.0
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for b in range(bodies.slot_end[None]):
                _body_motion(bodies, statics, b, dt)
            for b in range(bodies.slot_end[None]):
                _body_neighbors(bodies, statics, grid, b, margin, dt)
    else:
        for b in range(bodies.slot_end[None]):
            _body_motion(bodies, statics, b, dt)
        for b in range(bodies.slot_end[None]):
            _body_neighbors(bodies, statics, grid, b, margin, dt)
    grid.cell_size[None] = 2.0 * grid.typical_radius[None] * (1.0 + 0.5 * margin) + grid.max_motion[None]


@ti.func
def cell_box(grid: ti.template(), x, radius, margin):
    """Cells (lower, upper corner) a particle at ``x`` [m] of ``radius`` [m] occupies: one
    cell, or more when it is larger than the typical radius the cells are sized for."""
    extra = ti.max(radius - grid.typical_radius[None], 0.0) * (1.0 + 0.5 * margin)
    lower = ti.floor((x - extra) / grid.cell_size[None], ti.i32)
    upper = ti.floor((x + extra) / grid.cell_size[None], ti.i32)
    return lower, upper


@ti.func
def _particle_cell(bodies: ti.template(), particles: ti.template(), grid: ti.template(), p, margin):
    b = particles.body[p]
    act = 0
    if b >= 0:
        if bodies.near_body[b] == 1 or bodies.near_static[b] == 1:
            x = bodies.position[b] + bodies.rotation[b] @ particles.offset[p]
            particles.world_position[p] = x
            count = bodies.neighbor_count[b]
            if count < 0:
                act = 1
            r = particles.radius[p]
            for k in range(ti.max(count, 0)):
                if act == 0:
                    o = bodies.neighbors[b, k]
                    grow = (r + bodies.max_particle_radius[o]) * (1.0 + 0.5 * margin) + bodies.neighbor_motion[b, k]
                    gap = x - bodies.position[o]
                    bound = bodies.bounding_radius[o] + grow
                    # (o's bounding sphere first: no rotation for the particles far from it)
                    if gap.norm_sqr() < bound * bound:
                        local = bodies.rotation[o].transpose() @ gap
                        q = ti.math.clamp(local, bodies.local_lower[o], bodies.local_upper[o])
                        if (local - q).norm_sqr() < grow * grow:
                            # Inside the box: now o's cluster spheres (each encloses its member
                            # spheres), which leave out the holes and hollows a box holds.
                            reach = r * (1.0 + 0.5 * margin) + 0.5 * margin * bodies.max_particle_radius[o] \
                                + bodies.neighbor_motion[b, k]
                            for m in range(bodies.cluster_count[o]):
                                if act == 0:
                                    sphere = bodies.cluster[o, m]
                                    limit = sphere[3] + reach
                                    centre = ti.math.vec3(sphere[0], sphere[1], sphere[2])
                                    if (local - centre).norm_sqr() < limit * limit:
                                        act = 1
            if act == 1:
                lower, upper = cell_box(grid, x, r, margin)
                particles.cell[p] = lower
                particles.cell_hi[p] = upper
                for i, j, k in ti.ndrange((lower[0], upper[0] + 1), (lower[1], upper[1] + 1), (lower[2], upper[2] + 1)):
                    ti.atomic_add(grid.bucket_count[cell_hash(ti.math.ivec3(i, j, k), grid.table_size[None])], 1)
    particles.active[p] = act


@ti.func
def particle_cells(bodies: ti.template(), particles: ti.template(), grid: ti.template(), margin):
    """Pass over particles: world position of every particle of a body near something; a
    particle of a body with neighbours is *active* when it lies within a neighbour's
    body-frame box grown by both spheres' reach and both motions (no contact is possible
    otherwise); active particles count themselves into the buckets of the cells they
    occupy. Serial on the CPU, where the pass is lighter than a parallel dispatch."""
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for p in range(particles.slot_end[None]):
                _particle_cell(bodies, particles, grid, p, margin)
    else:
        for p in range(particles.slot_end[None]):
            _particle_cell(bodies, particles, grid, p, margin)


@ti.func
def bucket_scan(grid: ti.template()):
    """Serial exclusive prefix sum of bucket counts into start/cursor (start[size] = the
    total); zeroes counts for the next substep."""
    ti.loop_config(serialize=True)
    for _ in range(1):  # one serial task
        running = 0
        size = grid.table_size[None]
        for h in range(size):
            count = grid.bucket_count[h]
            grid.bucket_start[h] = running
            grid.bucket_cursor[h] = running
            running += count
            grid.bucket_count[h] = 0
        grid.bucket_start[size] = running


@ti.func
def _scatter_one(particles: ti.template(), grid: ti.template(), p):
    if particles.active[p] == 1:
        lower = particles.cell[p]
        upper = particles.cell_hi[p]
        span = upper - lower + 1
        for i, j, k in ti.ndrange((lower[0], upper[0] + 1), (lower[1], upper[1] + 1), (lower[2], upper[2] + 1)):
            h = cell_hash(ti.math.ivec3(i, j, k), grid.table_size[None])
            slot = ti.atomic_add(grid.bucket_cursor[h], 1)
            if slot < grid.entry_capacity:
                grid.sorted_particle[slot] = p
                grid.sorted_body[slot] = particles.body[p]
                grid.sorted_offset[slot] = ((i - lower[0]) * span[1] + (j - lower[1])) * span[2] + (k - lower[2])
            else:
                ti.atomic_add(grid.overflow[None], 1)


@ti.func
def bucket_scatter(particles: ti.template(), grid: ti.template()):
    """Pass over particles: write each active particle's slot into the range of every
    bucket it counted itself in. Serial on the CPU."""
    if ti.static(runtime.SERIAL_SMALL_LOOPS):
        ti.loop_config(serialize=True)
        for _ in range(1):
            for p in range(particles.slot_end[None]):
                _scatter_one(particles, grid, p)
    else:
        for p in range(particles.slot_end[None]):
            _scatter_one(particles, grid, p)
