"""Broadphase: which bodies may touch which this substep.

``body_cull`` gives every body its rotation matrix and motion bound for the substep, its
list of neighbouring bodies (grown bounding spheres overlap, at least one of the two awake)
with how far each pair can close, and whether it reaches a static collider. The narrowphase
then looks for sphere contacts only between neighbours, in each partner's body-frame grid
(``grid.py``).

The candidate pairs come from a hashed uniform grid over the bodies (Teschner et al. 2003,
"Optimized spatial hashing for collision detection of deformable objects"), rebuilt every
substep: each body's sphere grown by everything the pair test can add (its margin, its
motion, its spin's curvature, gravity) is entered in every cell of the box it covers, with
cells of twice the mean grown radius, and two bodies are tested where they share a cell,
once (in the first cell the two boxes share). A body whose box would cover more than
``MAX_BODY_CELLS`` cells (a glass wall among its shards) stays out of the grid and is
tested against every body. Testing every pair instead costs O(bodies^2) a substep, which
dominates with a thousand bodies. Each list is then sorted, so it is the same list, in the same
order, as testing every pair gives (tested), and the run is the same.
"""


from ..runtime import ti
from .. import runtime
from ..kinematics import linalg3 as la
from ..kinematics.bounds import is_idle, motion_speed, near_static, pair_motion
from ..kinematics.quaternion import quat_to_matrix


#: A body whose grown box covers more cells than this is tested against every body
#: instead of being entered in the grid.
MAX_BODY_CELLS = 64


@ti.data_oriented
class BodyGrid:
    """The broadphase's hashed grid over bodies, rebuilt every substep.

    Fields:
        bucket_count, bucket_cursor: (table_capacity,) i32; bucket_start:
            (table_capacity + 1,) i32: bucket h holds entries bucket_start[h] ..
            bucket_start[h + 1] (table_capacity: a power of two >= 2 x max bodies; the
            substep uses the smallest power of two >= 2 x the body slots in use).
        entry_body, entry_cell (ivec3): (entry_capacity,) the body and the cell of each
            entry (cells of several bodies may share a bucket).
        lower, upper: (max bodies,) ivec3 each body's box of cells this substep;
            grown: (max bodies,) [m] its grown radius.
        large: (max bodies,) i32 the bodies kept out of the grid (box over
            MAX_BODY_CELLS cells); large_count: scalar.
        cell_size [m], table_size, overflow (1: more entries than entry_capacity this
            substep, every pair is tested instead), grown_total [m] and active_count (the
            mean grown radius's sum and count): scalars.
    """

    def __init__(self, max_bodies: int):
        size = 1
        while size < 2 * max_bodies:
            size *= 2
        self.table_capacity = size
        self.entry_capacity = 16 * max_bodies
        self.bucket_count = ti.field(ti.i32, shape=size)
        self.bucket_cursor = ti.field(ti.i32, shape=size)
        self.bucket_start = ti.field(ti.i32, shape=size + 1)
        self.entry_body = ti.field(ti.i32, shape=self.entry_capacity)
        self.entry_cell = ti.math.ivec3.field(shape=self.entry_capacity)
        self.lower = ti.math.ivec3.field(shape=max_bodies)
        self.upper = ti.math.ivec3.field(shape=max_bodies)
        self.grown = ti.field(ti.f32, shape=max_bodies)
        self.large = ti.field(ti.i32, shape=max_bodies)
        self.large_count = ti.field(ti.i32, shape=())
        self.cell_size = ti.field(ti.f32, shape=())
        self.table_size = ti.field(ti.i32, shape=())
        self.overflow = ti.field(ti.i32, shape=())
        self.grown_total = ti.field(ti.f32, shape=())
        self.active_count = ti.field(ti.i32, shape=())


@ti.func
def _cell_hash(cell, table_size):
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
def _pair_grown_radius(bodies: ti.template(), statics: ti.template(), b, margin, dt):
    """Body b's bounding sphere grown by what the pair test adds on its side [m]: the
    contact margin, its motion over dt ((|v| + |w| R) dt), its spin's curvature
    (|w|^2 R dt^2 / 2) and gravity's |g| dt^2, so two bodies whose grown spheres do not
    meet fail the test (``bounds.pair_motion`` <= the sum of both sides' terms); a hair
    more, for the f32 cell bounds."""
    reach = (bodies.bounding_radius[b] + margin * bodies.max_particle_radius[b]
             + la.norm(statics.gravity[None]) * dt * dt)
    if not is_idle(bodies, b):
        w = la.norm(bodies.angular_velocity[b])
        radius = bodies.bounding_radius[b]
        reach += (la.norm(bodies.linear_velocity[b]) + w * radius) * dt + 0.5 * w * w * radius * dt * dt
    return reach * (1.0 + 1e-5) + 1e-7


