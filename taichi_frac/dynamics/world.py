"""The rigid-body world's façade: fixed-capacity Taichi fields, bodies added and removed at
run time (fragments) by writing into them, and the substep loop that sequences the kernels.

The host only loops over substeps and stages; every pass over particles, contacts or
bodies is a kernel (``collision/``, ``integrate.py``, ``solver.py``, ``impacts.py``). Where
a body's slots are (``slots.py``), the row layouts that carry bodies and impacts to and
from the kernels (``layouts.py``, ``body_fields.py``), cluster spheres (``clusters.py``)
and checkpoints (``checkpoints.py``) each have their own module.
"""


import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..runtime import ti
from .. import runtime
from ..collision import broadphase, narrowphase
from ..collision.grid import body_grid
from ..kinematics.quaternion import quaternion_matrix
from ..geometry.contact_patches import patches_of
from ..model import BodyModel
from . import body_fields, checkpoints, integrate, stages
from . import impacts as impact_kernels
from .checkpoints import Checkpoint
from .layouts import BODY_STATE, BODY_WRITE, BODY_WRITE_INTS, IMPACT, IMPACT_INTEGERS
from .options import CapacityError, DynamicsOptions, WorldCapacity
from .slots import SlotAllocator
from .state import MAX_CLUSTERS, Bodies, Particles, Statics, StepParams

