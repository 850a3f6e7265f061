"""A scene's bodies prepared and a World sized and furnished for them: what a
:class:`~taichi_frac.simulation.Simulation` does before its first frame.

Three steps, each usable alone (a bench that reuses one World across scenes calls the last
two with its own):

1. :func:`prepare_objects`: every object's mesh → tets → :class:`~taichi_frac.model.BodyModel`
   (``SceneObject.prepare``, cached on disk), with a breakable body's SPH neighbour lists
   (and the FEM stiffness when that stress model is chosen) built once, here, as the paper's
   preprocessing;
2. :func:`world_capacity` and :func:`dynamics_options`: how much room the World needs once
   the breakable bodies have split, and the solver settings of the scene;
3. :func:`furnish_world`: a new World, or the one given cleared and checked against that
   room, with the scene's ground and static boxes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from . import interrupts
from .geometry.validate import REPAIR_HINT, MeshError
from .memo import remember

__all__ = ["PreparedObject", "dynamics_options", "furnish_world", "prepare_objects", "release_world",
           "world_capacity"]


@dataclass(frozen=True)
class PreparedObject:
    """One scene object with its static model. ``breakable``: the object breaks in this run
    (it is breakable and the run has fracture on)."""

    obj: object  # scenes.SceneObject
    model: object  # model.BodyModel
    report: object  # geometry.prepare.PrepareReport
    breakable: bool


#: Prepared models kept in this process, by what a model depends on (``_prepare_key``): the
#: copies of one object in a scene, and the next run of the same scene, take the model
#: made once (a BodyModel never changes). The oldest go first past this many.
PREPARED_KEPT = 64
_PREPARED: dict[str, tuple] = {}


def prepare_object(obj, *, surface_contact: bool = False):
    """``obj.prepare(surface_contact=...)``, made once per process for what it depends on:
    (BodyModel, PrepareReport)."""
    key = _prepare_key(obj, surface_contact)
    if key not in _PREPARED:
        remember(_PREPARED, key, obj.prepare(surface_contact=surface_contact), PREPARED_KEPT)
    return _PREPARED[key]


def _prepare_key(obj, surface_contact: bool) -> str:
    """What a scene object's model depends on; a mesh file by its path, size and time."""
    stamp = None
    if obj.mesh is not None:
        try:
            info = Path(obj.mesh).stat()
            stamp = (str(Path(obj.mesh).resolve()), info.st_size, info.st_mtime_ns)
        except OSError:
            stamp = str(obj.mesh)  # (prepare says what is wrong with it)
    return repr((obj.source, stamp, obj.scale, obj.units, obj.material, obj.particles, obj.repair, surface_contact,
                 obj.thickness, obj.up_axis))


def prepare_objects(scene, *, fracture: bool = True, prepare=None) -> tuple[list[PreparedObject], float]:
    """Every object of ``scene`` prepared, in order, and the seconds it took. ``prepare``:
    callable(SceneObject, *, surface_contact) -> (BodyModel, PrepareReport) used instead of
    :func:`prepare_object` (this process's memo). Ctrl-C is honoured between objects."""
    t0 = time.perf_counter()
    prepare = prepare or prepare_object
    prepared = []
    for obj in scene.objects:
        interrupts.check()
        try:
            surface = scene.simulation.surface_contact
            model, report = prepare(obj, surface_contact=surface)
        except MeshError as exc:
            raise MeshError(f"object {obj.name!r}: " + str(exc).replace(REPAIR_HINT, _scene_repair_hint(obj.name))) \
                from None
        breakable = bool(obj.breakable and fracture)
        if breakable:
            # A breakable body's SPH neighbour lists, built once and kept beside its model (a
            # no-op for a model reused from a ``prepare`` callable); its fragments' are
            # restricted from them.
            from .fracture.neighbors import model_neighbor_lists, smoothing_length

            model_neighbor_lists(model, smoothing_length(model, obj.fracture))
            from .fracture.energy import stress_model_of

            if stress_model_of(model, obj.fracture) == "fem":  # its stiffness, factorised once
                from .fracture.fem import elastic_body_of

                elastic_body_of(model, obj.material)
        prepared.append(PreparedObject(obj, model, report, breakable))
    return prepared, time.perf_counter() - t0


def _scene_repair_hint(name: str) -> str:
    """How to ask for a mesh repair in a scene (the scene's words for ``validate.REPAIR_HINT``)."""
    return (f"set repair = true on object {name!r} (or --set {name}.repair=true) to try an automatic fix, "
            "or fix it in a modelling tool")


