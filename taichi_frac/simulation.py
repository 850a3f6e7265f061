"""Sequences a scene: rigid dynamics, fracture and output (the only place that knows all three).

One frame is: ``World.advance`` (broadphase, narrowphase, contact impulses, integration over
substeps) → the fracture stage (only for breakable bodies hit above their force threshold:
contact displacement, SPH stress, cracks, split into fragments that replace the parent in the
world) → the cache writer (one pose per live body). Each stage is timed; a stage a scene does
not use costs nothing (no breakable body: the fracture stage is never entered).
"""

from __future__ import annotations

import dataclasses
import gc
import json
import numbers
import time
import weakref
from dataclasses import dataclass, field

import numpy as np

from . import interrupts, runtime
from .kinematics.quaternion import quaternion_matrix
from .model import BodyModel
from .options import LOOKS, FractureOptions, Material, OptionError, ParticleOptions


class NonFinitePoseError(RuntimeError):
    """The simulation produced a NaN or infinite pose; the run stops (the cache keeps the
    frames before it, marked incomplete)."""


@dataclass
class BodyRecord:
    """What the simulation knows of a live (or ended) body beyond the World's fields."""

    name: str
    model: BodyModel
    root: BodyModel
    material: Material
    fracture: FractureOptions
    particles: ParticleOptions
    breakable: bool
    generation: int = 0
    cache_id: int | None = None
    parent: int | None = None
    birth_frame: int = 0
    friction: float = 0.5
    restitution: float = 0.2
    # Shading of the root's boundary faces (aligned with root.surface_faces), shared by
    # every fragment of it: normals (Fr,3,3), uvs (Fr,3,2) or None.
    root_normals: np.ndarray | None = None
    root_uvs: np.ndarray | None = None
    # What the cache draws (geometry/piece_surface.py), body frame: the artist's surface
    # cut along the cracks; None when no cache is written.
    render: object = None


@dataclass
class StageTimes:
    """Wall-clock seconds spent per stage over a run."""

    dynamics: float = 0.0
    fracture_analysis: float = 0.0
    fragment_split: float = 0.0
    output: float = 0.0

    def as_dict(self) -> dict:
        return {k: round(v, 6) for k, v in self.__dict__.items()}


@dataclass
class RunSummary:
    """The paper's Table 1 columns and what a run cost."""

    scene: str
    frames: int
    simulated_time: float
    physics_particles: int
    surface_particles: int
    boundary_particles: int
    fragments: int
    fractures: int
    wall_time: float
    stage_seconds: dict = field(default_factory=dict)
    dynamics_stage_seconds: dict = field(default_factory=dict)
    ms_per_frame: dict = field(default_factory=dict)
    interrupted: bool = False
    output: str | None = None
    mass_initial: float = 0.0
    mass_final: float = 0.0
    mass_dropped: float = 0.0
    resimulated_substeps: int = 0

    def to_json(self) -> str:
        return json.dumps(self.__dict__, indent=2, default=float)


def _strongest_per_pair(impacts: dict, bodies: np.ndarray) -> dict[int, np.ndarray]:
    """For each body in ``bodies``: row indices of its strongest impact per other body.

    Several substeps of one frame usually hold the same touch; the strongest (largest
    contact force, see dynamics/impacts.py) stands for it. Distinct others (the ground,
    another body, a wall) stay distinct: a body hit at several points in one frame is
    analysed with all of them at once.
    """
    force = np.linalg.norm(impacts["force"], axis=1)
    rows = np.nonzero(np.isin(impacts["body"], bodies))[0]
    if len(rows) == 0:
        return {}
    body = impacts["body"][rows].astype(np.int64)
    other = impacts["other"][rows].astype(np.int64)
    # Sort by (body, other, -force): the first row of each (body, other) run is its strongest.
    order = np.lexsort((-force[rows], other, body))
    body, other, rows = body[order], other[order], rows[order]
    first = np.ones(len(rows), dtype=bool)
    first[1:] = (body[1:] != body[:-1]) | (other[1:] != other[:-1])
    body, rows = body[first], rows[first]
    return {int(b): np.sort(rows[body == b]) for b in np.unique(body)}


