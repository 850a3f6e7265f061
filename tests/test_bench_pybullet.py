"""The pybullet reference of ``bench dynamics`` (benchmarks/pybullet_ref.py).

- without pybullet: our scene description -> pybullet bodies (masses, inertia, poses,
  quaternion order, coefficients, the fragment pile) against closed forms and hand values;
- with pybullet: one ring dropped comes to rest on the ground with its hole open, and a
  compound of more than 16 spheres (pybullet's createCollisionShapeArray limit) rests on
  its spheres.
"""

import dataclasses
import math

import numpy as np
import pytest
import trimesh

from benchmarks import pybullet_ref
from benchmarks.common import SCENES
from taichi_frac.scenes import load_scene

RING_MAJOR, RING_MINOR = 0.1, 0.025  # m, scenes/thirteen_rings.toml's torus
PORCELAIN_DENSITY = 2400.0  # kg/m^3


def _euler_matrix(euler_deg) -> np.ndarray:
    """R = Rz(c) Ry(b) Rx(a), extrinsic X then Y then Z (Blender's XYZ Euler), by hand."""
    a, b, c = np.radians(euler_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _quaternion_xyzw_matrix(q) -> np.ndarray:
    """The rotation of a quaternion in pybullet's (x, y, z, w) order, via trimesh (which
    takes (w, x, y, z)): independent of pybullet_ref's own conversion."""
    x, y, z, w = q
    return trimesh.transformations.quaternion_matrix([w, x, y, z])[:3, :3]


def test_thirteen_rings_conversion():
    scene = load_scene(SCENES / "thirteen_rings.toml")
    bodies, statics = pybullet_ref.scene_bodies(scene)
    assert [b.name for b in bodies] == [o.name for o in scene.objects]
    # Closed-form torus: V = 2 pi^2 R r^2; I_zz = m (R^2 + 3/4 r^2), I_xx = m (R^2/2 + 5/8 r^2).
    # Our surface is volume-matched (1e-6); its inertia is faceted (400 vertices): 1 %.
    mass = PORCELAIN_DENSITY * 2 * math.pi**2 * RING_MAJOR * RING_MINOR**2
    inertia = mass * np.array([RING_MAJOR**2 / 2 + 5 / 8 * RING_MINOR**2] * 2 + [RING_MAJOR**2 + 0.75 * RING_MINOR**2])
    for body, obj in zip(bodies, scene.objects):
        assert body.mass == pytest.approx(mass, rel=1e-5)
        np.testing.assert_allclose(body.inertia_diagonal, inertia, rtol=0.01)
        np.testing.assert_allclose(body.surface.center_mass, 0.0, atol=1e-12)
        np.testing.assert_array_equal(body.position, obj.position)
        w, x, y, z = obj.orientation
        np.testing.assert_array_equal(body.orientation_xyzw, [x, y, z, w])
        np.testing.assert_allclose(_quaternion_xyzw_matrix(body.orientation_xyzw), _euler_matrix(obj.euler_deg),
                                   atol=1e-12)
        assert (body.friction, body.restitution) == (0.5, 0.1)
    # ring01: euler_deg (37, 23, 53): its axis (the body Z axis) in the world, by hand.
    a, b, c = np.radians([37.0, 23.0, 53.0])
    axis = [math.cos(c) * math.sin(b) * math.cos(a) + math.sin(c) * math.sin(a),
            math.sin(c) * math.sin(b) * math.cos(a) - math.cos(c) * math.sin(a), math.cos(b) * math.cos(a)]
    np.testing.assert_allclose(_quaternion_xyzw_matrix(bodies[1].orientation_xyzw)[:, 2], axis, atol=1e-12)
    assert [(s.type, s.height, s.friction, s.restitution) for s in statics] == [("ground", 0.0, 0.6, 0.1)]
    # pybullet multiplies the two coefficients: ring-ground friction sqrt(0.5 x 0.6) as ours.
    assert pybullet_ref.pybullet_coefficient(0.5) * pybullet_ref.pybullet_coefficient(0.6) == pytest.approx(
        math.sqrt(0.3), rel=1e-12)
    assert pybullet_ref.pybullet_coefficient(0.1) ** 2 == pytest.approx(0.1, rel=1e-12)


def test_fragment_pile_conversion():
    bodies, statics = pybullet_ref.fragment_pile(216)
    assert len(bodies) == 216
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=0.02)
    assert bodies[0].mass == pytest.approx(PORCELAIN_DENSITY * sphere.volume, rel=1e-12)
    positions = np.array([b.position for b in bodies])
    # dynamics._fragment_pile's lattice: 6 x 6 x 6 points 0.05 m apart, x and y centred on 0,
    # the lowest layer at z = 0.025 m (a fragment of radius 0.02 m 5 mm above the ground
    # before its jitter of 3 mm standard deviation: some start a little in the ground, in
    # ours too), every point used once.
    pitch = 0.05
    lattice = (positions - [-2.5 * pitch, -2.5 * pitch, 0.5 * pitch]) / pitch
    cells = np.round(lattice).astype(int)
    assert np.abs(lattice - cells).max() * pitch < 4 * 0.003
    assert len({tuple(c) for c in cells}) == 216 and cells.min() == 0 and cells.max() == 5
    assert np.abs(positions[:, :2]).max() < 0.2 - 0.02  # inside the walls' inner faces
    assert [s.type for s in statics] == ["ground", "box", "box", "box", "box"]


