"""The pybullet reference of ``taichi-frac bench dynamics``: the same scenes in
pybullet 3.2.7 (``pip install pybullet==3.2.7``, the ``bench`` extra), timed per frame.

- the 13-ring scene (rings unbreakable), the rings as
  - ``"vhacd"``: a compound of V-HACD convex parts of our ring surface (the usual
    reference; a single convex hull would fill the ring's hole), or
  - ``"spheres"``: a compound of our boundary-layer spheres (the collision geometry of our
    two-scale model), given by the caller from the body models;
- the fragment pile of ``dynamics._fragment_pile``: icosphere fragments as convex hulls.

Our scene description is converted once into plain :class:`RigidBodySpec` and
:class:`StaticSpec` records (numpy and trimesh only; tested without pybullet), then
:func:`simulate` builds them in a pybullet DIRECT client and times each frame's
``stepSimulation`` calls. No Taichi here: pybullet is imported inside the functions that
use it, so this module imports without it.

Settings, stated because pybullet's defaults differ from ours:

- time step: pybullet's default 1/240 s does not divide a 20 ms frame (4.8 steps), so the
  frame is split into ``ceil(frame_dt x 240)`` equal steps: 5 steps of 4 ms at 50 fps;
- solver: pybullet's defaults (``numSolverIterations`` 50, as reported by
  ``getPhysicsEngineParameters``; its ERP, split impulse and sleeping as they come);
- bodies: Bullet's btRigidBody (``useMaximalCoordinates=True``), its fast path for free
  bodies; pybullet's default, a one-link btMultiBody, measured 1.3x (rings) to 1.5x (pile) slower;
- damping: pybullet's bodies have linear and angular damping 0.04 by default; ours have
  none, so it is set to 0;
- friction and restitution: pybullet multiplies the two bodies' coefficients, we combine
  friction as sqrt(a b) and restitution as max(a, b) (``collision/narrowphase.py``); each
  pybullet body gets sqrt of ours, which reproduces our friction exactly and our
  restitution wherever the two are equal (every pair of the 13-ring scene: 0.1);
- mass density x the surface mesh's volume [kg], inertia from the same mesh.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from taichi_frac.kinematics.quaternion import quaternion_matrix

#: pybullet's default time step [s]; a frame is split into steps no longer than this.
PYBULLET_DEFAULT_TIME_STEP = 1.0 / 240.0

#: Our bodies' sleep test (``DynamicsOptions.sleep_linear_speed``) [m/s]: a body is at
#: rest when every point of it (|v| + |w| x bounding radius) is slower than this.
REST_SPEED = 0.01

#: Collision geometries :func:`simulate` builds (see the module docstring).
COLLISION_MODES = ("vhacd", "spheres", "hull")

#: pybullet.vhacd is called with its defaults (as in the reference measurements); its log
#: prints them for 3.2.7: concavity 0.001, depth 20, 64 vertices a part, plane and hull
#: down-sampling 4, voxel grid 2.7 M voxels whatever ``resolution`` says. ~15 s for our ring,
#: whatever those knobs (measured: resolution 1e4-1e6, depth 4-20, down-sampling 4-16 all
#: took 10-15 s), hence the cache.
VHACD_CACHE_VERSION = 1


@dataclass(frozen=True, eq=False)
class RigidBodySpec:
    """One dynamic body, as pybullet gets it.

    Attributes:
        name: label (the scene object's name).
        surface: closed trimesh in the body frame [m]: origin at the centre of mass, axes
            the body's principal axes (checked by :func:`mass_properties`).
        mass: [kg] = density x surface volume.
        inertia_diagonal: (3,) [kg m^2] principal moments about the centre of mass.
        position: (3,) [m] world position of the centre of mass.
        orientation_xyzw: (4,) unit quaternion body -> world in pybullet's (x, y, z, w) order.
        linear_velocity: (3,) [m/s] world frame.  angular_velocity: (3,) [rad/s] world frame.
        friction, restitution: our coefficients [-] (not pybullet's: see
            :func:`pybullet_coefficient`).
    """

    name: str
    surface: trimesh.Trimesh
    mass: float
    inertia_diagonal: np.ndarray
    position: np.ndarray
    orientation_xyzw: np.ndarray
    linear_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    friction: float = 0.5
    restitution: float = 0.2

    @property
    def bounding_radius(self) -> float:
        """[m] farthest surface vertex from the centre of mass."""
        return float(np.linalg.norm(self.surface.vertices, axis=1).max())


@dataclass(frozen=True)
class StaticSpec:
    """A static collider: ``"ground"`` (the plane z = ``height`` [m]) or ``"box"`` (centre
    (3,) [m], half extents (3,) [m], orientation (x, y, z, w)); our friction and
    restitution [-]."""

    type: str
    height: float = 0.0
    center: tuple = (0.0, 0.0, 0.0)
    half_extents: tuple = (0.5, 0.5, 0.5)
    orientation_xyzw: tuple = (0.0, 0.0, 0.0, 1.0)
    friction: float = 0.5
    restitution: float = 0.2


@dataclass
class PyBulletRun:
    """What :func:`simulate` measured.

    Attributes:
        label: what ran (e.g. "13 rings, V-HACD").
        frames: timed frames.  frame_dt: [s].  steps_per_frame: stepSimulation calls a frame.
        maximal_coordinates: btRigidBody (True) or btMultiBody (False) bodies.
        time_step: pybullet's fixed time step [s].  solver_iterations: its numSolverIterations.
        engine_parameters: getPhysicsEngineParameters() as pybullet reported it.
        frame_ms: (frames,) [ms] wall time of each frame's stepSimulation calls.
        at_rest: (B,) bool, every point slower than ``rest_speed`` at the end.
        lowest_collision: (B,) [m] lowest point of each body's collision geometry (hull
            vertices or sphere bottoms) above the ground at the end (negative: below).
            From the geometry, not getAABB: a rotated compound's AABB is the box around its
            rotated local box, centimetres below the ground while every sphere rests on it.
            Convex hulls rest ~1 mm above the ground (pybullet's collision margin).
        lowest_surface: (B,) [m] the same for each body's surface mesh.
        collision_parts: convex parts / spheres per body (of the first body).
        centre_ray_blocked: bodies whose collision shape a ray along the body Z axis
            through its centre of mass hits at the start (for a ring: its hole is filled).
    """

    label: str
    frames: int
    frame_dt: float
    steps_per_frame: int
    maximal_coordinates: bool
    time_step: float
    solver_iterations: int
    engine_parameters: dict
    frame_ms: np.ndarray
    at_rest: np.ndarray
    lowest_collision: np.ndarray
    lowest_surface: np.ndarray
    collision_parts: int
    centre_ray_blocked: int

    @property
    def avg_ms(self) -> float:
        return float(self.frame_ms.mean())

    @property
    def max_ms(self) -> float:
        return float(self.frame_ms.max())

    @property
    def deepest_below_ground(self) -> float:
        """[m] deepest collision geometry below the ground at the end (0 when none is)."""
        return max(0.0, float(-self.lowest_collision.min()))


# ------------------------------------------------------------------ scene conversion


def wxyz_to_xyzw(q) -> np.ndarray:
    """Our quaternion order (w, x, y, z) -> pybullet's (x, y, z, w)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([x, y, z, w])


def pybullet_coefficient(ours: float) -> float:
    """pybullet multiplies two bodies' friction (and restitution) coefficients; we take the
    geometric mean sqrt(a b) (friction) or max(a, b) (restitution). sqrt(ours) per body
    makes pybullet's product equal our geometric mean, and our max where a = b."""
    return math.sqrt(float(ours))


def mass_properties(surface: trimesh.Trimesh, density: float) -> tuple[float, np.ndarray]:
    """(mass [kg], principal moments (3,) [kg m^2]) of a closed ``surface`` whose centre of
    mass is its origin and whose axes are principal (our primitives are symmetric about
    their axes); raises ValueError otherwise, since pybullet would then need an inertial
    frame rotation that we do not pass."""
    mass = density * float(surface.volume)
    inertia = np.asarray(surface.moment_inertia, dtype=np.float64) * density
    scale = float(np.abs(inertia).max())
    size = float(np.linalg.norm(surface.extents))
    if np.linalg.norm(surface.center_mass) > 1e-9 * size or \
            np.abs(inertia - np.diag(np.diag(inertia))).max() > 1e-6 * scale:
        raise ValueError("the surface's origin is not its centre of mass or its axes are not principal")
    return mass, np.diag(inertia).copy()


def object_surface(obj) -> trimesh.Trimesh:
    """The closed surface [m] of scene object ``obj`` that ``prepare_body`` meshes (the same
    facets for a primitive: the same edge length from its particle target), moved so its
    centre of mass is the origin (our body frame)."""
    from taichi_frac.geometry.bounded import StepClock
    from taichi_frac.geometry.meshio_in import unit_scale
    from taichi_frac.geometry.prepare import PRIMITIVE_EDGE_FACTOR, _surface_from_source
    from taichi_frac.geometry.tetra import regular_tet_edge

    target = obj.particles.target_particles

    def edge_for(volume):  # prepare_body's, for a particle target
        return PRIMITIVE_EDGE_FACTOR * regular_tet_edge(volume / target)

    _, surface, _ = _surface_from_source(obj.source, unit_scale(obj.scale, obj.units), obj.repair, edge_for,
                                         StepClock(name=str(obj.source)))
    surface = surface.copy()
    surface.apply_translation(-surface.center_mass)
    return surface


def scene_bodies(scene) -> tuple[list[RigidBodySpec], list[StaticSpec]]:
    """Our scene description (``taichi_frac.scenes.Scene``) -> pybullet bodies and statics.
    Every object becomes one rigid body (fracture is off in this comparison)."""
    surfaces: dict[tuple, trimesh.Trimesh] = {}
    bodies = []
    for obj in scene.objects:
        key = (obj.source, obj.scale, obj.units, obj.repair, obj.particles.target_particles)
        if key not in surfaces:  # thirteen identical rings: one surface
            surfaces[key] = object_surface(obj)
        surface = surfaces[key]
        mass, inertia = mass_properties(surface, obj.material.density)
        bodies.append(RigidBodySpec(
            name=obj.name, surface=surface, mass=mass, inertia_diagonal=inertia,
            position=np.asarray(obj.position, dtype=np.float64), orientation_xyzw=wxyz_to_xyzw(obj.orientation),
            linear_velocity=np.asarray(obj.linear_velocity, dtype=np.float64),
            angular_velocity=np.asarray(obj.angular_velocity, dtype=np.float64),
            friction=obj.friction, restitution=obj.restitution))
    statics = []
    for c in scene.colliders:
        if c.type == "ground":
            statics.append(StaticSpec(type="ground", height=c.height, friction=c.friction, restitution=c.restitution))
        else:
            statics.append(StaticSpec(type="box", center=tuple(c.center), half_extents=tuple(c.half_extents),
                                      orientation_xyzw=tuple(wxyz_to_xyzw(c.orientation)), friction=c.friction,
                                      restitution=c.restitution))
    return bodies, statics


def fragment_pile(count: int = 216) -> tuple[list[RigidBodySpec], list[StaticSpec]]:
    """``dynamics._fragment_pile``'s pile (``bench/pile.py``: the same layout): ``count``
    icospheres as convex hulls in a box of four static walls on the ground; our default
    friction 0.5 and restitution 0.2 everywhere."""
    from . import pile

    surface = trimesh.creation.icosphere(subdivisions=1, radius=pile.FRAGMENT_RADIUS)
    mass, inertia = mass_properties(surface, pile.FRAGMENT_DENSITY)
    positions, spins = pile.layout(count)
    bodies = [RigidBodySpec(name=f"fragment{k:04d}", surface=surface, mass=mass, inertia_diagonal=inertia,
                            position=x, orientation_xyzw=np.array([0.0, 0.0, 0.0, 1.0]), angular_velocity=w)
              for k, (x, w) in enumerate(zip(positions, spins))]
    statics = [StaticSpec(type="ground", height=0.0)]
    statics += [StaticSpec(type="box", center=c, half_extents=h) for c, h in pile.WALLS]
    return bodies, statics


# ------------------------------------------------------------------ collision shapes


def vhacd_cache_dir() -> Path:
    """``runtime.cache_dir() / "vhacd"`` (the same folder rule; runtime imports Taichi)."""
    root = os.environ.get("TAICHI_FRAC_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME", os.path.expanduser("~/.cache")), "taichi-frac")
    path = Path(root) / "vhacd"
    path.mkdir(parents=True, exist_ok=True)
    return path