# The shading attributes of a prepared model's boundary faces, kept while the model lives:
# a process that runs many variants of one scene reuses its models (Simulation(prepare=...),
# a sweep's worker), and finding them (closest points on the source surface) was nearly all
# of such a Simulation's set-up (1.43 of 1.44 s for the ring, profiled on a loaded machine).
# Read-only once computed.
_CORNER_ATTRIBUTES: "weakref.WeakKeyDictionary[BodyModel, tuple]" = weakref.WeakKeyDictionary()


def _root_corner_attributes(model: BodyModel, report) -> tuple:
    """(normals (Fr,3,3), uvs (Fr,3,2) or None) of ``model``'s boundary faces from its source surface."""
    if model not in _CORNER_ATTRIBUTES:
        from .geometry.surface_attributes import boundary_corner_attributes

        corners = model.vertices[model.surface_faces] + model.com_in_source
        _CORNER_ATTRIBUTES[model] = boundary_corner_attributes(report.surface, corners)
    return _CORNER_ATTRIBUTES[model]


class _FractureWatch:
    """Fracture inside the frame (``simulation.resimulate_fractures``), as the World's
    ``advance(watch=...)``: before each substep the bodies' motion state is kept; after
    it, the substep's impacts are analysed, and when a body breaks, the other bodies go
    back to their state before the substep, the pieces take the broken body's place, and
    the substep runs again, so the impact that broke the body meets its pieces (a
    projectile goes on through what it breaks). Impacts of the re-run are analysed too
    (pieces may break again), without a third run."""

    def __init__(self, sim: "Simulation", frame: int):
        self.sim, self.frame = sim, frame
        self.start = None
        self.first = 0
        self.count = 0  # impact rows of this advance when ``after`` last looked
        self.rerun = False
        self.analysed: dict = {}  # (body, other) -> largest force analysed this frame [N]
        self.seconds = 0.0  # spent in fracture stages [s]

    def before(self, k: int) -> None:
        # On the device: a host snapshot before every substep would cost milliseconds a
        # frame. The impact count is the one ``after`` read (advance resets it to 0 before
        # the first substep), not a second read of the same number.
        self.start = self.sim.world.checkpoint()
        self.first = 0 if k == 0 else self.count

    def after(self, k: int) -> bool:
        world = self.sim.world
        self.count = world.impact_count()
        if self.count == self.first:
            self.rerun = False
            return False
        t = time.perf_counter()
        start = None if self.rerun else self.start
        born = self.sim._fracture_stage(self.frame, start, self.first, self.analysed)
        self.seconds += time.perf_counter() - t
        if self.rerun or not born:
            self.rerun = False
            return False
        live, new = set(world.body_ids), set(born)
        world.restore(self.start, [b for b in self.start.ids if b in live and b not in new])
        self.first = self.count = world.impact_count()
        self.rerun = True
        self.sim.resimulated_substeps += 1
        return True