def _one_ring_scene(height: float = 0.15, tilt: float = 0.1):
    """Ring 0 of the 13-ring scene alone (its surface, hence its cached V-HACD parts, are
    the bench's), dropped from ``height`` [m], tilted ``tilt`` [rad] about x."""
    scene = load_scene(SCENES / "thirteen_rings.toml")
    ring = dataclasses.replace(scene.objects[0], position=(0.0, 0.0, height), euler_deg=None,
                               orientation=(math.cos(tilt / 2), math.sin(tilt / 2), 0.0, 0.0))
    return dataclasses.replace(scene, objects=[ring])


def test_one_ring_rests_on_the_ground_in_pybullet():
    """Sanity of the reference scene. V-HACD takes ~15 s on a cold cache (once: the
    decomposition is kept in vhacd_cache_dir(), shared with the bench), ~1 s after."""
    pytest.importorskip("pybullet")
    run = pybullet_ref.run_rings(_one_ring_scene(), "vhacd", seconds=1.0)
    assert run.collision_parts > 1
    assert run.centre_ray_blocked == 0, "the V-HACD compound fills the ring's hole"
    assert run.at_rest.all()
    assert abs(run.lowest_surface[0]) < 2e-3, f"ring surface {1e3 * run.lowest_surface[0]:.2f} mm above the ground"
    assert run.deepest_below_ground < 1e-4
    assert (run.steps_per_frame, run.time_step) == (5, pytest.approx(0.004))
    # The hole check itself: one convex hull of the ring fills the hole.
    assert pybullet_ref.run_rings(_one_ring_scene(), "hull", seconds=0.02).centre_ray_blocked == 1


def test_sphere_compound_beyond_sixteen_rests_on_its_spheres():
    """32 beads on the ring's centre circle (the URDF compound; createCollisionShapeArray
    would keep 16) comes to rest with its lowest bead on the ground, not into it."""
    pytest.importorskip("pybullet")
    scene = _one_ring_scene(height=0.1, tilt=0.05)
    angles = np.linspace(0, 2 * math.pi, 32, endpoint=False)
    centres = RING_MAJOR * np.stack([np.cos(angles), np.sin(angles), np.zeros(32)], axis=1)
    radii = np.full(32, RING_MINOR)
    run = pybullet_ref.run_rings(scene, "spheres", [(centres, radii)], seconds=1.0)
    assert run.collision_parts == 32
    assert run.at_rest.all()
    assert abs(run.lowest_collision[0]) < 5e-4