@contextlib.contextmanager
def _quiet_stdout():
    """pybullet.vhacd prints its progress from C to file descriptor 1: send it away."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def vhacd_decomposition(surface: trimesh.Trimesh, cache_dir: Path | None = None) -> Path:
    """The .obj of V-HACD's convex parts of ``surface`` (one object a part), cached under
    ``cache_dir`` (default :func:`vhacd_cache_dir`) keyed by the surface's bytes and
    pybullet's version (see :data:`VHACD_CACHE_VERSION`)."""
    import pybullet

    h = hashlib.sha256()
    h.update(np.ascontiguousarray(surface.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(surface.faces, dtype=np.int64).tobytes())
    h.update(repr(("defaults", pybullet_version(), VHACD_CACHE_VERSION)).encode())
    folder = cache_dir or vhacd_cache_dir()
    out = folder / f"{h.hexdigest()}.obj"
    if out.exists():
        return out
    with tempfile.TemporaryDirectory() as tmp:
        source, result, log = (os.path.join(tmp, n) for n in ("in.obj", "out.obj", "log.txt"))
        surface.export(source)
        with _quiet_stdout():
            pybullet.vhacd(source, result, log)
        if not os.path.exists(result) or os.path.getsize(result) == 0:
            raise RuntimeError(f"pybullet.vhacd wrote no decomposition (see its log: {Path(log).read_text()[-500:]})")
        os.replace(result, out)  # the same filesystem in general; atomic for parallel runs
    return out


def obj_vertices(path: Path) -> np.ndarray:
    """(V,3) [m] every ``v`` line of an .obj file (the convex parts' vertices)."""
    rows = [line.split()[1:4] for line in Path(path).read_text().splitlines() if line.startswith("v ")]
    return np.array(rows, dtype=np.float64)


def _spheres_urdf(spec: RigidBodySpec, centres: np.ndarray, radii: np.ndarray, path: str) -> None:
    """A one-link URDF whose link holds one <collision> sphere per boundary particle.

    Why URDF: ``createCollisionShapeArray`` keeps at most 16 shapes
    (MAX_COMPOUND_COLLISION_SHAPES in pybullet's SharedMemoryPublic.h) and drops the rest
    silently; the URDF importer builds a compound of any size. One element a line: pybullet
    fails to parse this file written on a single 58 kB line ("XML_ERROR_PARSING_ATTRIBUTE")."""
    i = spec.inertia_diagonal
    lines = ['<robot name="body"><link name="base"><inertial><origin xyz="0 0 0"/>',
             f'<mass value="{spec.mass:.12g}"/>',
             f'<inertia ixx="{i[0]:.12g}" iyy="{i[1]:.12g}" izz="{i[2]:.12g}" ixy="0" ixz="0" iyz="0"/></inertial>']
    lines += [f'<collision><origin xyz="{x:.9g} {y:.9g} {z:.9g}"/><geometry><sphere radius="{r:.9g}"/></geometry>'
              "</collision>" for (x, y, z), r in zip(centres, radii)]
    lines.append("</link></robot>")
    Path(path).write_text("\n".join(lines))


# ------------------------------------------------------------------ simulation


def simulate(bodies: list[RigidBodySpec], statics: list[StaticSpec], *, label: str, collision: str = "vhacd",
             spheres: list[tuple[np.ndarray, np.ndarray]] | None = None, frame_dt: float = 0.02,
             seconds: float = 3.0, gravity=(0.0, 0.0, -9.81), rest_speed: float = REST_SPEED,
             maximal_coordinates: bool = True, cache_dir: Path | None = None) -> PyBulletRun:
    """Build ``bodies`` and ``statics`` in a pybullet DIRECT client and step ``seconds`` [s]
    of ``frame_dt`` [s] frames, timing each frame.

    ``collision``: "vhacd" (V-HACD parts of each body's surface), "hull" (one convex hull
    of its vertices: the fragments) or "spheres" (``spheres[k]`` = (centres (N,3) [m] body
    frame, radii (N,) [m]) of body k, our boundary layer). ``maximal_coordinates``: Bullet's
    btRigidBody (True) or a one-link btMultiBody (False, pybullet's default for
    createMultiBody and loadURDF), measured 1.3x slower on the rings, 1.5x on the pile."""
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

    if collision not in COLLISION_MODES:
        raise ValueError(f"collision = {collision!r}: use one of {', '.join(COLLISION_MODES)}")
    if collision == "spheres" and (spheres is None or len(spheres) != len(bodies)):
        raise ValueError("collision = 'spheres' needs one (centres, radii) pair a body")
    steps = max(1, math.ceil(frame_dt / PYBULLET_DEFAULT_TIME_STEP - 1e-9))
    with _quiet_stdout():  # connecting prints "argv[0]="
        client = BulletClient(connection_mode=pybullet.DIRECT)
    try:
        client.setGravity(*map(float, gravity))
        client.setTimeStep(frame_dt / steps)
        for s in statics:
            if s.type == "ground":
                shape = client.createCollisionShape(pybullet.GEOM_PLANE)
                sid = client.createMultiBody(0, shape, basePosition=(0, 0, s.height))
            else:
                shape = client.createCollisionShape(pybullet.GEOM_BOX, halfExtents=s.half_extents)
                sid = client.createMultiBody(0, shape, basePosition=s.center, baseOrientation=s.orientation_xyzw)
            client.changeDynamics(sid, -1, lateralFriction=pybullet_coefficient(s.friction),
                                  restitution=pybullet_coefficient(s.restitution))
        ground = min((s.height for s in statics if s.type == "ground"), default=0.0)

        shapes: dict[int, tuple] = {}  # id(surface) -> (shape, (P,3) points, parts): shared
        collision_points = []  # per body: (P,3) body-frame points whose lowest is its bottom
        collision_pad = []  # per body: (P,) [m] from each point down to the geometry (sphere radii)
        collision_parts = []  # per body: convex parts or spheres
        ids = []
        with tempfile.TemporaryDirectory() as tmp:
            for k, spec in enumerate(bodies):
                if collision == "spheres":
                    centres, radii = (np.asarray(a, dtype=np.float64) for a in spheres[k])
                    path = os.path.join(tmp, f"body{k}.urdf")
                    _spheres_urdf(spec, centres, radii, path)
                    bid = client.loadURDF(path, basePosition=spec.position, baseOrientation=spec.orientation_xyzw,
                                          flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                          useMaximalCoordinates=maximal_coordinates)
                    points, pad, parts = centres, radii, len(radii)
                else:
                    if id(spec.surface) not in shapes:
                        if collision == "vhacd":
                            obj = vhacd_decomposition(spec.surface, cache_dir)
                            # A multi-object .obj becomes a compound of one convex hull a
                            # part (checked: the ray through a ring's hole hits nothing).
                            shape = client.createCollisionShape(pybullet.GEOM_MESH, fileName=str(obj))
                            text = Path(obj).read_text().splitlines()
                            shapes[id(spec.surface)] = (shape, obj_vertices(obj),
                                                        sum(line.startswith("o ") for line in text))
                        else:
                            vertices = np.asarray(spec.surface.vertices, dtype=np.float64)
                            shape = client.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices.tolist())
                            shapes[id(spec.surface)] = (shape, vertices, 1)
                    shape, points, parts = shapes[id(spec.surface)]
                    pad = np.zeros(len(points))
                    bid = client.createMultiBody(spec.mass, shape, basePosition=spec.position,
                                                 baseOrientation=spec.orientation_xyzw,
                                                 useMaximalCoordinates=maximal_coordinates)
                # createMultiBody takes a mesh's inertia from its bounding box: set ours, with
                # the mass (a btRigidBody given localInertiaDiagonal alone froze in place). No
                # damping (ours has none; pybullet's default is 0.04).
                client.changeDynamics(bid, -1, mass=spec.mass, localInertiaDiagonal=spec.inertia_diagonal.tolist(),
                                      lateralFriction=pybullet_coefficient(spec.friction),
                                      restitution=pybullet_coefficient(spec.restitution),
                                      linearDamping=0.0, angularDamping=0.0)
                client.resetBaseVelocity(bid, spec.linear_velocity.tolist(), spec.angular_velocity.tolist())
                ids.append(bid)
                collision_points.append(points)
                collision_pad.append(pad)
                collision_parts.append(parts)

        blocked = 0
        for bid, spec in zip(ids, bodies):
            axis = _rotation(spec.orientation_xyzw)[:, 2]
            # From the body's bounding sphere (which overlaps no other body's at the start in
            # our scenes) through its centre: only the body itself can be in the way.
            reach = spec.bounding_radius
            hit = client.rayTest((spec.position + reach * axis).tolist(), (spec.position - reach * axis).tolist())[0]
            blocked += int(hit[0] == bid)

        engine = client.getPhysicsEngineParameters()
        frames = int(round(seconds / frame_dt))
        frame_ms = np.empty(frames)
        for frame in range(frames):
            t = time.perf_counter()
            for _ in range(steps):
                client.stepSimulation()
            frame_ms[frame] = 1e3 * (time.perf_counter() - t)

        at_rest, low_collision, low_surface = [], [], []
        for bid, spec, points, pad in zip(ids, bodies, collision_points, collision_pad):
            position, orientation = client.getBasePositionAndOrientation(bid)
            linear, angular = client.getBaseVelocity(bid)
            rotation = _rotation(orientation)
            at_rest.append(np.linalg.norm(linear) + np.linalg.norm(angular) * spec.bounding_radius < rest_speed)
            low_collision.append(float(np.min(position[2] + points @ rotation[2] - pad)) - ground)
            low_surface.append(float(np.min(position[2] + spec.surface.vertices @ rotation[2])) - ground)
    finally:
        client.disconnect()
    return PyBulletRun(label=label, frames=frames, frame_dt=frame_dt, steps_per_frame=steps,
                       maximal_coordinates=maximal_coordinates,
                       time_step=float(engine["fixedTimeStep"]),
                       solver_iterations=int(engine["numSolverIterations"]), engine_parameters=dict(engine),
                       frame_ms=frame_ms, at_rest=np.array(at_rest), lowest_collision=np.array(low_collision),
                       lowest_surface=np.array(low_surface), collision_parts=int(collision_parts[0]),
                       centre_ray_blocked=blocked)


