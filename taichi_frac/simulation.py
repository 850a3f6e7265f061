"""Sequences a scene: rigid dynamics, fracture and output (the only place that knows all three).

One frame is: the World's substeps (broadphase, narrowphase, contact impulses, integration;
``World.begin_frame`` / ``substep`` / ``end_frame``) → the fracture stage
(``fracture/stage.py``: only for breakable bodies hit above their force threshold: contact
displacement, stress, cracks, split into fragments that replace the parent in the world) →
the piece surfaces (``surfaces/``: each split's pieces cut from their parent's render
solid, only when a cache is written, in worker processes the loop does not wait for) →
the recorder (``io/recorder.py``: one pose per live body, the pieces' surfaces, written as
the surfaces are done). With
``resimulate_fractures`` the stage runs after every substep instead, and this loop runs a
substep again after a split, so the impact that broke a body meets its pieces. Each stage
is timed; a stage a scene does not use costs nothing (no breakable body: the fracture stage
finds nothing to analyse).
"""

from __future__ import annotations

import gc
import json
import numbers
import time
from dataclasses import dataclass, field

import numpy as np

from . import interrupts, runtime
from .blas import one_blas_thread
from .fracture.stage import BodyRecord, FractureStage
from .options import LOOKS, OptionError

__all__ = ["BodyRecord", "NonFinitePoseError", "RunSummary", "Simulation", "StageTimes"]

#: Whether a run has started in this process (the first one's garbage is not worth a full
#: collection: ``Simulation._run``).
_RUNS_STARTED = False


class NonFinitePoseError(RuntimeError):
    """The simulation produced a NaN or infinite pose; the run stops (the cache keeps the
    frames before it, marked incomplete)."""


@dataclass
class StageTimes:
    """Wall-clock seconds spent per stage over a run. ``render_surfaces`` is the time spent
    cutting the pieces' render surfaces along the cracks (only a run that writes a cache
    cuts them): part of ``fragment_split`` when they are cut in this process, the workers'
    time otherwise, of which the run waited ``surfaces_wait`` at its end."""

    dynamics: float = 0.0
    fracture_analysis: float = 0.0
    fragment_split: float = 0.0
    render_surfaces: float = 0.0
    surfaces_wait: float = 0.0
    output: float = 0.0

    def as_dict(self) -> dict:
        return {k: round(v, 6) for k, v in self.__dict__.items()}


@dataclass
class RunSummary:
    """The paper's Table 1 columns and what a run cost. ``events``: one dict per split
    (``fracture.stage.impact_event``: frame, body, speed [m/s], energy [J], force [N],
    cracks, ring_cracks, pieces)."""

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
    surface_workers: int = 0
    events: list = field(default_factory=list)

    def to_json(self) -> str:
        return json.dumps(self.__dict__, indent=2, default=float)


