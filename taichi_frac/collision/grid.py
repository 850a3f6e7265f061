"""Uniform hashed grid over the collision particles, rebuilt every substep.

Three passes (one kernel each): ``particle_cells`` (world positions, cell, count per
bucket), ``bucket_scan`` (exclusive prefix sum; serial, because Taichi's PrefixSumExecutor
does not run on the CPU backend and a few thousand buckets scan in microseconds) and
``bucket_scatter``. Cells are hashed into a table (Teschner et al. 2003, "Optimized spatial
hashing for collision detection of deformable objects"), so the domain is unbounded; a
bucket may hold particles of several cells, so a query checks each candidate's true cell.
Only particles of bodies flagged ``near_body`` by ``body_cull`` enter the grid.
"""


import taichi as ti

from ..dynamics.quaternion import quat_to_matrix


@ti.data_oriented
class HashGrid:
    """Bucket arrays, shape (table_capacity,) (a power of two >= 2 x particle capacity).

    Fields:
        bucket_count: i32 particles per bucket; zeroed again by bucket_scan.
        bucket_start, bucket_end: i32 range of each bucket in ``sorted_particle``.
        bucket_cursor: i32 scatter cursor.
        sorted_particle: (particle capacity,) i32 particle slots ordered by bucket.
        table_size: scalar, the power of two in use this substep (<= capacity).
        cell_size: scalar [m], edge of a grid cell.
    """

    def __init__(self, particle_capacity: int):
        size = 1
        while size < 2 * particle_capacity:
            size *= 2
        self.table_capacity = size
        self.bucket_count = ti.field(ti.i32, shape=size)
        self.bucket_start = ti.field(ti.i32, shape=size)
        self.bucket_end = ti.field(ti.i32, shape=size)
        self.bucket_cursor = ti.field(ti.i32, shape=size)
        self.sorted_particle = ti.field(ti.i32, shape=particle_capacity)
        self.table_size = ti.field(ti.i32, shape=())
        self.cell_size = ti.field(ti.f32, shape=())


@ti.func
def cell_hash(cell, table_size):
    h = (cell[0] * 73856093) ^ (cell[1] * 19349663) ^ (cell[2] * 83492791)
    return h & (table_size - 1)


@ti.func
def body_cull(bodies: ti.template(), statics: ti.template(), margin):
    """Pass over bodies: flag the ones whose bounding sphere (grown by ``margin`` x its
    smallest particle radius) reaches another body (at least one of the two awake) or a
    static collider. O(bodies^2), fine for the thousand-odd bodies a scene holds."""
    for b in range(bodies.slot_end[None]):
        near_body = 0
        near_static = 0
        if bodies.active[b] == 1:
            xb = bodies.position[b]
            rb = bodies.bounding_radius[b] * (1.0 + margin)
            b_idle = bodies.sleeping[b] == 1 or bodies.fixed[b] == 1
            for o in range(bodies.slot_end[None]):
                if o != b and bodies.active[o] == 1 and near_body == 0:
                    o_idle = bodies.sleeping[o] == 1 or bodies.fixed[o] == 1
                    if not (b_idle and o_idle):
                        ro = bodies.bounding_radius[o] * (1.0 + margin)
                        if (bodies.position[o] - xb).norm_sqr() < (rb + ro) ** 2:
                            near_body = 1
            if not b_idle:
                for k in range(statics.plane_count[None]):
                    if xb[2] - rb < statics.plane_height[k]:
                        near_static = 1
                for k in range(statics.box_count[None]):
                    local = statics.box_rotation[k].transpose() @ (xb - statics.box_center[k])
                    q = ti.math.clamp(local, -statics.box_half_extents[k], statics.box_half_extents[k])
                    if (local - q).norm_sqr() < rb * rb:
                        near_static = 1
        bodies.near_body[b] = near_body
        bodies.near_static[b] = near_static


@ti.func
def particle_cells(bodies: ti.template(), particles: ti.template(), grid: ti.template()):
    """Pass over particles: world position of every particle of a flagged body; for bodies
    near another body also its cell and a count in the cell's bucket."""
    for p in range(particles.slot_end[None]):
        b = particles.body[p]
        if b >= 0:
            if bodies.near_body[b] == 1 or bodies.near_static[b] == 1:
                rot = quat_to_matrix(bodies.orientation[b])
                x = bodies.position[b] + rot @ particles.offset[p]
                particles.world_position[p] = x
                if bodies.near_body[b] == 1:
                    cell = ti.floor(x / grid.cell_size[None], ti.i32)
                    particles.cell[p] = cell
                    ti.atomic_add(grid.bucket_count[cell_hash(cell, grid.table_size[None])], 1)


@ti.func
def bucket_scan(grid: ti.template()):
    """Serial exclusive prefix sum of bucket counts into start/end/cursor; zeroes counts
    for the next substep."""
    for _ in range(1):  # one task; the inner loop is serial
        running = 0
        for h in range(grid.table_size[None]):
            count = grid.bucket_count[h]
            grid.bucket_start[h] = running
            grid.bucket_cursor[h] = running
            running += count
            grid.bucket_end[h] = running
            grid.bucket_count[h] = 0


@ti.func
def bucket_scatter(bodies: ti.template(), particles: ti.template(), grid: ti.template()):
    """Pass over particles: write each gridded particle's slot into its bucket's range."""
    for p in range(particles.slot_end[None]):
        b = particles.body[p]
        if b >= 0:
            if bodies.near_body[b] == 1:
                h = cell_hash(particles.cell[p], grid.table_size[None])
                grid.sorted_particle[ti.atomic_add(grid.bucket_cursor[h], 1)] = p