STAGES = ("collision", "response")


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
        self.kept = checkpoints.KeptState(cap.max_bodies)
        self._checkpoint_token = 0
        self.particles.body.fill(-1)
        self.statics.gravity[None] = tuple(map(float, self.options.gravity))
        self.stats = WorldStats()
        self.slots = SlotAllocator(cap)
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
        layers = []
        for model in models:
            if single:
                offsets, radii = model.particle_position[model.surface_particles], \
                    model.particle_radius[model.surface_particles]
            else:
                offsets, radii = model.collision_position, model.boundary_radius
            if len(radii) == 0:
                raise ValueError("the body has no collision particles (empty boundary layer)")
            layers.append((offsets, radii))
        # (one numpy pass for all the models' patches: a fracture adds its fragments at once)
        patches = patches_of(models, single) if self.options.surface_contact else []
        for patch, (_, radii) in zip(patches, layers):
            if len(patch.offsets) != len(radii) + 1:
                raise ValueError(f"the model's boundary groups ({len(patch.offsets) - 1}) do not match "
                                 f"its {len(radii)} collision spheres: rebuild it, or add it with "
                                 "DynamicsOptions(surface_contact=False)")
        taken, point_starts = self.slots.take([len(radii) for _, radii in layers],
                                              [len(patch.points) for patch in patches])
        ints = np.zeros((count, BODY_WRITE_INTS.width), dtype=np.int32)
        rows_out = np.empty((count, BODY_WRITE.width), dtype=np.float32)
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
            rows_out[b] = BODY_WRITE.row(
                position=positions[b], orientation=orientations_wxyz[b], linear_velocity=linear_velocities[b],
                angular_velocity=angular_velocities[b], inertia=inertia, inverse_inertia=inverse_inertia,
                inverse_mass=inverse_mass, friction=friction, restitution=restitution, contact_compliance=compliance,
                contact_radius=radius, grid_origin=origin, grid_edge=edge, grid_dims=dims)
            sphere_rows.append(np.column_stack([offsets, radii]))
            grid_rows.append(np.concatenate([order, cell_first]))
            ints[b] = BODY_WRITE_INTS.row(
                slot=slot, particle_start=start, fixed=int(fixed), spheres=spheres_so_far,
                spheres_end=spheres_so_far + n, grid=grid_so_far, grid_end=grid_so_far + len(grid_rows[-1]),
                clusters=min(MAX_CLUSTERS, max(1, n // 16)))
            spheres_so_far += n
            grid_so_far += len(grid_rows[-1])
        spheres = np.concatenate(sphere_rows).astype(np.float64)
        body_fields.write_bodies(self.bodies, self.particles, ints, rows_out, spheres,
                                 np.concatenate(grid_rows).astype(np.int32), np.empty(len(spheres)))
        if patches:
            self._write_patches(taken, patches, point_starts)
        self.breakable = getattr(self, "breakable", {})
        for (slot, start, n), can_break in zip(taken, breakable):
            self.slots.hold(slot, start, n)
            self.breakable[slot] = bool(can_break)
        self.particles.slot_end[None] = self.slots.particle_slot_end
        self.bodies.slot_end[None] = self.slots.body_slot_end
        return [slot for slot, _, _ in taken]

    def _write_patches(self, taken, patches, point_starts) -> None:
        """Copy the bodies' contact patches into their point ranges (one launch)."""
        ints, rows_so_far = [], 0
        for (slot, start, n), patch, first in zip(taken, patches, point_starts):
            counts = np.diff(patch.offsets)
            ints.append(np.column_stack([start + np.arange(n), first + patch.offsets[:-1], counts,
                                         rows_so_far + patch.offsets[:-1]]))
            rows_so_far += len(patch.points)
            self.slots.point_range[slot] = (first, len(patch.points))
        body_fields.write_patches(self.bodies, self.particles,
                                  np.ascontiguousarray(np.concatenate(ints), dtype=np.int32),
                                  np.concatenate([p.normals for p in patches]).astype(np.float32),
                                  np.concatenate([p.facets.reshape(len(p.facets), -1)
                                                  for p in patches]).astype(np.float32),
                                  np.concatenate([p.points for p in patches]).astype(np.float32))

    def remove_body(self, body: int) -> None:
        """Free a body's slot and particle range (a parent replaced by its fragments)."""
        self._check_body(body)
        start, count = self.slots.release(body)
        body_fields.clear_body(self.bodies, self.particles, body, start, count)

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
        body_fields.set_velocity(self.bodies, body, ti.Vector(list(map(float, linear_velocity))),
                                 ti.Vector(list(map(float, angular_velocity))))

    def wake(self, body: int) -> None:
        self._check_body(body)
        body_fields.wake(self.bodies, body)

    def clear(self) -> None:
        """Remove every body and static collider (fields and compiled kernels are kept)."""
        for body in list(self.slots.body_range):
            self.remove_body(body)
        self.slots.clear()
        self.bodies.slot_end[None] = 0
        self.particles.slot_end[None] = 0
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
        return sorted(self.slots.body_range)

    # ---------------------------------------------------------------- stepping

    def advance(self, frame_dt: float, substeps: int = 10) -> None:
        """Advance one frame of ``frame_dt`` [s]: :meth:`begin_frame`, every
        :meth:`substep`, :meth:`end_frame`. A caller that acts between substeps (the
        simulation's fracture inside a frame) runs those three itself."""
        count = self.begin_frame(frame_dt, substeps)
        for k in range(count):
            self.substep(frame_dt / count, k)
        self.end_frame()

    def begin_frame(self, frame_dt: float, substeps: int = 10) -> int:
        """Start a frame of ``frame_dt`` [s]; returns how many substeps it takes (0 when every
        body sleeps), each ``frame_dt / count`` long. At least ``substeps``; more are taken
        when a body that may touch something during the frame would otherwise move further
        than ``substep_motion_fraction`` of its mean collision-particle radius in one
        substep, up to ``max_substeps``. (Tunnelling is prevented by the speculative
        contacts at any substep length; the refinement keeps contacts accurate and the grid
        cells small.) Resets the frame's contact and impact counters; the caller then runs
        :meth:`substep` k = 0 .. count - 1 (a substep may be run again after a
        :meth:`restore`) and :meth:`end_frame`."""
        self._frame_started = time.perf_counter()
        opt = self.options
        self._impact_rows = None  # (read live while the frame runs: a fracture inside the frame)
        count = int(_begin_advance(self.fields, opt.contact_margin, frame_dt, int(substeps),
                                   opt.substep_motion_fraction))
        if count > opt.max_substeps:  # (0 when no one is awake)
            self.stats.substep_limit_hits += 1
            count = opt.max_substeps
        self._frame_substeps = count
        return count

    def end_frame(self) -> None:
        """End the frame :meth:`begin_frame` started: read its counters into ``stats`` and fix
        :meth:`impact_count` to the frame's rows."""
        count = self._frame_substeps
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
        self.stats.last_frame_seconds = time.perf_counter() - self._frame_started

    @property
    def has_contact_patches(self) -> bool:
        """Whether any body in the world has contact patches (added under
        ``surface_contact``): the collision stage compiles its patch code only then."""
        return bool(self.slots.point_range)

    def substep(self, dt: float, index: int) -> None:
        """Substep ``index`` (of the frame :meth:`begin_frame` started) of ``dt`` [s]:
        collision, then contact response and integration."""
        opt = self.options
        if self._params_of is not opt:
            self._write_params(opt)
        clock = self._clock()
        stages.collide(self.fields, opt.contact_margin, dt, opt.sleep_time, self.has_contact_patches)
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
        rows = np.zeros((len(ids), BODY_STATE.width), dtype=np.float64)
        if len(ids):
            body_fields.pack_bodies(self.bodies.motion_state, self.bodies.active,
                                    np.ascontiguousarray(ids, dtype=np.int32), rows)
        return _body_state(ids, rows)

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
        checkpoints.keep(self.fields, self.kept)
        self._checkpoint_token += 1
        return Checkpoint(ids=np.asarray(self.body_ids, dtype=np.int32), token=self._checkpoint_token)

    def restore(self, checkpoint: Checkpoint, ids) -> None:
        """Put bodies ``ids`` (each in the world now and in ``checkpoint``) back in their
        motion state of ``checkpoint``, and the contact cache (warm starting) back to that
        moment: the impulses stored since are no longer the valid half, so a substep run
        again warm-starts as it did. The other bodies are left as they are."""
        ids = np.asarray(ids, dtype=np.int64)
        missing = [int(b) for b in ids if int(b) not in self.slots.body_range]
        if missing:
            raise KeyError(f"bodies {missing} are not in the world")
        checkpoints.restore(self.fields, self.kept, self._checkpoint_ids(checkpoint, ids))

    def checkpoint_state(self, checkpoint: Checkpoint, ids) -> dict:
        """:meth:`body_state` of bodies ``ids`` as ``checkpoint`` holds them."""
        ids = np.asarray(ids, dtype=np.int64)
        rows = np.zeros((len(ids), BODY_STATE.width), dtype=np.float64)
        body_fields.pack_bodies(self.kept.motion, self.kept.active, self._checkpoint_ids(checkpoint, ids), rows)
        return _body_state(ids, rows)

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
        rows = np.zeros((n - first, IMPACT.width), dtype=np.float64)
        if n > first:
            body_fields.pack_impacts(self.impact_buffer, first, rows)
        return IMPACT.split(rows, integers=IMPACT_INTEGERS)

    def particle_state(self, body: int) -> dict:
        """World positions (K,3) [m] and radii (K,) [m] of one body's collision particles
        (tests, diagnostics; computed from the pose, not the broadphase buffer)."""
        start, count = self.slots.body_range[body]
        offsets = self.particles.offset.to_numpy()[start:start + count].astype(np.float64)
        radii = self.particles.radius.to_numpy()[start:start + count].astype(np.float64)
        state = self.body_state([body])
        rot = quaternion_matrix(state["orientation"][0])
        return dict(position=state["position"][0] + offsets @ rot.T, radius=radii)

    def _check_body(self, body: int) -> None:
        if body not in self.slots.body_range:
            raise KeyError(f"body {body} is not in the world")


def _body_state(ids: np.ndarray, rows: np.ndarray) -> dict:
    """The dict World.body_state returns from rows (K, BODY_STATE.width)."""
    state = dict(id=ids, **BODY_STATE.split(rows))
    state["active"] = state["active"] != 0
    state["sleeping"] = state["sleeping"] != 0
    return state
