"""The rigid-body world: fixed-capacity Taichi fields, bodies added and removed at run time
(fragments) by writing into them, and the substep loop that sequences the kernels.

The host only loops over substeps and stages; every pass over particles, contacts or
bodies is a kernel (``collision/``, ``integrate.py``, ``solver.py``, ``impacts.py``).
"""


import math
import time
from dataclasses import dataclass, field

import numpy as np
import taichi as ti

from .. import runtime
from ..collision.grid import CELLS_PER_SPHERE, body_grid
from ..collision import broadphase, narrowphase
from ..kinematics.quaternion import quaternion_matrix
from ..model import BodyModel
from . import impacts as impact_kernels
from . import integrate, stages
from .options import CapacityError, DynamicsOptions, WorldCapacity
from .state import MAX_CLUSTERS, Bodies, KeptMotion, Particles, Statics, StepParams

STAGES = ("collision", "response")


@dataclass(frozen=True)
class Checkpoint:
    """The motion state of the bodies ``ids`` (K,) at one moment, kept on the device
    (``World.checkpoint``): valid until the World's next checkpoint. ``token`` names it."""

    ids: np.ndarray
    token: int


@dataclass
class WorldStats:
    """Counters of a World.

    Attributes:
        contacts: contacts in the last substep of the last advance.
        peak_contacts: most contacts in one substep of the last advance.
        contact_overflows: contacts lost to ``max_contacts`` during the last advance
            (also summed into ``total_contact_overflows``); a warning is printed when > 0.
        impact_overflows: impact rows lost to ``max_impacts`` during the last advance.
        substeps: substeps taken by the last advance; total_substeps: since creation.
        substep_limit_hits: advances that wanted more than ``max_substeps``.
        frames: advances so far.
        seconds: wall time per stage summed since creation [s] (exact when
            ``options.stage_timing``).
        last_frame_seconds: wall time of the last advance [s].
    """

    contacts: int = 0
    peak_contacts: int = 0
    contact_overflows: int = 0
    total_contact_overflows: int = 0
    impact_overflows: int = 0
    substeps: int = 0
    total_substeps: int = 0
    substep_limit_hits: int = 0
    frames: int = 0
    seconds: dict = field(default_factory=lambda: {s: 0.0 for s in STAGES})
    last_frame_seconds: float = 0.0


#: Layout of a ``_write_bodies`` row (f32, 43): pose (13: position, orientation wxyz,
#: linear and angular velocity), inertia and inverse inertia (row-major 3x3), the scalars
#: (inverse mass, friction, restitution, compliance, contact radius), the sphere grid's
#: origin, edge and dims (``grid.body_grid``).
_ROW_INERTIA, _ROW_INVERSE_INERTIA, _ROW_SCALARS, _ROW_GRID = 13, 22, 31, 36  # (the pose at 0)
#: Columns of a ``_write_bodies`` ints row (i32): body slot, first particle slot, fixed,
#: its spheres' first and last + 1 row, its grid entries' first and last + 1 row, cluster
#: spheres asked.
_INT_SLOT, _INT_START, _INT_FIXED, _INT_SPHERES, _INT_SPHERES_END, _INT_GRID, _INT_GRID_END, _INT_CLUSTERS = range(8)


@ti.func
def _sphere_f32(spheres: ti.template(), k):
    """Row k of ``spheres`` (N,4) f64 as the f32 the fields hold (round to nearest, as
    numpy's astype)."""
    return ti.Vector([ti.cast(spheres[k, c], ti.f32) for c in ti.static(range(4))], dt=ti.f32)


_vec3d = ti.types.vector(3, ti.f64)


@ti.func
def _centre(spheres: ti.template(), k):
    return _vec3d(spheres[k, 0], spheres[k, 1], spheres[k, 2])


@ti.func
def _cluster_spheres(bodies: ti.template(), slot, spheres: ti.template(), begin, end, wanted,
                     nearest: ti.template()):
    """Body ``slot``'s cluster spheres (``Bodies.cluster``) over its collision spheres (rows
    ``begin`` to ``end`` of ``spheres`` (N,4) f64: body-frame centre [m], radius [m]), in
    f64: at most ``wanted`` seeds by farthest-point sampling (the first the sphere
    farthest from their mean), each cluster sphere at the mean of the spheres nearest its
    seed, its radius reaching the far side of every member (|offset - centre| + radius).
    ``nearest`` (N,) f64 is scratch (each sphere's squared distance to the nearest seed,
    then its cluster). Ties go to the lower index, as numpy's argmax/argmin."""
    mean = _vec3d(0.0)
    for k in range(begin, end):
        mean += _centre(spheres, k)
    mean /= ti.cast(end - begin, ti.f64)
    first = begin
    far = ti.cast(-1.0, ti.f64)
    for k in range(begin, end):
        d = _centre(spheres, k) - mean
        if d.dot(d) > far:
            far = d.dot(d)
            first = k
    seed_index = ti.Vector([0] * MAX_CLUSTERS, dt=ti.i32)
    seed_index[0] = first
    for k in range(begin, end):
        d = _centre(spheres, k) - _centre(spheres, first)
        nearest[k] = d.dot(d)
    seeds = 1
    while seeds < wanted:
        pick = begin
        for k in range(begin, end):
            if nearest[k] > nearest[pick]:
                pick = k
        if nearest[pick] <= 0.0:  # (coincident centres: fewer seeds)
            break
        seed_index[seeds] = pick
        seeds += 1
        for k in range(begin, end):
            d = _centre(spheres, k) - _centre(spheres, pick)
            nearest[k] = ti.min(nearest[k], d.dot(d))
    # Each sphere's cluster (its nearest seed), then each cluster's mean, then its reach.
    for k in range(begin, end):
        label = 0
        best = ti.cast(1e300, ti.f64)
        for m in range(seeds):
            d = _centre(spheres, k) - _centre(spheres, seed_index[m])
            if d.dot(d) < best:
                best = d.dot(d)
                label = m
        nearest[k] = label
    sums = ti.Matrix([[0.0] * 4 for _ in range(MAX_CLUSTERS)], ti.f64)  # centre sum, count; then centre, reach
    for k in range(begin, end):
        m = ti.cast(nearest[k], ti.i32)
        for x in ti.static(range(3)):
            sums[m, x] += spheres[k, x]
        sums[m, 3] += 1.0
    for m in range(seeds):
        for x in ti.static(range(3)):
            sums[m, x] /= sums[m, 3]
        sums[m, 3] = 0.0
    for k in range(begin, end):
        m = ti.cast(nearest[k], ti.i32)
        centre = _vec3d(sums[m, 0], sums[m, 1], sums[m, 2])
        sums[m, 3] = ti.max(sums[m, 3], (_centre(spheres, k) - centre).norm() + spheres[k, 3])
    for m in range(seeds):
        bodies.cluster[slot, m] = ti.Vector([ti.cast(sums[m, c], ti.f32) for c in ti.static(range(4))], dt=ti.f32)
    bodies.cluster_count[slot] = seeds