def world_capacity(scene, prepared: list[PreparedObject], *, single_scale: bool | None = None):
    """The :class:`~taichi_frac.dynamics.WorldCapacity` the scene needs, with room for its
    breakable bodies' pieces: fragments add crack faces, so their boundary layers hold more
    particles than the parent's (room for about four times the breakable bodies' boundary
    particles)."""
    from .dynamics import WorldCapacity

    single = single_scale if single_scale is not None else scene.simulation.single_scale
    particles_now = sum(p.model.surface_particle_count if single else p.model.boundary_particle_count
                        for p in prepared)
    breakable = [p.model for p in prepared if p.breakable]
    extra = sum(4 * m.boundary_particle_count + m.surface_particle_count for m in breakable)
    return WorldCapacity(
        max_bodies=max(64, len(prepared) + 256 * len(breakable)),
        max_boundary_particles=max(1024, particles_now + extra),
        # 4 per particle of that room: the shipped scenes peak far below it, and each
        # contact slot costs memory on every particle of the largest scenes.
        max_contacts=max(65536, 4 * (particles_now + extra)),
        max_static_boxes=max(4, sum(c.type == "box" for c in scene.colliders)),
    )


def allocated_capacity(need):
    """The capacity a new World is built with for a scene that needs ``need``: each size
    rounded up to a power of two, from a floor that holds scenes of up to a few dozen
    breakable bodies. The compiled kernels depend on the fields' sizes, so scenes of like
    size share one set in Taichi's offline cache (and a World) instead of compiling anew;
    the floor costs about 120 MB of fields, and the frames cost the same."""
    from .dynamics import WorldCapacity

    particles = _power_of_two(max(65536, need.max_boundary_particles))
    return WorldCapacity(max_bodies=_power_of_two(max(4096, need.max_bodies)), max_boundary_particles=particles,
                         max_contacts=max(need.max_contacts, 4 * particles),
                         max_static_boxes=_power_of_two(max(4, need.max_static_boxes)))


def _power_of_two(n: int) -> int:
    """The smallest power of two >= ``n`` (n >= 1)."""
    return 1 << (int(n) - 1).bit_length()


def dynamics_options(scene, *, single_scale: bool | None = None):
    """The scene's solver settings as :class:`~taichi_frac.dynamics.DynamicsOptions`; impacts
    are recorded from the lowest force threshold of its breakable objects (0 if none)."""
    from .dynamics import DynamicsOptions

    overrides = {} if single_scale is None else {"single_scale": bool(single_scale)}
    thresholds = [o.fracture.impact_force_threshold for o in scene.objects if o.breakable]
    overrides["record_force_threshold"] = min(thresholds) if thresholds else 0.0
    return DynamicsOptions.from_simulation(scene.simulation, **overrides)


#: The World this process built for a run, kept for the next run once that one has ended
#: (``release_world``): its fields are allocated and its kernels compiled already.
_SHARED = {"world": None, "busy": False}

_CAPACITY_FIELDS = ("max_bodies", "max_boundary_particles", "max_contacts", "max_impacts", "max_static_boxes",
                    "max_planes", "max_surface_points")


def furnish_world(scene, capacity, options, *, arch: str | None = None, world=None):
    """A World with room for ``capacity`` (what the scene needs: a new one is built with
    :func:`allocated_capacity`) and ``options``, holding the scene's ground and static boxes
    (no bodies yet). ``world``: one to reuse (its kernels are compiled already), cleared
    first; ValueError naming the field when it has less room than ``capacity``. Without one,
    the World of this process's last ended run is reused when it has the room (call
    :func:`release_world` when the run ends), else a new one is built."""
    from .dynamics import World

    built = False
    if world is not None:
        for name in ("max_bodies", "max_boundary_particles", "max_static_boxes"):
            if getattr(world.capacity, name) < getattr(capacity, name):
                raise ValueError(f"the World given has {name}={getattr(world.capacity, name)}, this scene "
                                 f"needs {getattr(capacity, name)}")
    elif _SHARED["world"] is not None and not _SHARED["busy"] and _fits(_SHARED["world"].capacity, capacity):
        world = _SHARED["world"]
        _SHARED["busy"] = True
    else:
        world = World(allocated_capacity(capacity), options, arch=arch or scene.simulation.arch)
        _SHARED.update(world=world, busy=True)
        built = True
    if not built:  # (a new World is empty and has the options already)
        world.clear()
        world.set_options(options)
    for c in scene.colliders:
        if c.type == "ground":
            world.add_ground(c.height, friction=c.friction, restitution=c.restitution)
        else:
            world.add_static_box(c.center, c.half_extents, c.orientation, friction=c.friction,
                                 restitution=c.restitution)
    return world


def release_world(world) -> None:
    """A run has ended with ``world``: the next run in this process may reuse it."""
    if world is _SHARED["world"]:
        _SHARED["busy"] = False


def _fits(have, need) -> bool:
    """Whether a World of capacity ``have`` has room for ``need`` in every field."""
    return all(getattr(have, name) >= getattr(need, name) for name in _CAPACITY_FIELDS)