class Simulation:
    """Runs a :class:`~taichi_frac.scenes.Scene` end to end.

    Usage::

        sim = Simulation(load_scene("scenes/single_ring.toml"))
        summary = sim.run()                  # writes scene.output_path
        print(summary.fragments)

    Args:
        scene: the scene.
        output: cache path overriding the scene's (None: the scene's; False: write nothing).
        arch: Taichi backend overriding ``scene.simulation.arch``.
        progress: callable(frame, frame_count, simulated_time, fragments, frames_per_second)
            called after every frame, or None.
        single_scale: override the scene's single_scale setting (benchmarks).
        fracture: False disables the fracture stage (every body unbreakable).
        frames: simulate this many frames instead of duration x fps.
        world: an existing World to reuse (cleared first; its capacities must suffice):
            its kernels are already compiled, so a second scene in one process starts at once.
        overwrite: write the output even while another run holds its lock file.

    The output path is checked and locked (``io.output``) before any object is meshed.
        prepare: callable(SceneObject) -> (BodyModel, PrepareReport) used instead of
            ``obj.prepare()``: a memo kept by a process that runs many variants of one scene
            (a sweep's worker), so those that change no geometry reuse the model and its SPH
            neighbour lists. The model must not be changed by the caller between runs.
    """

    def __init__(self, scene, *, output=None, arch: str | None = None, progress=None,
                 single_scale: bool | None = None, fracture: bool = True, frames: int | None = None,
                 world=None, overwrite: bool = False, prepare=None):
        self.scene = scene
        sim = scene.simulation
        if frames is not None and (not isinstance(frames, numbers.Integral) or frames < 1):
            raise OptionError(f"frames = {frames!r}: simulate at least 1 frame")
        self.frame_count = int(frames if frames is not None else sim.frame_count)
        self.frame_dt = sim.frame_dt
        self.progress = progress
        self.fracture_enabled = bool(fracture)
        self.times = StageTimes()
        self.records: dict[int, BodyRecord] = {}
        self.fracture_events = 0
        self.resimulated_substeps = 0
        self.mass_dropped = 0.0
        self.prepare_reports = []
        # Per split that cut a render solid: (seconds, geometry/piece_surface.py's counts).
        self.render_cuts: list[tuple[float, dict]] = []
        self._tet_peak_stress: dict[int, np.ndarray] = {}
        if output is None:
            output = scene.output_path
        self.output_path = None if output is False else output
        self._lock = None
        self._prepare = prepare
        if self.output_path is not None:
            from .io.output import OutputLock, check_output_path

            check_output_path(self.output_path)
            self._lock = OutputLock(self.output_path)
            self._lock.acquire(overwrite=overwrite)
        try:
            self._build(scene, arch, single_scale, world)
        except BaseException:
            if self._lock is not None:
                self._lock.release()
            raise

    def _build(self, scene, arch, single_scale, world):
        from .dynamics import DynamicsOptions, World, WorldCapacity

        sim = scene.simulation
        # The arch first: preparing a breakable body runs kernels (its SPH neighbour lists),
        # and the first kernel fixes the process's arch. A World given brings its own.
        if world is None or arch is not None:
            runtime.init(arch or sim.arch)

        t0 = time.perf_counter()
        prepared = []
        for obj in scene.objects:
            interrupts.check()
            model, report = obj.prepare() if self._prepare is None else self._prepare(obj)
            prepared.append((obj, model))
            self.prepare_reports.append(report)
            if obj.breakable and self.fracture_enabled:
                # The SPH neighbour lists are part of a breakable body's static model (the
                # paper's preprocessing); its fragments' are restricted from them.
                from .fracture.cracks import model_neighbor_lists, smoothing_length

                model_neighbor_lists(model, smoothing_length(model, obj.fracture))
                if obj.fracture.stress_model == "fem":  # its stiffness, factorised once
                    from .fracture.fem import elastic_body_of

                    elastic_body_of(model, obj.material)
        self.prepare_seconds = time.perf_counter() - t0

        breakable = [m for o, m in prepared if o.breakable and self.fracture_enabled]
        # Fragments add crack faces, so their boundary layers hold more particles than the
        # parent's: room for about four times the breakable bodies' boundary particles.
        particles_now = sum(
            (m.surface_particle_count if (single_scale or sim.single_scale) else m.boundary_particle_count)
            for _, m in prepared
        )
        extra = sum(4 * m.boundary_particle_count + m.surface_particle_count for m in breakable)
        capacity = WorldCapacity(
            max_bodies=max(64, len(prepared) + 256 * len(breakable)),
            max_boundary_particles=max(1024, particles_now + extra),
            # 4 per particle of that room: the scenes peak far below it (13 rings with
            # fracture: 5,693 contacts against 205k), and each contact slot costs ~220 B
            # (the 1M-particle scaling case peaked at 3.2 GB with 8 per particle).
            max_contacts=max(65536, 4 * (particles_now + extra)),
            max_static_boxes=max(4, sum(c.type == "box" for c in scene.colliders)),
        )
        overrides = {} if single_scale is None else {"single_scale": bool(single_scale)}
        thresholds = [o.fracture.impact_force_threshold for o, _ in prepared if o.breakable]
        overrides["record_force_threshold"] = min(thresholds) if thresholds else 0.0
        options = DynamicsOptions.from_simulation(sim, **overrides)
        if world is None:
            self.world = World(capacity, options, arch=arch or sim.arch)
        else:
            for name in ("max_bodies", "max_boundary_particles", "max_static_boxes"):
                if getattr(world.capacity, name) < getattr(capacity, name):
                    raise ValueError(f"the World given has {name}={getattr(world.capacity, name)}, this scene "
                                     f"needs {getattr(capacity, name)}")
            world.clear()
            world.set_options(options)
            self.world = world
        for c in scene.colliders:
            if c.type == "ground":
                self.world.add_ground(c.height, friction=c.friction, restitution=c.restitution)
            else:
                self.world.add_static_box(c.center, c.half_extents, c.orientation, friction=c.friction,
                                          restitution=c.restitution)
        for (obj, model), report in zip(prepared, self.prepare_reports):
            body = self.world.add_body(
                model, obj.position, obj.orientation, obj.linear_velocity, obj.angular_velocity,
                friction=obj.friction, restitution=obj.restitution,
                breakable=obj.breakable and self.fracture_enabled,
                young_modulus=obj.material.young_modulus, poisson_ratio=obj.material.poisson_ratio,
            )
            self.records[body] = BodyRecord(
                name=obj.name, model=model, root=model, material=obj.material, fracture=obj.fracture,
                particles=obj.particles, breakable=obj.breakable and self.fracture_enabled,
                friction=obj.friction, restitution=obj.restitution,
            )
            if report.surface is not None and self.output_path is not None:
                rec = self.records[body]
                rec.root_normals, rec.root_uvs = _root_corner_attributes(model, report)
            if self.output_path is not None:
                from .geometry.piece_surface import render_solid_from_surface, render_solid_from_tets

                rec = self.records[body]
                rec.render = (render_solid_from_tets(model) if report.surface is None else
                              render_solid_from_surface(report.surface, model.com_in_source, model.spacing))
        self.initial_mass = sum(r.model.mass for r in self.records.values())
        self._dynamics_seconds_at_start = dict(self.world.stats.seconds)  # a reused World keeps counting
        self.table1 = dict(
            physics_particles=sum(r.model.tet_count for r in self.records.values() if r.breakable),
            surface_particles=sum(r.model.surface_particle_count for r in self.records.values() if r.breakable),
            boundary_particles=sum(r.model.boundary_particle_count for r in self.records.values() if r.breakable),
        )
        self.writer = None
        interrupts.check()  # (a Ctrl-C swallowed while the World compiled)

    # ------------------------------------------------------------------ output

    def _open_cache(self):
        from .io.cache import CacheWriter

        out = self.scene.output
        # (checkpoint_every 0: only the final write, and Ctrl-C's)
        self.writer = CacheWriter(self.output_path, fps=self.scene.simulation.fps, start_frame=0,
                                  checkpoint_every=out.checkpoint_every or 2**31 - 1,
                                  checkpoint_seconds=out.checkpoint_seconds, lock=self._lock)
        for rec in self.records.values():
            self._add_to_cache(rec, birth_frame=0)
        self._write_frame(0)

    def _add_to_cache(self, rec: BodyRecord, birth_frame: int, parent_cache=None, impact=None, peak=0.0,
                      tet_peak=None):
        from .io.fragment_mesh import fragment_surface, render_surface, root_faces_of, surface_corner_attributes

        look = None if parent_cache is not None else LOOKS[rec.material.look]  # (pieces share the body's)
        if rec.render is not None:
            vertices, faces, inner, normals, uvs, face_peak = render_surface(rec.render, rec.model, tet_peak)
            rec.cache_id = self.writer.add_fragment(
                rec.name, vertices, faces, inner, birth_frame, parent=parent_cache, impact=impact,
                peak_principal_stress=float(peak), face_peak_stress=face_peak, normals=normals, uvs=uvs,
                shade_inner=True, look=look,
            )
            return
        # A piece the render solid gave no part to: its tets' boundary.
        face_peak = None if tet_peak is None else tet_peak[rec.model.surface_face_tet]
        root_faces = root_faces_of(rec.model, rec.root)  # (both calls below need it)
        vertices, faces, inner = fragment_surface(rec.model, rec.root, root_faces)
        normals = uvs = None
        if rec.root_normals is not None:
            normals, uvs = surface_corner_attributes(rec.model, rec.root, rec.root_normals, rec.root_uvs, root_faces)
        rec.cache_id = self.writer.add_fragment(
            rec.name, vertices, faces, inner, birth_frame, parent=parent_cache, impact=impact,
            peak_principal_stress=float(peak), face_peak_stress=face_peak, normals=normals, uvs=uvs,
            look=look,
        )

    def _write_frame(self, frame: int):
        if self.writer is None:
            return
        t = time.perf_counter()
        ids = self.world.body_ids
        state = self.world.body_state(ids)
        self._check_finite_poses(frame, ids, state)
        cache_ids = [self.records[b].cache_id for b in ids]
        self.writer.write_frame(frame, cache_ids, state["position"], state["orientation"])
        self._checkpoint_if_due(frame)
        self.times.output += time.perf_counter() - t

    def _check_finite_poses(self, frame: int, ids, state) -> None:
        """Raise NonFinitePoseError naming the first body whose pose is NaN or infinite."""
        ok = np.all(np.isfinite(state["position"]), axis=1) & np.all(np.isfinite(state["orientation"]), axis=1)
        if not np.all(ok):
            k = int(np.argmin(ok))
            kept = (f"the cache keeps frames 0-{frame - 1}, marked incomplete" if self.writer is not None
                    else "no cache was written")
            raise NonFinitePoseError(
                f"frame {frame}: body {self.records[ids[k]].name!r} has a non-finite pose (position "
                f"{state['position'][k].tolist()}); the simulation stopped and {kept}. Look for extreme speeds, "
                "sizes or material values in the scene")

    def _checkpoint_if_due(self, frame: int) -> None:
        """Besides the writer's every-N-frames rule: right after the first simulated frame,
        then whenever ``checkpoint_seconds`` of wall time have passed, however slow the frames
        (the first frame compiles kernels: minutes on a cold cache). A kill then loses at most
        that much work."""
        out = self.scene.output
        if out.checkpoint_every == 0 or self.writer.frames_since_write == 0:
            return
        if frame == 1 or (out.checkpoint_seconds > 0 and self.writer.seconds_since_write >= out.checkpoint_seconds):
            self.writer.checkpoint()

    # ------------------------------------------------------------------ fracture

    def _fracture_stage(self, frame: int, start=None, first: int = 0, analysed: dict | None = None) -> list[int]:
        """Analyse the impacts recorded since row ``first`` of this advance, split the
        bodies that crack; returns the new pieces' body ids. ``start``: a World checkpoint
        from before those impacts; the pieces are then put where their parent was then
        (``resimulate_fractures``: see ``_FractureWatch``). ``analysed``: (body, other) ->
        the largest force [N] already analysed for that pair in this frame without a crack;
        a pair's impact no stronger is not analysed again (and the dict is updated)."""
        from .fracture.cracks import analyze_impact
        from .fracture.fragments import fragment_peak_stress, make_fragments, split_body

        born: list[int] = []
        if self.world.impact_count() <= first:  # (most frames: no impact, nothing to look at)
            return born
        live = set(self.world.body_ids)
        breakable = np.array([b for b, r in self.records.items() if r.breakable and b in live])
        if len(breakable) == 0:
            return born
        impacts = self.world.impacts(first)
        if len(impacts["body"]) == 0:
            return born
        per_body = _strongest_per_pair(impacts, breakable)
        for body, rows in per_body.items():
            rec = self.records[body]
            force = impacts["force"][rows]
            strong = np.linalg.norm(force, axis=1) >= max(rec.fracture.impact_force_threshold, 1e-12)
            if not np.any(strong):
                continue
            rows, force = rows[strong], force[strong]
            if analysed is not None:
                size = np.linalg.norm(force, axis=1)
                pairs = [(body, int(o)) for o in impacts["other"][rows]]
                if all(size[i] <= analysed.get(p, -1.0) for i, p in enumerate(pairs)):
                    continue  # the same touch, no stronger than one that cracked nothing
            t = time.perf_counter()
            # In the body's frame at the impact's substep: the body may move far by the
            # frame's end (a struck glass wall, 17 mm).
            points_b, normals_b = impacts["point_body"][rows], impacts["normal_body"][rows]
            force_b = impacts["force_body"][rows]
            analysis = analyze_impact(rec.model, points_b, normals_b, force_b, rec.material, rec.fracture,
                                      full_field=False)
            self.times.fracture_analysis += time.perf_counter() - t
            if not analysis.any_crack:
                if analysed is not None:
                    for i, p in enumerate(pairs):
                        analysed[p] = max(analysed.get(p, 0.0), float(size[i]))
                continue
            t = time.perf_counter()
            split = split_body(rec.model, analysis, rec.fracture)
            if split.fragment_count + (1 if split.dropped_mass > 0 else 0) <= 1:
                self.times.fragment_split += time.perf_counter() - t
                continue
            if analysis.field_particles is not None and self.writer is not None:
                # A crack of given length was found from the stress near the contacts; the
                # pieces' peak stress (the cache's per-face stress) reads the whole field,
                # computed only now that the cracks do split the body (in the 13 rings, 20
                # of 33 cracking impacts split nothing and skip it), and only when a cache
                # is written: nothing else reads it. The cracks, hence the split, are the same.
                self.times.fragment_split += time.perf_counter() - t
                t = time.perf_counter()
                analysis = analyze_impact(rec.model, points_b, normals_b, force_b, rec.material, rec.fracture,
                                          full_field=True)
                split = dataclasses.replace(split, fragment_peak_stress=fragment_peak_stress(
                    split.fragment_tets, analysis.particle_principal_stress))
                self.times.fracture_analysis += time.perf_counter() - t
                t = time.perf_counter()
            # The pieces start where the body is now, or was before the substep run again.
            state = self.world.body_state([body]) if start is None else self.world.checkpoint_state(start, [body])
            pieces = make_fragments(
                rec.model, split, state["position"][0], state["orientation"][0], state["linear_velocity"][0],
                state["angular_velocity"][0],
                rec.material, rec.particles, options=rec.fracture, analysis=analysis, birth_frame=frame,
                parent=body, parent_generation=rec.generation,
            )
            peak_parent = None
            if self.writer is not None:
                peak_parent = np.maximum(self._tet_peak_stress.get(body, np.zeros(rec.model.tet_count)),
                                         analysis.particle_principal_stress)
            renders = [None] * len(pieces)
            if rec.render is not None:
                from .geometry.piece_surface import cut_render_solid

                t_cut = time.perf_counter()
                renders, counts = cut_render_solid(
                    rec.render, rec.model, split.fragment_tets, analysis.cracks,
                    [p.model.com_in_source for p in pieces], roughness=rec.fracture.crack_roughness,
                    roughness_scale=rec.fracture.crack_roughness_scale, seed=rec.fracture.seed)
                self.render_cuts.append((time.perf_counter() - t_cut, counts))
            self.world.remove_body(body)
            if analysed is not None:  # its slot may go to a piece: forget what it went through
                for key in [key for key in analysed if body in key]:
                    del analysed[key]
            if self.writer is not None:
                self.writer.end_fragment(rec.cache_id, frame)
            self.mass_dropped += split.dropped_mass
            self.fracture_events += 1
            pieces = [self._lift_out_of_ground(piece) for piece in pieces]
            children = self.world.add_bodies(
                [p.model for p in pieces], [p.position for p in pieces], [p.orientation for p in pieces],
                [p.linear_velocity for p in pieces], [p.angular_velocity for p in pieces], friction=rec.friction,
                restitution=rec.restitution, breakable=[p.breakable for p in pieces],
                young_modulus=rec.material.young_modulus, poisson_ratio=rec.material.poisson_ratio,
            )
            for k, (piece, child) in enumerate(zip(pieces, children)):
                child_rec = BodyRecord(
                    name=f"{rec.name}_{k}", model=piece.model, root=rec.root, material=rec.material,
                    fracture=rec.fracture, particles=rec.particles, breakable=piece.breakable,
                    generation=piece.generation, parent=body, birth_frame=frame, friction=rec.friction,
                    restitution=rec.restitution, root_normals=rec.root_normals, root_uvs=rec.root_uvs,
                    render=renders[k],
                )
                # The world may hand the parent's freed slot to a child: the parent's record
                # is no longer needed (its cache id and peak stress are held above).
                self.records[child] = child_rec
                born.append(child)
                if self.writer is not None:
                    tet_peak = peak_parent[piece.parent_tets]
                    self._tet_peak_stress[child] = tet_peak
                    impact = None if piece.impact is None else dict(point=piece.impact.point, force=piece.impact.force)
                    self._add_to_cache(child_rec, frame, parent_cache=rec.cache_id, impact=impact,
                                       peak=piece.peak_principal_stress, tet_peak=tet_peak)
            self.times.fragment_split += time.perf_counter() - t
        return born

    def _lift_out_of_ground(self, piece):
        """Move a new fragment up out of the ground planes if its collision spheres start
        inside one. A fragment's boundary layer is built afresh (its crack faces are new
        surface), so its spheres need not match the parent's, which the solver had kept out
        of the ground; without this a piece born at the moment of impact can start up to a
        few millimetres deep and be shot out by the position correction. The shift is
        vertical and smaller than one boundary particle radius; velocities are untouched."""
        grounds = [c.height for c in self.scene.colliders if c.type == "ground"]
        if not grounds:
            return piece
        m = piece.model
        rot = quaternion_matrix(piece.orientation)
        lowest = np.min(piece.position[2] + m.collision_position @ rot[2] - m.boundary_radius)
        depth = max(grounds) - lowest
        allowed = self.world.options.allowed_penetration * float(m.boundary_radius.mean())
        if depth > allowed:
            piece = dataclasses.replace(piece, position=piece.position + np.array([0.0, 0.0, depth - allowed]))
        return piece

    # ------------------------------------------------------------------ loop

    @property
    def fragment_count(self) -> int:
        """Live pieces made by fracture (the paper's Table 1 'fragments' column)."""
        return sum(1 for b in self.world.body_ids if self.records[b].generation > 0)

    def run(self) -> RunSummary:
        """Simulate every frame; Ctrl-C stops cleanly with a valid cache of the frames done.

        The objects alive when the run starts (Taichi's, the models', the scene's: ~10^5)
        are frozen out of Python's cyclic garbage collector for the run (``gc.freeze``,
        undone at the end): otherwise each full collection walks them all, a pause of tens
        of milliseconds inside a frame."""
        start = time.perf_counter()
        interrupted = False
        failed = True  # until the loop ends: an exception leaves the cache incomplete
        sim = self.scene.simulation
        frame_ms: list[float] = []
        done = 0  # frames simulated and written (a Ctrl-C may land anywhere in a frame)
        gc.collect()
        gc.freeze()
        try:
            if self.output_path is not None:
                self._open_cache()
            resimulate = self.fracture_enabled and sim.resimulate_fractures
            for frame in range(1, self.frame_count + 1):
                t_frame = time.perf_counter()
                t = time.perf_counter()
                watch = _FractureWatch(self, frame) if resimulate else None
                self.world.advance(self.frame_dt, sim.substeps, watch=watch)
                # (the watch's fracture stages are timed as analysis and split, not dynamics)
                self.times.dynamics += time.perf_counter() - t - (watch.seconds if watch else 0.0)
                if self.fracture_enabled and not resimulate:
                    self._fracture_stage(frame)
                self._write_frame(frame)
                done = frame
                frame_ms.append(1000.0 * (time.perf_counter() - t_frame))
                if self.progress is not None:
                    elapsed = time.perf_counter() - start
                    self.progress(frame, self.frame_count, frame * self.frame_dt, self.fragment_count,
                                  frame / max(elapsed, 1e-9))
                interrupts.check()  # (a Ctrl-C that a library swallowed)
            if self.writer is None:  # (with a cache every frame was checked as it was written)
                ids = self.world.body_ids
                self._check_finite_poses(done, ids, self.world.body_state(ids))
            failed = False
        except KeyboardInterrupt:
            interrupted = True
            failed = False
        finally:
            gc.unfreeze()
            try:
                if self.writer is not None:
                    t = time.perf_counter()
                    # complete only when every requested frame was written
                    self.writer.close(complete=not failed and not interrupted and done == self.frame_count)
                    self.times.output += time.perf_counter() - t
            finally:
                if self._lock is not None:
                    self._lock.release()
        return self._summary(done, frame_ms, time.perf_counter() - start, interrupted)

    def _summary(self, frames: int, frame_ms: list[float], wall: float, interrupted: bool) -> RunSummary:
        ws = self.world.stats
        live = self.world.body_ids
        ms = np.asarray(frame_ms) if frame_ms else np.zeros(1)
        dynamics_seconds = {k: v - self._dynamics_seconds_at_start.get(k, 0.0) for k, v in ws.seconds.items()}
        return RunSummary(
            scene=self.scene.name,
            frames=frames,
            simulated_time=frames * self.frame_dt,
            physics_particles=self.table1["physics_particles"],
            surface_particles=self.table1["surface_particles"],
            boundary_particles=self.table1["boundary_particles"],
            fragments=self.fragment_count,
            fractures=self.fracture_events,
            wall_time=wall,
            stage_seconds=self.times.as_dict() | {"prepare": round(self.prepare_seconds, 6)},
            dynamics_stage_seconds={k: round(v, 6) for k, v in dynamics_seconds.items()},
            # first: in a new process, the frame that launches the dynamics kernels for the
            # first time (Taichi's front end runs then, ~1-2 s even with the offline cache
            # warm); the first impact's frame does the same for the fracture kernels.
            ms_per_frame=dict(mean=float(ms.mean()), max=float(ms.max()), median=float(np.median(ms)),
                              first=float(ms[0]), mean_after_first=float(ms[1:].mean()) if len(ms) > 1 else None,
                              max_after_first=float(ms[1:].max()) if len(ms) > 1 else None),
            interrupted=interrupted,
            output=None if self.output_path is None else str(self.output_path),
            mass_initial=self.initial_mass,
            mass_final=sum(self.records[b].model.mass for b in live),
            mass_dropped=self.mass_dropped,
            resimulated_substeps=self.resimulated_substeps,
        )