@ti.kernel
def _write_bodies(bodies: ti.template(), particles: ti.template(),
                  ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                  row: ti.types.ndarray(dtype=ti.f32, ndim=2),
                  spheres: ti.types.ndarray(dtype=ti.f64, ndim=2),
                  grid_ints: ti.types.ndarray(dtype=ti.i32, ndim=1),
                  nearest: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """Fill K body slots and their particle ranges in one launch: ``ints`` (K,8) (see
    ``_INT_*``), ``row`` (K,43) (see ``_ROW_*``), ``spheres`` (N,4) every body's collision
    spheres, body after body (body-frame centre [m], radius [m]), ``grid_ints`` each
    body's sphere-grid order (its spheres' count) then cell starts (cells + 1),
    body-relative, body after body; ``nearest`` (N,) scratch. Few array arguments: each
    costs ~11 us of Python a launch, and one launch serves all the pieces of a split."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for b in range(ints.shape[0]):
        slot = ints[b, _INT_SLOT]
        start = ints[b, _INT_START]
        begin = ints[b, _INT_SPHERES]
        end = ints[b, _INT_SPHERES_END]
        bodies.position[slot] = ti.math.vec3(row[b, 0], row[b, 1], row[b, 2])
        bodies.orientation[slot] = ti.math.vec4(row[b, 3], row[b, 4], row[b, 5], row[b, 6]).normalized()
        bodies.linear_velocity[slot] = ti.math.vec3(row[b, 7], row[b, 8], row[b, 9])
        bodies.angular_velocity[slot] = ti.math.vec3(row[b, 10], row[b, 11], row[b, 12])
        bodies.pseudo_linear_velocity[slot] = ti.math.vec3(0.0)
        bodies.pseudo_angular_velocity[slot] = ti.math.vec3(0.0)
        for r, c in ti.static(ti.ndrange(3, 3)):
            bodies.inertia_body[slot][r, c] = row[b, _ROW_INERTIA + 3 * r + c]
            bodies.inverse_inertia_body[slot][r, c] = row[b, _ROW_INVERSE_INERTIA + 3 * r + c]
        bodies.inverse_mass[slot] = row[b, _ROW_SCALARS]
        bodies.friction[slot] = row[b, _ROW_SCALARS + 1]
        bodies.restitution[slot] = row[b, _ROW_SCALARS + 2]
        bodies.contact_compliance[slot] = row[b, _ROW_SCALARS + 3]
        bodies.contact_radius[slot] = row[b, _ROW_SCALARS + 4]
        bodies.fixed[slot] = ints[b, _INT_FIXED]
        bodies.sleeping[slot] = 0
        bodies.sleep_timer[slot] = 0.0
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
            bounding = ti.max(bounding, offset.norm() + r)
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
        g = _ROW_GRID
        bodies.grid_origin[slot] = ti.math.vec3(row[b, g], row[b, g + 1], row[b, g + 2])
        bodies.grid_edge[slot] = row[b, g + 3]
        bodies.grid_dims[slot] = ti.math.ivec3(ti.cast(row[b, g + 4], ti.i32), ti.cast(row[b, g + 5], ti.i32),
                                               ti.cast(row[b, g + 6], ti.i32))
        _cluster_spheres(bodies, slot, spheres, begin, end, ints[b, _INT_CLUSTERS], nearest)
        grid = ints[b, _INT_GRID]
        count = end - begin
        for k in range(count):
            p = start + k
            particles.body[p] = slot
            particles.cache_stamp[0, p] = -1
            particles.cache_stamp[1, p] = -1
            particles.point_count[p] = 0  # (sphere contacts unless _write_patches says otherwise)
            sphere = _sphere_f32(spheres, begin + k)
            particles.offset[p] = ti.math.vec3(sphere[0], sphere[1], sphere[2])
            particles.radius[p] = sphere[3]
            j = grid_ints[grid + k]
            particles.grid_sphere[p] = _sphere_f32(spheres, begin + j)
            particles.grid_slot[p] = start + j
        for c in range(ints[b, _INT_GRID_END] - grid - count):
            particles.cell_first[ti.static(CELLS_PER_SPHERE) * start + c] = start + grid_ints[grid + count + c]


@ti.kernel
def _write_patches(particles: ti.template(), ints: ti.types.ndarray(dtype=ti.i32, ndim=2),
                   normals: ti.types.ndarray(dtype=ti.f32, ndim=2), points: ti.types.ndarray(dtype=ti.f32, ndim=2)):
    """The contact patches of S spheres: ``ints`` (S,4) (particle slot, first row of
    ``surface_point`` for its patch, its point count, the first row of those points in
    ``points``), ``normals`` (S,3) body frame, ``points`` (P,3) [m] body frame."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for s in range(ints.shape[0]):
        p = ints[s, 0]
        start = ints[s, 1]
        particles.point_start[p] = start
        particles.point_count[p] = ints[s, 2]
        particles.patch_normal[p] = ti.math.vec3(normals[s, 0], normals[s, 1], normals[s, 2])
        for k in range(ints[s, 2]):
            row = ints[s, 3] + k
            particles.surface_point[start + k] = ti.math.vec3(points[row, 0], points[row, 1], points[row, 2])


@ti.kernel
def _clear_body(bodies: ti.template(), particles: ti.template(), slot: ti.i32, start: ti.i32, count: ti.i32):
    bodies.active[slot] = 0
    bodies.near_body[slot] = 0
    bodies.near_static[slot] = 0
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(count):
        particles.body[start + k] = -1


@ti.kernel
def _set_velocity(bodies: ti.template(), slot: ti.i32, v: ti.types.vector(3, ti.f32), w: ti.types.vector(3, ti.f32)):
    bodies.linear_velocity[slot] = v
    bodies.angular_velocity[slot] = w
    bodies.sleeping[slot] = 0
    bodies.sleep_timer[slot] = 0.0


@ti.kernel
def _wake(bodies: ti.template(), slot: ti.i32):
    bodies.sleeping[slot] = 0
    bodies.sleep_timer[slot] = 0.0


@ti.kernel
def _pack_impacts(impacts: ti.template(), first: ti.i32, rows: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Impact rows first..first+R-1 into ``rows`` (R, 27): body, other, point, normal, impulse,
    force, duration, speed, dt, substep, point_body, normal_body, force_body (the layout
    World.impacts unpacks)."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for r in range(rows.shape[0]):
        k = first + r
        rows[r, 0] = impacts.body[k]
        rows[r, 1] = impacts.other[k]
        for c in ti.static(range(3)):
            rows[r, 2 + c] = impacts.point[k][c]
            rows[r, 5 + c] = impacts.normal[k][c]
            rows[r, 8 + c] = impacts.impulse[k][c]
            rows[r, 11 + c] = impacts.force[k][c]
            rows[r, 18 + c] = impacts.point_body[k][c]
            rows[r, 21 + c] = impacts.normal_body[k][c]
            rows[r, 24 + c] = impacts.force_body[k][c]
        rows[r, 14] = impacts.duration[k]
        rows[r, 15] = impacts.speed[k]
        rows[r, 16] = impacts.dt[k]
        rows[r, 17] = impacts.substep[k]


@ti.func
def _pack_body(bodies: ti.template(), b, rows: ti.template(), k):
    for c in ti.static(range(3)):
        rows[k, c] = bodies.position[b][c]
        rows[k, 7 + c] = bodies.linear_velocity[b][c]
        rows[k, 10 + c] = bodies.angular_velocity[b][c]
    for c in ti.static(range(4)):
        rows[k, 3 + c] = bodies.orientation[b][c]
    rows[k, 13] = bodies.active[b]
    rows[k, 14] = bodies.sleeping[b]
    rows[k, 15] = bodies.sleep_timer[b]
    rows[k, 16] = bodies.wake_request[b]


@ti.kernel
def _pack_bodies(bodies: ti.template(), ids: ti.types.ndarray(dtype=ti.i32, ndim=1),
                 rows: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Bodies ``ids`` (K,) into ``rows`` (K, 17): position, orientation (wxyz), linear and
    angular velocity, active, sleeping, sleep timer, wake request (the layout
    World.body_state unpacks)."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(ids.shape[0]):
        _pack_body(bodies, ids[k], rows, k)


@ti.func
def _unpack_body(bodies: ti.template(), b, rows: ti.template(), k):
    """The inverse of _pack_body for the motion state (not ``active``) of body ``b``."""
    for c in ti.static(range(3)):  # (f64 rows of f32 values: exact)
        bodies.position[b][c] = ti.cast(rows[k, c], ti.f32)
        bodies.linear_velocity[b][c] = ti.cast(rows[k, 7 + c], ti.f32)
        bodies.angular_velocity[b][c] = ti.cast(rows[k, 10 + c], ti.f32)
    for c in ti.static(range(4)):
        bodies.orientation[b][c] = ti.cast(rows[k, 3 + c], ti.f32)
    bodies.sleeping[b] = ti.cast(rows[k, 14], ti.i32)
    bodies.sleep_timer[b] = ti.cast(rows[k, 15], ti.f32)
    bodies.wake_request[b] = ti.cast(rows[k, 16], ti.i32)


@ti.kernel
def _keep_bodies(f: ti.template(), kept: ti.template()):
    """Every body slot's motion state and the contact cache's parity and epoch into
    ``kept`` (a KeptMotion). One serial task: a parallel one over ~100 bodies costs more to
    dispatch than the copy, and a copy to the host, with its array arguments, would be paid
    before every substep of a scene that re-runs broken substeps."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for b in range(f.bodies.slot_end[None]):
        _pack_body(f.bodies, b, kept.rows, b)
    kept.cache[0] = f.particles.parity[None]
    kept.cache[1] = f.particles.cache_epoch[None]


@ti.kernel
def _restore_kept(f: ti.template(), kept: ti.template(), ids: ti.types.ndarray(dtype=ti.i32, ndim=1)):
    """Bodies ``ids`` back to their motion state in ``kept`` (slot b in row b), and the
    contact cache's parity and epoch."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(ids.shape[0]):
        _unpack_body(f.bodies, ids[k], kept.rows, ids[k])
    f.particles.parity[None] = kept.cache[0]
    f.particles.cache_epoch[None] = kept.cache[1]


@ti.kernel
def _pack_kept(kept: ti.template(), ids: ti.types.ndarray(dtype=ti.i32, ndim=1),
               rows: ti.types.ndarray(dtype=ti.f64, ndim=2)):
    """Rows of ``kept`` for bodies ``ids`` (K,) into ``rows`` (K, 17)."""
    ti.loop_config(serialize=runtime.SERIAL_SMALL_LOOPS)
    for k in range(ids.shape[0]):
        for c in ti.static(range(17)):
            rows[k, c] = kept.rows[ids[k], c]


@ti.kernel
def _begin_advance(f: ti.template(), margin: ti.f32, frame_dt: ti.f32, substeps: ti.i32,
                   motion_fraction: ti.f32) -> ti.i32:
    """The advance's counters reset, and the substeps this frame needs
    (``integrate.frame_substeps``), in one launch."""
    f.contacts.overflow[None] = 0
    f.contacts.peak[None] = 0
    f.impacts.count[None] = 0
    f.impacts.overflow[None] = 0
    return integrate.frame_substeps(f, margin, frame_dt, substeps, motion_fraction)


@ti.kernel
def _advance_counters(f: ti.template()) -> ti.types.vector(5, ti.i32):
    """(contacts in the last substep, peak, lost to capacity, impact rows lost, impact rows
    recorded) in one launch instead of five field reads."""
    return ti.Vector([f.contacts.count[None], f.contacts.peak[None], f.contacts.overflow[None],
                      f.impacts.overflow[None], f.impacts.count[None]], dt=ti.i32)


def _body_rows(ids: np.ndarray, rows: np.ndarray) -> dict:
    """The dict World.body_state returns from rows (K, 17) in ``_pack_body``'s layout."""
    return dict(id=ids, position=rows[:, 0:3], orientation=rows[:, 3:7], linear_velocity=rows[:, 7:10],
                angular_velocity=rows[:, 10:13], active=rows[:, 13] != 0, sleeping=rows[:, 14] != 0)


class World:
    """Rigid bodies colliding through their particle layers (see docs/ARCHITECTURE.md).

    All Taichi fields are allocated here once (``capacity``); adding or removing bodies
    writes into them through kernels that take numpy arrays (``ti.types.ndarray``), so no
    kernel is recompiled at run time.
    """

    def __init__(self, capacity: WorldCapacity | None = None, options: DynamicsOptions | None = None,
                 arch: str | None = None):
        runtime.init(arch)
        self.capacity = capacity or WorldCapacity()
        self.options = options or DynamicsOptions()
        cap = self.capacity
        self.bodies = Bodies(cap.max_bodies)
        self.particles = Particles(cap.max_boundary_particles, cap.max_surface_points)
        self.statics = Statics(cap.max_planes, cap.max_static_boxes)
        self.grid = broadphase.BodyGrid(cap.max_bodies)
        self.contacts = narrowphase.Contacts(cap.max_contacts)
        self.impact_buffer = impact_kernels.Impacts(cap.max_impacts, cap.max_contacts)
        self.fields = stages.WorldFields(self.bodies, self.statics, self.particles, self.grid, self.contacts,
                                         self.impact_buffer, StepParams())
        self._params_of = None  # the options object the StepParams fields hold
        self.kept = KeptMotion(cap.max_bodies)
        self._checkpoint_token = 0
        self.particles.body.fill(-1)
        self.statics.gravity[None] = tuple(map(float, self.options.gravity))
        self.stats = WorldStats()
        self._free_body_slots: list[int] = []
        self._body_slot_end = 0
        self._free_ranges: list[tuple[int, int]] = [(0, cap.max_boundary_particles)]  # (start, count)
        self._body_range: dict[int, tuple[int, int]] = {}
        self._particles_in_use = 0
        self._free_points: list[tuple[int, int]] = [(0, cap.max_surface_points)]  # (start, count)
        self._point_range: dict[int, tuple[int, int]] = {}  # body slot -> its patch points
        self._particle_slot_end = 0
        self._plane_count = 0
        self._box_count = 0
        self._substep_counter = 0
        self._impact_rows = 0  # impact rows of the last advance, once it has ended

    # ---------------------------------------------------------------- bodies

    def add_body(self, model: BodyModel, position=(0.0, 0.0, 0.0), orientation_wxyz=(1.0, 0.0, 0.0, 0.0),
                 linear_velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0), *, friction: float = 0.5,
                 restitution: float = 0.2, single_scale: bool | None = None, fixed: bool = False,
                 breakable: bool = True, young_modulus: float | None = None, poisson_ratio: float = 0.25,
                 contact_radius: float | None = None) -> int:
        """Add a body (its COM at ``position`` [m], world velocities [m/s], [rad/s]) and
        return its slot id. ``single_scale`` (default ``options.single_scale``) collides with
        the physics surface particles instead of the boundary layer. ``breakable`` is
        bookkeeping for the fracture stage (kept in ``self.breakable``).
        ``young_modulus`` [Pa] (None: rigid) and ``poisson_ratio`` give the Hertz contact
        time of its impacts; ``contact_radius`` [m] (default: the radius of the sphere of
        its volume) is the curvature it impacts with (see impacts.py)."""
        return self.add_bodies([model], [position], [orientation_wxyz], [linear_velocity], [angular_velocity],
                               friction=friction, restitution=restitution, single_scale=single_scale, fixed=fixed,
                               breakable=breakable, young_modulus=young_modulus, poisson_ratio=poisson_ratio,
                               contact_radius=contact_radius)[0]

    def add_bodies(self, models, positions, orientations_wxyz, linear_velocities, angular_velocities, *,
                   friction: float = 0.5, restitution: float = 0.2, single_scale: bool | None = None,
                   fixed: bool = False, breakable=True, young_modulus: float | None = None,
                   poisson_ratio: float = 0.25, contact_radius: float | None = None) -> list[int]:
        """Add K bodies at once (the pieces of a split) in one launch; returns their slot
        ids in order. Per body: ``models``, ``positions`` (K,3) [m], ``orientations_wxyz``
        (K,4), ``linear_velocities`` (K,3) [m/s], ``angular_velocities`` (K,3) [rad/s] and
        ``breakable`` (one bool for all, or K); the other arguments are shared and mean
        what they mean for :meth:`add_body`. Either every body is added or none (a full
        capacity raises CapacityError with nothing added)."""
        count = len(models)
        per_body = (positions, orientations_wxyz, linear_velocities, angular_velocities)
        if any(len(a) != count for a in per_body):
            raise ValueError(f"add_bodies needs one position, orientation and pair of velocities per model "
                             f"({count} models), got {[len(a) for a in per_body]}")
        if isinstance(breakable, (bool, np.bool_)):
            breakable = [bool(breakable)] * count
        if len(breakable) != count:
            raise ValueError(f"breakable: one bool, or one per model ({count}), got {len(breakable)}")
        if young_modulus is not None and not young_modulus > 0:
            raise ValueError(f"young_modulus must be > 0 [Pa] or None (rigid), got {young_modulus!r}")
        compliance = 0.0 if young_modulus is None else (1.0 - poisson_ratio ** 2) / young_modulus
        single = self.options.single_scale if single_scale is None else bool(single_scale)
        poses = [np.concatenate([positions[b], orientations_wxyz[b], linear_velocities[b], angular_velocities[b]])
                 for b in range(count)]
        if any(pose.shape != (13,) for pose in poses):
            raise ValueError("position, velocities need 3 components and orientation_wxyz 4")
        layers, patches = [], []
        for model in models:
            if single:
                offsets, radii = model.particle_position[model.surface_particles], \
                    model.particle_radius[model.surface_particles]
            else:
                offsets, radii = model.collision_position, model.boundary_radius
            if len(radii) == 0:
                raise ValueError("the body has no collision particles (empty boundary layer)")
            layers.append((offsets, radii))
            if self.options.surface_contact:
                patches.append(model.surface_particle_patches if single else model.boundary_patches)
                if len(patches[-1].offsets) != len(radii) + 1:
                    raise ValueError(f"the model's boundary groups ({len(patches[-1].offsets) - 1}) do not match "
                                     f"its {len(radii)} collision spheres: rebuild it, or add it with "
                                     "DynamicsOptions(surface_contact=False)")
        taken = []  # (slot, start, count): given back if a later body does not fit
        point_starts = []
        try:
            for offsets, radii in layers:
                slot = self._allocate_body_slot()
                taken.append((slot, self._allocate_particles(len(radii), slot_for_error=slot), len(radii)))
            for patch in patches:
                point_starts.append(self._allocate_points(len(patch.points)))
        except CapacityError:
            for slot, start, n in reversed(taken):  # (so the slots go out again in the same order)
                self._free_body_slots.insert(0, slot)
                self._release_particles(start, n)
            for first, patch in zip(point_starts, patches):
                self._free_points = _give_range(self._free_points, first, len(patch.points))
            raise
        ints = np.zeros((count, 8), dtype=np.int32)
        rows_out = np.empty((count, 43), dtype=np.float32)
        sphere_rows, grid_rows = [], []
        spheres_so_far = grid_so_far = 0
        for b, (model, (offsets, radii), (slot, start, n)) in enumerate(zip(models, layers, taken)):
            inertia = np.asarray(model.inertia, dtype=np.float64)
            if fixed:
                inverse_mass, inverse_inertia = 0.0, np.zeros((3, 3))
            else:
                inverse_mass, inverse_inertia = 1.0 / model.mass, np.linalg.inv(inertia)
            radius = contact_radius if contact_radius is not None else (3.0 * model.volume / (4.0 * np.pi)) ** (1 / 3)
            origin, edge, dims, cell_first, order = body_grid(offsets, radii, self.options.contact_margin)
            rows_out[b] = np.concatenate([poses[b], inertia.reshape(-1), inverse_inertia.reshape(-1),
                                          [inverse_mass, friction, restitution, compliance, radius], origin, [edge],
                                          dims])
            sphere_rows.append(np.column_stack([offsets, radii]))
            grid_rows.append(np.concatenate([order, cell_first]))
            ints[b] = (slot, start, int(fixed), spheres_so_far, spheres_so_far + n, grid_so_far,
                       grid_so_far + len(grid_rows[-1]), min(MAX_CLUSTERS, max(1, n // 16)))
            spheres_so_far += n
            grid_so_far += len(grid_rows[-1])
        spheres = np.concatenate(sphere_rows).astype(np.float64)
        _write_bodies(self.bodies, self.particles, ints, rows_out, spheres,
                      np.concatenate(grid_rows).astype(np.int32), np.empty(len(spheres)))
        if patches:
            self._write_patches(taken, patches, point_starts)
        self.breakable = getattr(self, "breakable", {})
        for (slot, start, n), can_break in zip(taken, breakable):
            self._body_range[slot] = (start, n)
            self.breakable[slot] = bool(can_break)
            self._particles_in_use += n
            self._particle_slot_end = max(self._particle_slot_end, start + n)
        self.particles.slot_end[None] = self._particle_slot_end
        self.bodies.slot_end[None] = self._body_slot_end
        return [slot for slot, _, _ in taken]

    def _write_patches(self, taken, patches, point_starts) -> None:
        """Copy the bodies' contact patches into their point ranges (one launch)."""
        ints, rows_so_far = [], 0
        for (slot, start, n), patch, first in zip(taken, patches, point_starts):
            counts = np.diff(patch.offsets)
            ints.append(np.column_stack([start + np.arange(n), first + patch.offsets[:-1], counts,
                                         rows_so_far + patch.offsets[:-1]]))
            rows_so_far += len(patch.points)
            self._point_range[slot] = (first, len(patch.points))
        _write_patches(self.particles, np.ascontiguousarray(np.concatenate(ints), dtype=np.int32),
                       np.concatenate([p.normals for p in patches]).astype(np.float32),
                       np.concatenate([p.points for p in patches]).astype(np.float32))

    def remove_body(self, body: int) -> None:
        """Free a body's slot and particle range (a parent replaced by its fragments)."""
        if body not in self._body_range:
            raise KeyError(f"body {body} is not in the world")
        start, count = self._body_range.pop(body)
        _clear_body(self.bodies, self.particles, body, start, count)
        self._free_body_slots.append(body)
        self._release_particles(start, count)
        self._particles_in_use -= count
        if body in self._point_range:
            self._free_points = _give_range(self._free_points, *self._point_range.pop(body))

    def add_ground(self, height: float = 0.0, friction: float = 0.5, restitution: float = 0.2) -> int:
        """A horizontal ground plane z = height [m] (normal +Z); returns its index."""
        if self._plane_count >= self.capacity.max_planes:
            raise CapacityError(f"more than max_planes={self.capacity.max_planes} ground planes: "
                                "raise WorldCapacity(max_planes=...)")
        k = self._plane_count
        self.statics.plane_height[k] = height
        self.statics.plane_friction[k] = friction
        self.statics.plane_restitution[k] = restitution
        self._plane_count += 1
        self.statics.plane_count[None] = self._plane_count
        return k

    def add_static_box(self, center, half_extents, orientation=(1.0, 0.0, 0.0, 0.0), friction: float = 0.5,
                       restitution: float = 0.2) -> int:
        """A static oriented box (walls, inclines): centre [m], half extents [m],
        orientation wxyz box -> world. Returns its index."""
        if self._box_count >= self.capacity.max_static_boxes:
            raise CapacityError(f"more than max_static_boxes={self.capacity.max_static_boxes} static boxes: "
                                "raise WorldCapacity(max_static_boxes=...)")
        k = self._box_count
        q = np.asarray(orientation, dtype=np.float64)
        q = q / np.linalg.norm(q)
        self.statics.box_center[k] = np.asarray(center, dtype=np.float32)
        self.statics.box_half_extents[k] = np.asarray(half_extents, dtype=np.float32)
        self.statics.box_rotation[k] = quaternion_matrix(q).astype(np.float32)
        self.statics.box_friction[k] = friction
        self.statics.box_restitution[k] = restitution
        self._box_count += 1
        self.statics.box_count[None] = self._box_count
        return k

    def set_body_velocity(self, body: int, linear_velocity, angular_velocity) -> None:
        """Set a body's world velocities [m/s], [rad/s] and wake it."""
        self._check_body(body)
        _set_velocity(self.bodies, body, ti.Vector(list(map(float, linear_velocity))),
                      ti.Vector(list(map(float, angular_velocity))))

    def wake(self, body: int) -> None:
        self._check_body(body)
        _wake(self.bodies, body)

    def clear(self) -> None:
        """Remove every body and static collider (fields and compiled kernels are kept)."""
        for body in list(self._body_range):
            self.remove_body(body)
        self._free_body_slots = []
        self._body_slot_end = 0
        self.bodies.slot_end[None] = 0
        self._particle_slot_end = 0
        self.particles.slot_end[None] = 0
        self._free_ranges = [(0, self.capacity.max_boundary_particles)]
        self._free_points = [(0, self.capacity.max_surface_points)]
        self._point_range = {}
        self._plane_count = self._box_count = 0
        self.statics.plane_count[None] = 0
        self.statics.box_count[None] = 0
        self._checkpoint_token += 1  # a checkpoint of the bodies removed restores nothing

    def set_options(self, options: DynamicsOptions) -> None:
        """Replace the solver options between advances (kernel arguments and StepParams
        fields written before the next substep, so this compiles nothing)."""
        self.options = options
        self.statics.gravity[None] = tuple(map(float, options.gravity))

    @property
    def body_ids(self) -> list[int]:
        return sorted(self._body_range)

    # ---------------------------------------------------------------- stepping

    def advance(self, frame_dt: float, substeps: int = 10, watch=None) -> None:
        """Advance one frame of ``frame_dt`` [s] in at least ``substeps`` substeps; more are
        taken when a body that may touch something during the frame would otherwise move
        further than ``substep_motion_fraction`` of its mean collision-particle radius in one
        substep, up to ``max_substeps``. (Tunnelling is prevented by the speculative
        contacts at any substep length; the refinement keeps contacts accurate and the grid
        cells small.)

        ``watch``: an object with ``before(k)`` and ``after(k) -> bool``, called around
        each substep k; when ``after`` returns True the substep is run again (once, with
        ``after`` called again): the simulation's fracture inside a frame, which restores
        the bodies to their state before the substep and puts a broken body's pieces in
        its place."""
        t_frame = time.perf_counter()
        opt = self.options
        self._impact_rows = None  # (read live while the frame runs: a watch's fracture stage)
        count = int(_begin_advance(self.fields, opt.contact_margin, frame_dt, int(substeps),
                                   opt.substep_motion_fraction))
        if count > 0:  # someone is awake
            if count > opt.max_substeps:
                self.stats.substep_limit_hits += 1
                count = opt.max_substeps
            dt = frame_dt / count
            for k in range(count):
                if watch is not None:
                    watch.before(k)
                self._substep(dt, k)
                if watch is not None and watch.after(k):
                    self._substep(dt, k)
                    watch.after(k)
        self.stats.substeps = count
        self.stats.total_substeps += count
        self.stats.frames += 1
        contacts, peak, overflow, impact_overflow, impact_rows = (int(v) for v in _advance_counters(self.fields))
        self._impact_rows = min(impact_rows, self.capacity.max_impacts)
        self.stats.contacts = contacts if count else 0
        self.stats.peak_contacts = max(peak, self.stats.contacts)
        self.stats.contact_overflows = overflow
        self.stats.total_contact_overflows += overflow
        self.stats.impact_overflows = impact_overflow
        if overflow:
            print(f"taichi-frac dynamics: {overflow} contacts lost in this frame: more than "
                  f"max_contacts={self.capacity.max_contacts} in a substep; raise WorldCapacity(max_contacts=...)")
        self.stats.last_frame_seconds = time.perf_counter() - t_frame

    def _substep(self, dt: float, index: int) -> None:
        opt = self.options
        if self._params_of is not opt:
            self._write_params(opt)
        clock = self._clock()
        stages.collide(self.fields, opt.contact_margin, dt, opt.sleep_time)
        clock("collision")
        stages.respond(self.fields, dt, index, 1.0 - math.exp(-opt.position_correction_rate * dt))
        clock("response")

    def _write_params(self, opt: DynamicsOptions) -> None:
        """The options ``respond`` reads into its StepParams fields (once per options object:
        they are frozen, and replaced whole by :meth:`set_options`)."""
        params = self.fields.params
        values = dict(
            iterations=opt.solver_iterations, restitution_iterations=opt.restitution_iterations,
            allowed_penetration=opt.allowed_penetration,
            max_correction_speed=opt.max_correction_speed, restitution_threshold=opt.restitution_threshold,
            force_threshold=opt.record_force_threshold, impact_speed=opt.impact_speed,
            max_rotation=opt.max_rotation_per_substep, sleep_linear_speed=opt.sleep_linear_speed,
            sleep_angular_speed=opt.sleep_angular_speed, sleep_time=opt.sleep_time, warm_start=opt.warm_start,
            rolling_resistance=opt.rolling_resistance,
        )
        for name, value in values.items():
            getattr(params, name)[None] = value
        self._params_of = opt

    def _clock(self):
        last = [time.perf_counter()]
        seconds = self.stats.seconds
        sync = self.options.stage_timing

        def tick(stage: str):
            if sync:
                ti.sync()
            now = time.perf_counter()
            seconds[stage] += now - last[0]
            last[0] = now

        return tick

    # ---------------------------------------------------------------- read back

    def body_state(self, ids=None) -> dict:
        """World state of bodies ``ids`` (default: all in the world, sorted): position (K,3)
        [m], orientation (K,4) wxyz, linear_velocity (K,3) [m/s], angular_velocity (K,3)
        [rad/s], active (K,) bool, sleeping (K,) bool. float64 copies."""
        ids = np.asarray(self.body_ids if ids is None else ids, dtype=np.int64)
        if len(ids) and (ids.min() < 0 or ids.max() >= self.capacity.max_bodies):
            raise IndexError(f"body ids must lie in [0, {self.capacity.max_bodies}), got {ids.min()}..{ids.max()}")
        # One launch for the K rows: six whole-field reads would cost more, paid per
        # analysed impact and per written frame.
        rows = np.zeros((len(ids), 17), dtype=np.float64)
        if len(ids):
            _pack_bodies(self.bodies, np.ascontiguousarray(ids, dtype=np.int32), rows)
        return _body_rows(ids, rows)

    def impact_count(self) -> int:
        """Impact rows recorded so far in this advance (see :meth:`impacts`): the count the
        advance read at its end, or, while it runs, the live one (a field read, a launch)."""
        if self._impact_rows is not None:
            return self._impact_rows
        return min(int(self.impact_buffer.count[None]), self.capacity.max_impacts)

    def checkpoint(self) -> Checkpoint:
        """The motion state of every body now (pose, velocities, sleep state) and the contact
        cache's, kept on the device for :meth:`restore` and :meth:`checkpoint_state` (one
        small launch; nothing is copied to the host; static data is not copied). Valid
        until the next checkpoint: the World keeps only the latest."""
        _keep_bodies(self.fields, self.kept)
        self._checkpoint_token += 1
        return Checkpoint(ids=np.asarray(self.body_ids, dtype=np.int32), token=self._checkpoint_token)

    def restore(self, checkpoint: Checkpoint, ids) -> None:
        """Put bodies ``ids`` (each in the world now and in ``checkpoint``) back in their
        motion state of ``checkpoint``, and the contact cache (warm starting) back to that
        moment: the impulses stored since are no longer the valid half, so a substep run
        again warm-starts as it did. The other bodies are left as they are."""
        ids = np.asarray(ids, dtype=np.int64)
        missing = [int(b) for b in ids if int(b) not in self._body_range]
        if missing:
            raise KeyError(f"bodies {missing} are not in the world")
        _restore_kept(self.fields, self.kept, self._checkpoint_ids(checkpoint, ids))

    def checkpoint_state(self, checkpoint: Checkpoint, ids) -> dict:
        """:meth:`body_state` of bodies ``ids`` as ``checkpoint`` holds them."""
        ids = np.asarray(ids, dtype=np.int64)
        rows = np.zeros((len(ids), 17), dtype=np.float64)
        _pack_kept(self.kept, self._checkpoint_ids(checkpoint, ids), rows)
        return _body_rows(ids, rows)

    def _checkpoint_ids(self, checkpoint: Checkpoint, ids: np.ndarray) -> np.ndarray:
        """``ids`` as i32 for a kernel; raises if ``checkpoint`` is stale or lacks one."""
        if checkpoint.token != self._checkpoint_token:
            raise ValueError(f"checkpoint {checkpoint.token} is stale: the World has taken checkpoint "
                             f"{self._checkpoint_token} since (or been cleared), and keeps only the latest")
        missing = np.setdiff1d(ids, checkpoint.ids)
        if len(missing):
            raise KeyError(f"bodies {missing.tolist()} are not in the checkpoint")
        return np.ascontiguousarray(ids, dtype=np.int32)

    def impacts(self, first: int = 0) -> dict:
        """Impact rows of the last advance (see docs/ARCHITECTURE.md): body (K,), other (K,)
        (-1 ground, -2 static box), point (K,3) [m], normal (K,3) unit into body, impulse
        (K,3) [N s] on body, force (K,3) [N] on body (Hertz peak force at the approach
        speed for an impact, J / dt for a sustained contact; see dynamics/impacts.py),
        duration (K,) [s] Hertz contact time
        (0: sustained), speed (K,) [m/s] approach speed, dt (K,) [s], substep (K,);
        point_body, normal_body, force_body (K,3): point, normal and force in the body's
        frame at that substep. ``first``: only the rows from that one on (those of the
        substeps since :meth:`impact_count` returned it)."""
        n = self.impact_count()
        first = min(max(int(first), 0), n)
        # The rows in one launch: reading each field whole (16k rows x 10 fields) costs
        # milliseconds a frame.
        rows = np.zeros((n - first, 27), dtype=np.float64)
        if n > first:
            _pack_impacts(self.impact_buffer, first, rows)
        return dict(
            body=rows[:, 0].astype(np.int32), other=rows[:, 1].astype(np.int32), point=rows[:, 2:5],
            normal=rows[:, 5:8], impulse=rows[:, 8:11], force=rows[:, 11:14], duration=rows[:, 14],
            speed=rows[:, 15], dt=rows[:, 16], substep=rows[:, 17].astype(np.int32),
            point_body=rows[:, 18:21], normal_body=rows[:, 21:24], force_body=rows[:, 24:27],
        )

    def particle_state(self, body: int) -> dict:
        """World positions (K,3) [m] and radii (K,) [m] of one body's collision particles
        (tests, diagnostics; computed from the pose, not the broadphase buffer)."""
        start, count = self._body_range[body]
        offsets = self.particles.offset.to_numpy()[start:start + count].astype(np.float64)
        radii = self.particles.radius.to_numpy()[start:start + count].astype(np.float64)
        state = self.body_state([body])
        rot = quaternion_matrix(state["orientation"][0])
        return dict(position=state["position"][0] + offsets @ rot.T, radius=radii)

    # ---------------------------------------------------------------- slots

    def _check_body(self, body: int) -> None:
        if body not in self._body_range:
            raise KeyError(f"body {body} is not in the world")

    def _allocate_body_slot(self) -> int:
        if self._free_body_slots:
            return self._free_body_slots.pop(0)
        if self._body_slot_end >= self.capacity.max_bodies:
            raise CapacityError(f"more than max_bodies={self.capacity.max_bodies} bodies: "
                                "raise WorldCapacity(max_bodies=...)")
        self._body_slot_end += 1
        return self._body_slot_end - 1

    def _allocate_particles(self, count: int, slot_for_error: int) -> int:
        start = _take_range(self._free_ranges, count)
        if start is not None:
            return start
        self._free_body_slots.insert(0, slot_for_error)
        raise CapacityError(
            f"no room for {count} more collision particles: {self._particles_in_use} of "
            f"max_boundary_particles={self.capacity.max_boundary_particles} in use "
            f"(largest free range {max((f for _, f in self._free_ranges), default=0)}): "
            "raise WorldCapacity(max_boundary_particles=...)")

    def _allocate_points(self, count: int) -> int:
        start = _take_range(self._free_points, count)
        if start is None:
            raise CapacityError(
                f"no room for {count} more contact-patch points (max_surface_points="
                f"{self.capacity.max_surface_points}, largest free range "
                f"{max((f for _, f in self._free_points), default=0)}): raise WorldCapacity(max_surface_points=...)")
        return start

    def _release_particles(self, start: int, count: int) -> None:
        self._free_ranges = _give_range(self._free_ranges, start, count)


def _take_range(ranges: list, count: int):
    """First fit: the start of ``count`` slots taken from the free ``ranges`` [(start,
    count)] (updated in place), or None when no range is large enough."""
    for k, (start, free) in enumerate(ranges):
        if free >= count:
            if free == count:
                ranges.pop(k)
            else:
                ranges[k] = (start + count, free - count)
            return start
    return None


def _give_range(ranges: list, start: int, count: int) -> list:
    """The free ``ranges`` with [start, start + count) given back, neighbours merged."""
    merged: list[tuple[int, int]] = []
    for s, n in sorted(ranges + [(start, count)]):
        if merged and merged[-1][0] + merged[-1][1] == s:
            merged[-1] = (merged[-1][0], merged[-1][1] + n)
        else:
            merged.append((s, n))
    return merged