def _rotation(q_xyzw) -> np.ndarray:
    """(3,3) rotation matrix of a unit quaternion in pybullet's order (x, y, z, w)."""
    return quaternion_matrix(np.roll(np.asarray(q_xyzw, dtype=np.float64), 1))


def run_rings(scene, collision: str = "vhacd", spheres=None, *, seconds: float | None = None,
              maximal_coordinates: bool = True, cache_dir: Path | None = None) -> PyBulletRun:
    """``scene`` (the 13 rings) in pybullet with the scene's frame rate, duration and gravity."""
    sim = scene.simulation
    bodies, statics = scene_bodies(scene)
    label = {"vhacd": "V-HACD parts", "spheres": "boundary spheres", "hull": "convex hull"}[collision]
    return simulate(bodies, statics, label=f"{len(bodies)} rings, {label}", collision=collision, spheres=spheres,
                    frame_dt=sim.frame_dt, seconds=sim.duration if seconds is None else seconds,
                    gravity=sim.gravity, rest_speed=sim.sleep_linear_speed, maximal_coordinates=maximal_coordinates,
                    cache_dir=cache_dir)


def run_fragment_pile(count: int = 216, *, seconds: float = 3.0, frame_dt: float = 0.02,
                      gravity=(0.0, 0.0, -9.81), maximal_coordinates: bool = True) -> PyBulletRun:
    """:func:`fragment_pile` in pybullet, the fragments as convex hulls."""
    bodies, statics = fragment_pile(count)
    return simulate(bodies, statics, label=f"{count} fragments, convex hulls", collision="hull",
                    frame_dt=frame_dt, seconds=seconds, gravity=gravity, maximal_coordinates=maximal_coordinates)


