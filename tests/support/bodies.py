"""The bodies the dynamics tests check and the report's stability table simulates, defined
once so both describe the same bodies: tet meshes made with tetgen directly (independent of
``taichi_frac.geometry``), cached per process. Density [kg/m^3], lengths [m]."""

import functools

import numpy as np

from taichi_frac.model import build_body_model

DENSITY = 2400.0


def tet_model(mesh, max_volume: float, density: float = DENSITY, group: int = 4):
    """The BodyModel of a closed trimesh ``mesh``, tets of at most ``max_volume`` [m^3]."""
    import tetgen

    gen = tetgen.TetGen(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    # (tetgen reads maxvolume only with fixedvolume: without it a 0.1 m cube is 6 tets
    # whatever ``pieces`` asks)
    vertices, tets = gen.tetrahedralize(order=1, mindihedral=10, minratio=1.5, fixedvolume=True,
                                        maxvolume=max_volume)[:2]
    return build_body_model(vertices, tets, density, boundary_group_size=group)


@functools.lru_cache(maxsize=None)
def box_model(ex: float, ey: float, ez: float, pieces: int = 400, density: float = DENSITY):
    """A box of ``ex`` x ``ey`` x ``ez`` [m], tets of at most 1/``pieces`` of its volume
    (tetgen's quality bound adds more: 740 for a 0.1 m cube at 400)."""
    import trimesh

    mesh = trimesh.creation.box((ex, ey, ez))
    return tet_model(mesh, mesh.volume / pieces, density)


@functools.lru_cache(maxsize=None)
def sphere_model(radius: float, subdivisions: int = 2, pieces: int = 300, density: float = DENSITY):
    """An icosphere of ``radius`` [m], tets of at most 1/``pieces`` of its volume (718 for
    a 5 cm sphere at 300)."""
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return tet_model(mesh, mesh.volume / pieces, density)


@functools.lru_cache(maxsize=None)
def torus_model(pieces: int = 1500, major: float = 0.1, minor: float = 0.025):
    """A torus of radii ``major`` and ``minor`` [m], 40 sections round and 12 round its
    tube, tets of at most 1/``pieces`` of its volume (3,023 at 1500)."""
    import trimesh

    mesh = trimesh.creation.torus(major, minor, major_sections=40, minor_sections=12)
    return tet_model(mesh, mesh.volume / pieces)


@functools.lru_cache(maxsize=None)
def single_tet_model(edge: float = 0.05):
    vertices = np.array([[0, 0, 0], [edge, 0, 0], [0, edge, 0], [0, 0, edge]], dtype=float)
    return build_body_model(vertices, np.array([[0, 1, 2, 3]]), DENSITY, boundary_group_size=4)


@functools.lru_cache(maxsize=None)
def ring_chips(count: int = 36, seed: int = 0, pieces: int = 700, reach: float = 0.02) -> tuple:
    """``count`` chips cut from a porcelain ring (``torus_model(pieces)``: 1,330 tets at the
    default): each the tets whose centroids lie within 0.6-1.4 ``reach`` [m] of a random
    point of its surface (3-47 tets, 1-11 collision spheres at the defaults: the jagged
    pieces a fracture makes). Chips of no tet are left out."""
    ring = torus_model(pieces=pieces)
    centroids = ring.vertices[ring.tets].mean(axis=1)
    surface = np.unique(np.asarray(ring.surface_faces))
    rng = np.random.default_rng(seed)
    chips = []
    for _ in range(count):
        centre = ring.vertices[rng.choice(surface)]
        picked = np.nonzero(np.linalg.norm(centroids - centre, axis=1) < reach * (0.6 + 0.8 * rng.random()))[0]
        if len(picked):
            used, index = np.unique(ring.tets[picked], return_inverse=True)
            chips.append(build_body_model(ring.vertices[used], index.reshape(-1, 4), DENSITY, boundary_group_size=4))
    return tuple(chips)


def drop_heap(world, chips, seed: int = 0, spacing: float = 0.035) -> list[int]:
    """``chips`` (BodyModels) added to ``world`` over a ground at z = 0 (restitution 0.1) in
    a heap: columns on a 3 x 3 grid ``spacing`` [m] apart, 4 cm between layers, each chip
    turned at random (``seed``) and let go 1 cm above the ground or the layer below.
    Returns their body ids."""
    from taichi_frac.kinematics.quaternion import quaternion_matrix

    world.add_ground(0.0, restitution=0.1)
    rng = np.random.default_rng(seed)
    bodies = []
    for k, chip in enumerate(chips):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        low = (chip.vertices @ quaternion_matrix(q).T)[:, 2].min()
        position = ((k % 3) * spacing, ((k // 3) % 3) * spacing, 0.01 - low + 0.04 * (k // 9))
        bodies.append(world.add_body(chip, position, tuple(q), restitution=0.1))
    return bodies


def heap_asleep(world, seed: int, times=(3.0,)) -> tuple[list[int], int]:
    """Drop heap ``seed`` of 36 ring chips (``ring_chips``, ``drop_heap``) into ``world``
    (cleared, its options set) and run it in 20 ms frames of two substeps, as the 13 rings
    run: (the chips asleep at each of ``times`` [s], ascending; the chips)."""
    bodies = drop_heap(world, ring_chips(36, seed=seed), seed=seed)
    asleep = []
    frame = 0
    for seconds in times:
        while frame < round(seconds / 0.02):
            world.advance(0.02, 2)
            frame += 1
        asleep.append(int(world.body_state(bodies)["sleeping"].sum()))
    return asleep, len(bodies)


def stack_rings(world, model, count: int, minor: float = 0.025) -> list[int]:
    """``count`` copies of the flat torus ``model`` (tube radius ``minor`` [m]) stacked on a
    ground at z = 0 added to ``world``, each let down 0.5 mm above the one below it,
    restitution 0; returns their body ids, lowest first. At rest ring k's centre of mass is
    at (2k + 1) ``minor``."""
    world.add_ground(0.0, restitution=0.0)
    gap = 0.0005
    return [world.add_body(model, (0, 0, minor + gap + k * (2 * minor + gap)), restitution=0.0)
            for k in range(count)]


def stack_cubes(world, model, low: float) -> tuple[int, int]:
    """Two copies of the cube ``model`` added to ``world`` on a ground at z = 0, restitution
    0: the lower let down 1 mm above it, the upper 1 mm above the lower, offset 10 / 5 mm
    along x / y. ``low`` [m]: how far the cube reaches below its centre of mass (its
    collision layer's or its surface's). Returns (lower, upper) body ids."""
    world.add_ground(0.0, restitution=0.0)
    return (world.add_body(model, (0, 0, low + 1e-3), restitution=0.0),
            world.add_body(model, (0.01, 0.005, 3 * low + 3e-3), restitution=0.0))


def settle_and_hold(world, bodies, settle_frames: int, hold_frames: int):
    """Advance ``world`` by ``settle_frames`` 20 ms frames (10 substeps each), then by
    ``hold_frames`` more: (the ``bodies``' positions after settling (B,3) [m], their
    ``body_state`` after holding)."""
    for _ in range(settle_frames):
        world.advance(0.02, 10)
    settled = world.body_state(bodies)["position"]
    for _ in range(hold_frames):
        world.advance(0.02, 10)
    return settled, world.body_state(bodies)


def _tilted(world, model, tilt: float, restitution: float, drop: float):
    """Add a frictionless ground at z = 0 and ``model`` turned ``tilt`` [rad] about x, its
    lowest vertex ``drop`` [m] above the ground, at rest: (body id, rotation matrix,
    centre-of-mass position)."""
    from taichi_frac.kinematics.quaternion import quaternion_matrix

    q = (np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0)
    rot = quaternion_matrix(np.array(q))
    position = (0.0, 0.0, drop - float((model.vertices @ rot.T)[:, 2].min()))
    world.add_ground(0.0, friction=0.0, restitution=restitution)
    body = world.add_body(model, position, q, friction=0.0, restitution=restitution)
    return body, rot, position


def tilted_landing(world, model, tilt: float, restitution: float = 0.5, drop: float = 0.1,
                   substeps: int = 10) -> tuple[float, float, float]:
    """``model`` turned ``tilt`` [rad] about x, let fall without spin from ``drop`` [m] (its
    lowest vertex above a ground at z = 0 added to ``world``), nothing with friction: (the
    normal impulse [N s] of the first substep that touches the ground, the closed form for
    a rigid body struck at one point with Newton's restitution e,

        J = (1 + e) v / (1/m + (r x n) . I^-1 (r x n)),

    where v [m/s] is the approach speed the impact rows report, n = +Z and r the lowest
    vertex less the centre of mass, and v). Where the impulse acts decides it: a contact 5 mm
    nearer the centre than the lowest vertex of a tilted ring strikes 5-10 % harder. Choose
    a tilt at which one vertex is clearly lowest (a faceted tube with two level vertices
    touches along their edge)."""
    _, rot, _ = _tilted(world, model, tilt, restitution, drop)
    vertices = model.vertices @ rot.T
    arm = vertices[np.argmin(vertices[:, 2])]
    for _ in range(int(np.ceil(2.0 * np.sqrt(2.0 * drop / 9.81) / 0.01))):
        world.advance(0.01, substeps)
        rows = world.impacts()
        if len(rows["body"]):
            break
    else:
        raise RuntimeError("the body never reached the ground")
    first = rows["substep"] == rows["substep"].min()
    impulse = float(np.einsum("ij,ij->", rows["impulse"][first], rows["normal"][first]))
    speed = float(rows["speed"][first].max())
    lever = np.cross(arm, (0.0, 0.0, 1.0))
    inverse_mass = 1.0 / model.mass + lever @ np.linalg.solve(rot @ model.inertia @ rot.T, lever)
    return impulse, (1.0 + restitution) * speed / inverse_mass, speed


#: [s] how often ``tilted_rebound`` reads the pose (a peak read this often is at most
#: g (1 ms)^2 / 2 = 5 um low).
REBOUND_SAMPLE = 0.002


def tilted_rebound(world, model, tilt: float, substep: float, restitution: float = 0.5, drop: float = 0.3,
                   window: float = 0.5, reference=None):
    """``model`` dropped as in :func:`tilted_landing` (frictionless, from rest, ``drop``
    [m]), simulated with substeps of at most ``substep`` [s] (at most ``REBOUND_SAMPLE``; the
    World shortens them while a body moves more than its spheres' mean radius in one) and
    dropped by the event-driven reference (``rigid_drop.drop``, with the same restitution,
    and the world's restitution threshold and gravity): (the simulated rebound, the
    reference's ``RigidDrop``). The rebound [m] is how far the centre of mass rises above
    its height when the lowest vertex touches, until, having risen, it falls back through
    that height (or ``window`` [s] after the first impact). ``reference``: a reference
    already computed for these mass properties and this drop, to reuse."""
    from . import rigid_drop

    body, rot, position = _tilted(world, model, tilt, restitution, drop)
    if reference is None:
        reference = rigid_drop.drop(model.vertices, model.mass, model.inertia, position, rot, restitution,
                                    world.options.restitution_threshold, window=window,
                                    gravity=-float(world.options.gravity[2]))
    touch = position[2] - drop
    substeps = max(1, round(REBOUND_SAMPLE / substep))
    struck, peak, rose = None, -np.inf, False
    for frame in range(int(np.ceil((2.0 * np.sqrt(2.0 * drop / 9.81) + window) / REBOUND_SAMPLE))):
        world.advance(REBOUND_SAMPLE, substeps)
        if struck is None and world.impact_count():
            struck = frame
        if struck is not None:
            state = world.body_state([body])
            z, rising = float(state["position"][0][2]), state["linear_velocity"][0][2] > 0.0
            peak, rose = max(peak, z), rose or rising
            if (rose and not rising and z < touch) or (frame - struck) * REBOUND_SAMPLE > window:
                break
    if struck is None:
        raise RuntimeError("the body never reached the ground")
    return peak - touch, reference