class Simulation:
    """Runs a :class:`~taichi_frac.scenes.Scene` end to end.

    Usage::

        sim = Simulation(load_scene("single_ring"))
        summary = sim.run()                  # writes scene.output_path
        print(summary.fragments)

    Args:
        scene: the scene.
        output: cache path overriding the scene's (None: the scene's; False: write nothing).
        arch: Taichi backend overriding ``scene.simulation.arch``.
        progress: callable(frame, frame_count, simulated_time, fragments, frames_per_second)
            called after every frame, or None.
        surfaces_progress: callable(left, splits) called while the run, its frames done,
            waits for the pieces' surfaces still being cut: ``left`` of the ``splits`` it
            found unfinished, once at the start of the wait and again each time one is
            written; or None.
        single_scale: override the scene's single_scale setting (benchmarks).
        fracture: False disables the fracture stage (every body unbreakable).
        frames: simulate this many frames instead of duration x fps.
        world: an existing World to reuse (cleared first; its capacities must suffice):
            its kernels are already compiled, so a second scene in one process starts at once.
            None: the World of this process's last ended run when it has the room (so a
            second run pays for no World and no kernels), else a new one. A finished run's
            results are its summary and its cache; its ``world`` belongs to the next run.
        overwrite: write the output even while another run holds its lock file.

    The output path is checked and locked (``io.output``) before any object is meshed.
        prepare: callable(SceneObject, *, surface_contact) -> (BodyModel, PrepareReport)
            used instead of ``scene_setup.prepare_object`` (this process's memo of prepared
            models, so runs that change no geometry reuse the model and its SPH neighbour
            lists). The model must not be changed by the caller between runs.
        surface_workers: worker processes that cut the pieces' render surfaces while the
            frames go on (0: in this process, between frames); None: four, or one per core on
            more, at most one per breakable object (``surfaces.pool.default_worker_count``).
            Workers are forked from this process and stay idle after the run for the next run
            in it, whose repeated splits they answer from their memos. The cache is the same
            either way, whichever worker cuts a split.

    Attributes (for benches and tests): ``world``; ``records`` (body id -> BodyRecord, every
    body that lived); ``fracture_stage`` (``fracture.stage.FractureStage``, None without
    fracture); ``recorder`` (``io.recorder.CacheRecorder``, None without a cache);
    ``surfaces`` (``surfaces.pool.SurfaceWorkers`` or ``InProcessSurfaces``, None without a
    cache);
    ``fracture_events``, ``mass_dropped``, ``resimulated_substeps``, ``render_cuts``,
    ``times`` (StageTimes).
    """

    def __init__(self, scene, *, output=None, arch: str | None = None, progress=None,
                 single_scale: bool | None = None, fracture: bool = True, frames: int | None = None,
                 world=None, overwrite: bool = False, prepare=None, surface_workers: int | None = None,
                 surfaces_progress=None):
        self.scene = scene
        sim = scene.simulation
        if frames is not None and (not isinstance(frames, numbers.Integral) or frames < 1):
            raise OptionError(f"frames = {frames!r}: simulate at least 1 frame")
        self.frame_count = int(frames if frames is not None else sim.frame_count)
        self.frame_dt = sim.frame_dt
        self.progress = progress
        self.surfaces_progress = surfaces_progress
        self.fracture_enabled = bool(fracture)
        self.times = StageTimes()
        self.records: dict[int, BodyRecord] = {}
        self.resimulated_substeps = 0
        self.events: list[dict] = []  # one per split (fracture.stage.impact_event)
        self.prepare_reports = []
        self.fracture_stage: FractureStage | None = None  # (fracture enabled)
        self.recorder = None  # io.recorder.CacheRecorder (a cache is written)
        self.surfaces = None  # surfaces.pool's stage (a cache is written)
        self._surface_workers = surface_workers
        if output is None:
            output = scene.output_path
        self.output_path = None if output is False else output
        self._lock = None
        self._prepare = prepare
        self.world = None
        t_build = time.perf_counter()
        try:
            if self.output_path is not None:
                from .io.output import OutputLock, check_output_path

                check_output_path(self.output_path)
                lock = OutputLock(self.output_path)
                # A Ctrl-C between the lock file's writing and its holder knowing it would
                # leave the file behind: it is raised once the lock is ours to give back.
                with interrupts.deferred():
                    lock.acquire(overwrite=overwrite)
                    self._lock = lock
            with one_blas_thread():  # (as the run: beside the workers' first jobs, see run)
                self._build(scene, arch, single_scale, world)
            self.setup_seconds = time.perf_counter() - t_build - self.prepare_seconds
        except BaseException:
            self._release()
            raise

    def _build(self, scene, arch, single_scale, world):
        from .scene_setup import dynamics_options, furnish_world, prepare_objects, world_capacity

        sim = scene.simulation
        # The arch first: preparing a breakable body runs kernels (its SPH neighbour lists),
        # and the first kernel fixes the process's arch. A World given brings its own.
        if world is None or arch is not None:
            runtime.init(arch or sim.arch)
        if self.output_path is not None:
            # Before the objects are prepared: worker processes start while this one meshes.
            from .surfaces.pool import InProcessSurfaces, SurfaceWorkers, default_worker_count

            workers = self._surface_workers
            if workers is None:
                workers = default_worker_count(sum(o.breakable for o in scene.objects) if self.fracture_enabled else 0)
            self.surfaces = SurfaceWorkers(workers) if workers > 0 else InProcessSurfaces()
        prepared, self.prepare_seconds = prepare_objects(scene, fracture=self.fracture_enabled,
                                                         prepare=self._prepare)
        self.prepare_reports = [p.report for p in prepared]
        self._initial_surfaces = []  # (body, name, look, surfaces.BodySurface): the cache's first bodies
        self.world = furnish_world(scene, world_capacity(scene, prepared, single_scale=single_scale),
                                   dynamics_options(scene, single_scale=single_scale), arch=arch, world=world)
        if self.output_path is not None:
            from .io.recorder import CacheRecorder

            out = scene.output
            self.recorder = CacheRecorder(self.output_path, fps=sim.fps, checkpoint_every=out.checkpoint_every,
                                          checkpoint_seconds=out.checkpoint_seconds, lock=self._lock)
        for p in prepared:
            obj, model = p.obj, p.model
            body = self.world.add_body(
                model, obj.position, obj.orientation, obj.linear_velocity, obj.angular_velocity,
                friction=obj.friction, restitution=obj.restitution,
                breakable=p.breakable,
                young_modulus=obj.material.young_modulus, poisson_ratio=obj.material.poisson_ratio,
            )
            self.records[body] = BodyRecord(
                name=obj.name, model=model, root=model, material=obj.material, fracture=obj.fracture,
                particles=obj.particles, breakable=p.breakable,
                friction=obj.friction, restitution=obj.restitution,
            )
            if self.surfaces is not None:
                self._initial_surfaces.append((body, obj.name, LOOKS[obj.material.look],
                                               self.surfaces.add_body(body, model, p.report.surface)))
        self.initial_mass = sum(r.model.mass for r in self.records.values())
        self._dynamics_seconds_at_start = dict(self.world.stats.seconds)  # a reused World keeps counting
        self.table1 = dict(
            physics_particles=sum(r.model.tet_count for r in self.records.values() if r.breakable),
            surface_particles=sum(r.model.surface_particle_count for r in self.records.values() if r.breakable),
            boundary_particles=sum(r.model.boundary_particle_count for r in self.records.values() if r.breakable),
        )
        if self.fracture_enabled:
            self.fracture_stage = FractureStage(
                self.world, self.records, ground_heights=[c.height for c in scene.colliders if c.type == "ground"],
                # The pieces' peak stress reads the whole field: only the cache draws it.
                field_stress=self.recorder is not None, skip_repeats=sim.resimulate_fractures, times=self.times)
        interrupts.check()  # (a Ctrl-C swallowed while the World compiled)

    # ------------------------------------------------------------------ output

    def _open_cache(self):
        self.recorder.open(self._initial_surfaces)
        self._write_frame(0)

    def _write_frame(self, frame: int):
        if self.recorder is None:
            return
        t = time.perf_counter()
        ids = self.world.body_ids
        state = self.world.body_state(ids)
        self._check_finite_poses(frame, ids, state)
        self.recorder.write_frame(frame, ids, state)
        self.times.output += time.perf_counter() - t

    def _check_finite_poses(self, frame: int, ids, state) -> None:
        """Raise NonFinitePoseError naming the first body whose pose is NaN or infinite."""
        ok = np.all(np.isfinite(state["position"]), axis=1) & np.all(np.isfinite(state["orientation"]), axis=1)
        if not np.all(ok):
            k = int(np.argmin(ok))
            kept = (f"the cache keeps frames 0-{frame - 1}, marked incomplete" if self.recorder is not None
                    else "no cache was written")
            raise NonFinitePoseError(
                f"frame {frame}: body {self.records[ids[k]].name!r} has a non-finite pose (position "
                f"{state['position'][k].tolist()}); the simulation stopped and {kept}. Look for extreme speeds, "
                "sizes or material values in the scene")

    # ------------------------------------------------------------------ frame

    def _step_frame(self, frame: int) -> None:
        """Advance the World one frame, the fracture stage after it or, with
        ``resimulate_fractures``, after each substep."""
        t = time.perf_counter()
        if self.fracture_stage is not None and self.scene.simulation.resimulate_fractures:
            fracture_seconds = self._substeps_with_fracture(frame)
            # (the stage's time is counted as analysis and split, not dynamics)
            self.times.dynamics += time.perf_counter() - t - fracture_seconds
            return
        self.world.advance(self.frame_dt, self.scene.simulation.substeps)
        self.times.dynamics += time.perf_counter() - t
        if self.fracture_stage is not None:
            self.fracture_stage.begin_frame()
            self._record(self.fracture_stage.run(frame))

    def _substeps_with_fracture(self, frame: int) -> float:
        """One frame with the fracture stage after every substep that recorded impacts. When
        a body breaks, the other bodies go back to their state before the substep, the pieces
        take the broken body's place (where it was then), and the substep runs again, so the
        impact that broke the body meets its pieces (a projectile goes on through what it
        breaks). Impacts of the re-run are analysed too (pieces may break again), without a
        third run. Keeping the state before every substep is one small launch on the device
        (``World.checkpoint``). Returns the seconds spent in the stage."""
        world, stage = self.world, self.fracture_stage
        count = world.begin_frame(self.frame_dt, self.scene.simulation.substeps)
        stage.begin_frame()
        seconds = 0.0
        seen = 0  # impact rows of this frame analysed so far
        for k in range(count):
            dt = self.frame_dt / count
            start = world.checkpoint()
            world.substep(dt, k)
            first, seen = seen, world.impact_count()
            if seen == first:
                continue
            t = time.perf_counter()
            fractures = stage.run(frame, first, start)
            self._record(fractures)
            seconds += time.perf_counter() - t
            if not fractures:
                continue
            live, born = set(world.body_ids), {c for f in fractures for c in f.children}
            world.restore(start, [b for b in start.ids if b in live and b not in born])
            self.resimulated_substeps += 1
            first = world.impact_count()
            world.substep(dt, k)
            seen = world.impact_count()
            if seen != first:
                t = time.perf_counter()
                self._record(stage.run(frame, first))
                seconds += time.perf_counter() - t
        world.end_frame()
        return seconds

    def _record(self, fractures) -> None:
        """List the splits' events; cut their piece surfaces and hand them to the recorder
        (timed with the splits)."""
        self.events += [f.event for f in fractures]
        if self.recorder is None or not fractures:
            return
        t = time.perf_counter()
        for fracture in fractures:
            self.recorder.record_fracture(fracture, self.surfaces.cut(fracture))
        self.times.fragment_split += time.perf_counter() - t

    # ------------------------------------------------------------------ loop

    @property
    def fracture_events(self) -> int:
        """Bodies split so far."""
        return 0 if self.fracture_stage is None else self.fracture_stage.fracture_events

    @property
    def mass_dropped(self) -> float:
        """[kg] mass removed by the "drop" small-fragment policy so far."""
        return 0.0 if self.fracture_stage is None else self.fracture_stage.mass_dropped

    @property
    def render_cuts(self) -> list[tuple[float, dict]]:
        """Per split that cut a render solid: (seconds, surfaces/cut.py's counts)."""
        return [] if self.surfaces is None else self.surfaces.cuts

    @property
    def fragment_count(self) -> int:
        """Live pieces made by fracture (the paper's Table 1 'fragments' column)."""
        return sum(1 for b in self.world.body_ids if self.records[b].generation > 0)

    def run(self) -> RunSummary:
        """Simulate every frame; Ctrl-C stops cleanly with a valid cache of the frames done.

        The objects alive when the run starts (Taichi's, the models', the scene's: ~10^5)
        are frozen out of Python's cyclic garbage collector for the run (``gc.freeze``,
        undone at the end): otherwise each full collection walks them all, a pause of tens
        of milliseconds inside a frame. BLAS runs one thread in this process for the run, as
        for the set-up (``blas.one_blas_thread``): beside the surface workers a threaded BLAS
        waits for its helper thread to be scheduled at every small solve (the set-up's 3x3
        inverses took 3 ms each beside the workers' first jobs)."""
        with one_blas_thread():
            return self._run()

    def _run(self) -> RunSummary:
        start = time.perf_counter()
        interrupted = False
        failed = True  # until the loop ends: an exception leaves the cache incomplete
        frame_ms: list[float] = []
        done = 0  # frames simulated and written (a Ctrl-C may land anywhere in a frame)
        try:  # (from here on, a Ctrl-C ends in the finally below, which gives the lock back)
            # (garbage is collected before it is frozen: a full collection walks every object,
            # 0.13 s after a new process's set-up, which leaves almost none (70 objects); a
            # later run's may hold the runs' before it, so it gets one)
            global _RUNS_STARTED
            gc.collect(2 if _RUNS_STARTED else 1)
            _RUNS_STARTED = True
            gc.freeze()
            if self.recorder is not None:
                self._open_cache()
            for frame in range(1, self.frame_count + 1):
                t_frame = time.perf_counter()
                self._step_frame(frame)
                self._write_frame(frame)
                done = frame
                frame_ms.append(1000.0 * (time.perf_counter() - t_frame))
                if self.progress is not None:
                    elapsed = time.perf_counter() - start
                    self.progress(frame, self.frame_count, frame * self.frame_dt, self.fragment_count,
                                  frame / max(elapsed, 1e-9))
                interrupts.check()  # (a Ctrl-C that a library swallowed)
            if self.recorder is None:  # (with a cache every frame was checked as it was written)
                ids = self.world.body_ids
                self._check_finite_poses(done, ids, self.world.body_state(ids))
            failed = False
        except KeyboardInterrupt:
            interrupted = True
            failed = False
        finally:
            gc.unfreeze()
            try:
                if self.recorder is not None:
                    t = time.perf_counter()
                    # complete only when every requested frame was written
                    self.recorder.close(complete=not failed and not interrupted and done == self.frame_count,
                                        on_wait=self.surfaces_progress)
                    self.times.surfaces_wait += self.recorder.wait_seconds
                    self.times.output += time.perf_counter() - t - self.recorder.wait_seconds
            finally:
                self._release()
        self.times.render_surfaces = sum(seconds for seconds, _ in self.render_cuts)
        return self._summary(done, frame_ms, time.perf_counter() - start, interrupted)

    def _first_analysis(self) -> float:
        """[s] the run's first impact analysis (0 without one): in a new process, mostly the
        fracture kernels' first launch."""
        stage = self.fracture_stage
        return 0.0 if stage is None or stage.first_analysis_seconds is None else stage.first_analysis_seconds

    def _release(self) -> None:
        """The output's lock, and the World for the next run in this process."""
        from .scene_setup import release_world

        try:
            if self.surfaces is not None:
                # Workers whose results can no longer be written are killed; the others wait
                # for the next run in this process.
                recorder = self.recorder
                self.surfaces.close(cancel=recorder is None or recorder.writer is None or recorder.pending)
        finally:
            if self._lock is not None:
                self._lock.release()
            if self.world is not None:
                release_world(self.world)

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
            stage_seconds=self.times.as_dict() | {"prepare": round(self.prepare_seconds, 6),
                                                  "setup": round(self.setup_seconds, 6),
                                                  "first_analysis": round(self._first_analysis(), 6)},
            dynamics_stage_seconds={k: round(v, 6) for k, v in dynamics_seconds.items()},
            # first: in a new process, the frame that launches the dynamics kernels for the
            # first time (Taichi's front end runs then, even with the offline cache warm);
            # the first impact's frame does the same for the fracture kernels.
            ms_per_frame=dict(mean=float(ms.mean()), max=float(ms.max()), median=float(np.median(ms)),
                              first=float(ms[0]), mean_after_first=float(ms[1:].mean()) if len(ms) > 1 else None,
                              max_after_first=float(ms[1:].max()) if len(ms) > 1 else None),
            interrupted=interrupted,
            output=None if self.output_path is None else str(self.output_path),
            mass_initial=self.initial_mass,
            mass_final=sum(self.records[b].model.mass for b in live),
            mass_dropped=self.mass_dropped,
            resimulated_substeps=self.resimulated_substeps,
            surface_workers=getattr(self.surfaces, "count", 0),
            events=list(self.events),
        )