def pybullet_version() -> str:
    import importlib.metadata

    return importlib.metadata.version("pybullet")


def settings_text(run: PyBulletRun) -> str:
    """pybullet's time stepping of ``run``, for the table."""
    return (f"{run.steps_per_frame} x {1e3 * run.time_step:g} ms steps, "
            f"{run.solver_iterations} solver iterations, "
            + ("btRigidBody" if run.maximal_coordinates else "btMultiBody"))


def comparison_table(scene, spheres, *, rings_ms: tuple[float, float], pile_ms: tuple[float, float],
                     fragments: int = 216, seconds: float = 3.0, progress=print, rings_note: str = "") -> str:
    """Run the rings (V-HACD parts, then our boundary spheres ``spheres``, one (centres,
    radii) pair an object) and the fragment pile in pybullet; a markdown table against our
    ms/frame (avg, max) of the rings (``rings_ms``) and of the pile (``pile_ms``)."""
    from .common import md_table, ms_pair

    sim = scene.simulation
    progress("pybullet: rings, V-HACD parts (the decomposition is cached after the first run)")
    vhacd = run_rings(scene, "vhacd")
    progress("pybullet: rings, our boundary spheres")
    balls = run_rings(scene, "spheres", spheres)
    progress("pybullet: fragment pile")
    pile = run_fragment_pile(fragments, seconds=seconds, frame_dt=sim.frame_dt, gravity=sim.gravity)

    def row(label, ours, run):
        return [label, ms_pair(*ours), ms_pair(run.avg_ms, run.max_ms),
                f"{run.avg_ms / ours[0]:.1f}x / {run.max_ms / ours[1]:.1f}x", settings_text(run),
                f"{int(run.at_rest.sum())} / {len(run.at_rest)}", f"{1e3 * run.deepest_below_ground:.3f}"]

    holes = "" if vhacd.centre_ray_blocked == 0 else f" (**{vhacd.centre_ray_blocked} holes filled**)"
    rings = len(scene.objects)
    return "\n".join([
        f"pybullet {pybullet_version()} on the same scenes (DIRECT client; the frame cut into whole steps of at "
        "most its default 1/240 s, its solver defaults, no damping, friction and restitution combined as ours: "
        "see benchmarks/pybullet_ref.py). Ours: the two-scale rows above"
        f"{' (' + rings_note + ')' if rings_note else ''}. A ratio over 1: pybullet is slower. At rest: every "
        f"point slower than {1e3 * REST_SPEED:g} mm/s at the end.",
        "",
        md_table(["scene", "ours ms/frame avg / max", "pybullet ms/frame avg / max", "pybullet / ours (avg / max)",
                  "pybullet settings", "pybullet at rest at end", "pybullet deepest below ground [mm]"], [
            row(f"{rings} rings; pybullet: V-HACD, {vhacd.collision_parts} convex parts a ring{holes}",
                rings_ms, vhacd),
            row(f"{rings} rings; pybullet: our boundary spheres, {balls.collision_parts} a ring", rings_ms, balls),
            row(f"{fragments} fragments, {seconds:g} s; pybullet: convex hulls", pile_ms, pile),
        ]),
    ])