@ti.func
def _test_neighbor(bodies: ti.template(), statics: ti.template(), b, o, xb, rb, count, margin, dt):
    """Append ``o`` to awake body b's neighbour list when their grown bounding spheres
    overlap; returns the new count (-1: the list overflowed)."""
    closing = pair_motion(bodies, statics, b, o, dt)
    reach = rb + bodies.bounding_radius[o] + margin * bodies.max_particle_radius[o] + closing
    if la.norm_sqr(bodies.position[o] - xb) < reach * reach:
        if count < bodies.max_neighbors:
            bodies.neighbors[b, count] = o
            bodies.neighbor_motion[b, count] = closing
            count += 1
        else:
            count = -1
    return count


@ti.func
def _body_grown(bodies: ti.template(), statics: ti.template(), grid: ti.template(), b, margin, dt):
    """Body b's grown radius, summed into the mean that sizes the cells."""
    if bodies.active[b] == 1:
        g = _pair_grown_radius(bodies, statics, b, margin, dt)
        grid.grown[b] = g
        ti.atomic_add(grid.grown_total[None], g)
        ti.atomic_add(grid.active_count[None], 1)


@ti.func
def _grid_setup(bodies: ti.template(), grid: ti.template()):
    """Cell size (twice the mean grown radius) and table size (the smallest power of two
    >= 2 x the body slots in use) of this substep."""
    size = 1
    while size < 2 * bodies.slot_end[None] and size < grid.table_capacity:
        size *= 2
    grid.table_size[None] = size
    grid.cell_size[None] = 2.0 * grid.grown_total[None] / ti.max(grid.active_count[None], 1)
    grid.large_count[None] = 0
    grid.overflow[None] = 0


@ti.func
def _body_box(bodies: ti.template(), grid: ti.template(), b):
    """Body b's box of cells; over MAX_BODY_CELLS cells it goes to the large list (an
    empty box), else it counts itself into its cells' buckets."""
    if bodies.active[b] == 1:
        cell = grid.cell_size[None]
        x = bodies.position[b]
        g = grid.grown[b]
        lower = ti.floor((x - g) / cell, ti.i32)
        upper = ti.floor((x + g) / cell, ti.i32)
        grid.lower[b] = lower
        grid.upper[b] = upper
        span = upper - lower + 1
        if span[0] * span[1] * span[2] > MAX_BODY_CELLS:
            grid.large[ti.atomic_add(grid.large_count[None], 1)] = b
            grid.upper[b] = lower - 1  # (an empty box: in no bucket)
        else:
            size = grid.table_size[None]
            for i, j, k in ti.ndrange((lower[0], upper[0] + 1), (lower[1], upper[1] + 1), (lower[2], upper[2] + 1)):
                ti.atomic_add(grid.bucket_count[_cell_hash(ti.math.ivec3(i, j, k), size)], 1)


@ti.func
def _grid_scan(grid: ti.template()):
    """Prefix sum of the bucket counts (zeroing them for the next substep); more entries
    than the capacity set ``overflow`` (every pair is then tested)."""
    size = grid.table_size[None]
    running = 0
    for h in range(size):
        count = grid.bucket_count[h]
        grid.bucket_start[h] = running
        grid.bucket_cursor[h] = running
        running += count
        grid.bucket_count[h] = 0
    grid.bucket_start[size] = running
    if running > grid.entry_capacity:
        grid.overflow[None] = 1


@ti.func
def _body_scatter(bodies: ti.template(), grid: ti.template(), b):
    """Body b's entries into the buckets of its cells (none after an overflow)."""
    if bodies.active[b] == 1 and grid.overflow[None] == 0:
        lower = grid.lower[b]
        upper = grid.upper[b]
        size = grid.table_size[None]
        for i, j, k in ti.ndrange((lower[0], upper[0] + 1), (lower[1], upper[1] + 1), (lower[2], upper[2] + 1)):
            cell = ti.math.ivec3(i, j, k)
            slot = ti.atomic_add(grid.bucket_cursor[_cell_hash(cell, size)], 1)
            grid.entry_body[slot] = b
            grid.entry_cell[slot] = cell


