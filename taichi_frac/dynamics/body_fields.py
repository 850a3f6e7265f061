"""The kernels that write bodies into the World's fields and read them back, each over
K bodies (or impact rows) in one launch, in the row layouts of ``layouts.py``."""


from ..runtime import ti
from .. import runtime
from ..collision.grid import CELLS_PER_SPHERE
from ..kinematics import linalg3 as la
from .clusters import cluster_spheres
from .layouts import BODY_STATE as S
from .layouts import BODY_WRITE as W
from .layouts import BODY_WRITE_INTS as I
from .layouts import IMPACT


@ti.func
def _sphere_f32(spheres: ti.template(), k):
    """Row k of ``spheres`` (N,4) f64 as the f32 the fields hold (round to nearest, as
    numpy's astype)."""
    return ti.Vector([ti.cast(spheres[k, c], ti.f32) for c in ti.static(range(4))], dt=ti.f32)


@ti.func
def _vec3_at(row: ti.template(), b, start):
    return ti.math.vec3(row[b, start], row[b, start + 1], row[b, start + 2])


@ti.kernel
def write_bodies(bodies: ti.template(), particles: ti.template(),
                 ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                 row: ti.types.ndarray(dtype=ti.f32, ndim=2),
                 spheres: ti.types.ndarray(dtype=ti.f64, ndim=2),
                 grid_ints: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 nearest: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """Fill K body slots and their particle ranges in one launch: ``ints`` (K,
    BODY_WRITE_INTS.width), ``row`` (K, BODY_WRITE.width), ``spheres`` (N,4) every body's
    collision spheres, body after body (body-frame centre [m], radius [m]), ``grid_ints``
    each body's sphere-grid order (its spheres' count) then cell starts (cells + 1),
    body-relative, body after body; ``nearest`` (N,) scratch. Few array arguments: each
    costs ~11 us of Python a launch, and one launch serves all the pieces of a split."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for b in range(ints.shape[0]):
        slot = ints[b, I.slot]
        start = ints[b, I.particle_start]
        begin = ints[b, I.spheres]
        end = ints[b, I.spheres_end]
        bodies.position[slot] = _vec3_at(row, b, W.position)
        o = W.orientation
        bodies.orientation[slot] = ti.math.vec4(row[b, o], row[b, o + 1], row[b, o + 2], row[b, o + 3]).normalized()
        bodies.linear_velocity[slot] = _vec3_at(row, b, W.linear_velocity)
        bodies.angular_velocity[slot] = _vec3_at(row, b, W.angular_velocity)
        bodies.pseudo_linear_velocity[slot] = ti.math.vec3(0.0)
        bodies.pseudo_angular_velocity[slot] = ti.math.vec3(0.0)
        for r, c in ti.static(ti.ndrange(3, 3)):
            bodies.inertia_body[slot][r, c] = row[b, W.inertia + 3 * r + c]
            bodies.inverse_inertia_body[slot][r, c] = row[b, W.inverse_inertia + 3 * r + c]
        bodies.inverse_mass[slot] = row[b, W.inverse_mass]
        bodies.friction[slot] = row[b, W.friction]
        bodies.restitution[slot] = row[b, W.restitution]
        bodies.contact_compliance[slot] = row[b, W.contact_compliance]
        bodies.contact_radius[slot] = row[b, W.contact_radius]
        bodies.fixed[slot] = ints[b, I.fixed]
        bodies.sleeping[slot] = 0
        bodies.sleep_timer[slot] = 0.0
        bodies.sleep_anchor[slot] = bodies.position[slot]
        bodies.sleep_anchor_orientation[slot] = bodies.orientation[slot]
        bodies.wake_request[slot] = 0
        bodies.particle_start[slot] = start
        bodies.particle_count[slot] = end - begin
        bodies.active[slot] = 1
        bounding = 0.0
        largest = 0.0
        total = 0.0
        lower = ti.math.vec3(1e30)
        upper = ti.math.vec3(-1e30)
        for k in range(begin, end):
            sphere = _sphere_f32(spheres, k)
            offset = ti.math.vec3(sphere[0], sphere[1], sphere[2])
            r = sphere[3]
            bounding = ti.max(bounding, la.norm(offset) + r)
            largest = ti.max(largest, r)
            total += r
            lower = ti.min(lower, offset - r)
            upper = ti.max(upper, offset + r)
        bodies.bounding_radius[slot] = bounding
        bodies.max_particle_radius[slot] = largest
        bodies.mean_particle_radius[slot] = total / (end - begin)
        bodies.local_lower[slot] = lower
        bodies.local_upper[slot] = upper
        bodies.motion[slot] = 0.0
        bodies.grid_origin[slot] = _vec3_at(row, b, W.grid_origin)
        bodies.grid_edge[slot] = row[b, W.grid_edge]
        g = W.grid_dims
        bodies.grid_dims[slot] = ti.math.ivec3(ti.cast(row[b, g], ti.i32), ti.cast(row[b, g + 1], ti.i32),
                                               ti.cast(row[b, g + 2], ti.i32))
        cluster_spheres(bodies, slot, spheres, begin, end, ints[b, I.clusters], nearest)
        grid = ints[b, I.grid]
        count = end - begin
        for k in range(count):
            p = start + k
            particles.body[p] = slot
            particles.cache_stamp[0, p] = -1
            particles.cache_stamp[1, p] = -1
            particles.hull_stamp[0, p] = -1
            particles.hull_stamp[1, p] = -1
            particles.point_count[p] = 0  # (sphere contacts unless write_patches says otherwise)
            particles.overhang[p] = 0.0
            sphere = _sphere_f32(spheres, begin + k)
            particles.offset[p] = ti.math.vec3(sphere[0], sphere[1], sphere[2])
            particles.radius[p] = sphere[3]
            j = grid_ints[grid + k]
            particles.grid_sphere[p] = _sphere_f32(spheres, begin + j)
            particles.grid_slot[p] = start + j
        for c in range(ints[b, I.grid_end] - grid - count):
            particles.cell_first[ti.static(CELLS_PER_SPHERE) * start + c] = start + grid_ints[grid + count + c]


@ti.kernel
def write_patches(bodies: ti.template(), particles: ti.template(), ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                  normals: ti.types.ndarray(dtype=ti.f32, ndim=2), facets: ti.types.ndarray(dtype=ti.f32, ndim=2),
                  points: ti.types.ndarray(dtype=ti.f32, ndim=2)):
    """The contact patches of S spheres: ``ints`` (S,4) (particle slot, first row of
    ``surface_point`` for its patch, its point count, the first row of those points in
    ``points``), ``normals`` (S,3) and ``facets`` (S, 3 MAX_FACETS) body frame, ``points``
    (P,3) [m] body frame. Each sphere's ``overhang``, and its body's bounding radius and
    box grown to hold the patch."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for s in range(ints.shape[0]):
        p = ints[s, 0]
        start = ints[s, 1]
        particles.point_start[p] = start
        particles.point_count[p] = ints[s, 2]
        particles.patch_normal[p] = ti.math.vec3(normals[s, 0], normals[s, 1], normals[s, 2])
        for f in ti.static(range(particles.patch_facet.shape[1])):
            particles.patch_facet[p, f] = ti.math.vec3(facets[s, 3 * f], facets[s, 3 * f + 1], facets[s, 3 * f + 2])
        centre = particles.offset[p]
        radius = particles.radius[p]
        reach = radius
        for k in range(ints[s, 2]):
            row = ints[s, 3] + k
            x = ti.math.vec3(points[row, 0], points[row, 1], points[row, 2])
            particles.surface_point[start + k] = x
            reach = ti.max(reach, la.norm(x - centre))
        over = reach - radius
        particles.overhang[p] = over
        b = particles.body[p]
        ti.atomic_max(bodies.bounding_radius[b], la.norm(centre) + reach)
        for d in ti.static(range(3)):
            ti.atomic_min(bodies.local_lower[b][d], centre[d] - reach)
            ti.atomic_max(bodies.local_upper[b][d], centre[d] + reach)


@ti.kernel
def clear_body(bodies: ti.template(), particles: ti.template(), slot: ti.i32, start: ti.i32, count: ti.i32):
    bodies.active[slot] = 0
    bodies.near_body[slot] = 0
    bodies.near_static[slot] = 0
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(count):
        particles.body[start + k] = -1


@ti.kernel
def set_velocity(bodies: ti.template(), slot: ti.i32, v: ti.types.vector(3, ti.f32), w: ti.types.vector(3, ti.f32)):
    bodies.linear_velocity[slot] = v
    bodies.angular_velocity[slot] = w
    bodies.sleeping[slot] = 0
    bodies.sleep_timer[slot] = 0.0


@ti.kernel
def wake(bodies: ti.template(), slot: ti.i32):
    bodies.sleeping[slot] = 0
    bodies.sleep_timer[slot] = 0.0


@ti.kernel
def pack_impacts(impacts: ti.template(), first: ti.i32, rows: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Impact rows first..first+R-1 into ``rows`` (R, IMPACT.width)."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for r in range(rows.shape[0]):
        k = first + r
        rows[r, IMPACT.body] = impacts.body[k]
        rows[r, IMPACT.other] = impacts.other[k]
        for c in ti.static(range(3)):
            rows[r, IMPACT.point + c] = impacts.point[k][c]
            rows[r, IMPACT.normal + c] = impacts.normal[k][c]
            rows[r, IMPACT.impulse + c] = impacts.impulse[k][c]
            rows[r, IMPACT.force + c] = impacts.force[k][c]
            rows[r, IMPACT.point_body + c] = impacts.point_body[k][c]
            rows[r, IMPACT.normal_body + c] = impacts.normal_body[k][c]
            rows[r, IMPACT.force_body + c] = impacts.force_body[k][c]
        rows[r, IMPACT.duration] = impacts.duration[k]
        rows[r, IMPACT.speed] = impacts.speed[k]
        rows[r, IMPACT.dt] = impacts.dt[k]
        rows[r, IMPACT.substep] = impacts.substep[k]


@ti.kernel
def pack_bodies(motion: ti.template(), active: ti.template(), ids: ti.types.ndarray(dtype=ti.i32, ndim=1),
                rows: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Bodies ``ids`` (K,) of ``motion`` (a BodyMotion: the World's, or a checkpoint's)
    and ``active`` (their slots' flags) into ``rows`` (K, BODY_STATE.width)."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(ids.shape[0]):
        b = ids[k]
        for c in ti.static(range(3)):
            rows[k, S.position + c] = motion.position[b][c]
            rows[k, S.linear_velocity + c] = motion.linear_velocity[b][c]
            rows[k, S.angular_velocity + c] = motion.angular_velocity[b][c]
        for c in ti.static(range(4)):
            rows[k, S.orientation + c] = motion.orientation[b][c]
        rows[k, S.active] = active[b]
        rows[k, S.sleeping] = motion.sleeping[b]