@ti.func
def _body_neighbors(bodies: ti.template(), statics: ti.template(), grid: ti.template(), b, margin, dt):
    """Body b's neighbour list: from the bodies sharing a cell with it (each pair in the
    first cell the two boxes share), every large body, and every body when b is large or
    the grid overflowed; then sorted by body slot (the order testing every pair gives).
    Only for an awake body: an idle one makes no contacts of its own, so nothing reads its
    list or flags (it is found in its awake neighbours' lists); in a settling pile most
    bodies sleep, and their lists were most of the broadphase's time."""
    count = 0
    near = 0
    if bodies.active[b] == 1 and not is_idle(bodies, b):
        xb = bodies.position[b]
        rb = bodies.bounding_radius[b] + margin * bodies.max_particle_radius[b]
        lower = grid.lower[b]
        upper = grid.upper[b]
        if grid.overflow[None] == 1 or (upper < lower).any():  # every body
            for o in range(bodies.slot_end[None]):
                if o != b and bodies.active[o] == 1 and count >= 0:
                    count = _test_neighbor(bodies, statics, b, o, xb, rb, count, margin, dt)
        else:
            size = grid.table_size[None]
            for i, j, k in ti.ndrange((lower[0], upper[0] + 1), (lower[1], upper[1] + 1), (lower[2], upper[2] + 1)):
                cell = ti.math.ivec3(i, j, k)
                h = _cell_hash(cell, size)
                for e in range(grid.bucket_start[h], grid.bucket_start[h + 1]):
                    o = grid.entry_body[e]
                    if o != b and count >= 0 and (grid.entry_cell[e] == cell).all() \
                            and (ti.max(lower, grid.lower[o]) == cell).all():
                        count = _test_neighbor(bodies, statics, b, o, xb, rb, count, margin, dt)
            for m in range(grid.large_count[None]):
                if count >= 0:
                    count = _test_neighbor(bodies, statics, b, grid.large[m], xb, rb, count, margin, dt)
            # Insertion sort by slot (a few dozen entries), with the closings alongside.
            for m in range(1, ti.max(count, 0)):
                o = bodies.neighbors[b, m]
                closing = bodies.neighbor_motion[b, m]
                n = m
                while n > 0 and bodies.neighbors[b, n - 1] > o:
                    bodies.neighbors[b, n] = bodies.neighbors[b, n - 1]
                    bodies.neighbor_motion[b, n] = bodies.neighbor_motion[b, n - 1]
                    n -= 1
                bodies.neighbors[b, n] = o
                bodies.neighbor_motion[b, n] = closing
        near = near_static(statics, xb, _grown_radius(bodies, b, margin))
    bodies.neighbor_count[b] = count
    bodies.near_body[b] = 1 if count != 0 else 0
    bodies.near_static[b] = near


@ti.func
def body_cull(bodies: ti.template(), statics: ti.template(), grid: ti.template(), margin, dt):
    """Passes over bodies: rotation matrix and motion bound of each body this substep;
    the body grid (grown radii, cells, prefix sum, scatter); each body's neighbour list
    (grown bounding spheres overlap, at least one of the two awake, grown by how far the
    pair can close this substep, ``bounds.pair_motion``; more than ``max_neighbors``
    neighbours set the count to -1 and the narrowphase then tries every body) and whether
    it reaches a static collider. Serial passes on the CPU (``runtime.SERIAL_SMALL_LOOPS``),
    parallel ones elsewhere (the order the entries land in differs from run to run there,
    but each list is sorted)."""
    body_cull_passes(bodies, statics, grid, margin, dt, runtime.SERIAL_SMALL_LOOPS)


@ti.func
def body_cull_passes(bodies: ti.template(), statics: ti.template(), grid: ti.template(), margin, dt,
                     serial: ti.template()):
    """``body_cull``'s passes, each a serial loop when ``serial`` (compile time), else a
    parallel one (atomics for the sums, counts, entries and large list); the prefix sum is
    serial either way."""
    grid.grown_total[None] = 0.0
    grid.active_count[None] = 0
    ti.loop_config(serialize=serial)
    for b in range(bodies.slot_end[None]):
        _body_motion(bodies, statics, b, dt)
        _body_grown(bodies, statics, grid, b, margin, dt)
    _grid_setup(bodies, grid)
    ti.loop_config(serialize=serial)
    for b in range(bodies.slot_end[None]):
        _body_box(bodies, grid, b)
    ti.loop_config(serialize=True)
    for _ in range(1):
        _grid_scan(grid)
    ti.loop_config(serialize=serial)
    for b in range(bodies.slot_end[None]):
        _body_scatter(bodies, grid, b)
    ti.loop_config(serialize=serial)
    for b in range(bodies.slot_end[None]):
        _body_neighbors(bodies, statics, grid, b, margin, dt)
