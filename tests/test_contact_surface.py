"""Surface contacts (``DynamicsOptions(surface_contact=True)``): bodies rest on their true
surface, not on their collision spheres, and a chip never falls through a body.

References: the closed-form rest heights of a polyhedron on a plane (its centre of mass
above its lowest vertex: half the edge for a cube on a face, half the face diagonal on an
edge; the minor radius for a torus lying flat, whose mesh has vertices on the true
surface at the bottom of the tube)."""

import math

import numpy as np
import pytest
import trimesh

from taichi_frac.geometry.tetra import tetrahedralize
from taichi_frac.geometry.contact_patches import contact_patches
from taichi_frac.model import build_body_model
from taichi_frac.bench.bodies import box_model, ring_model, single_tet_model, stack_rings
from support.dynamics import fresh_world, rotation

#: Rest heights within this of exact [m] (the bound surface contact is held to).
REST_TOLERANCE = 0.5e-3


def _settle(model, position, orientation, seconds, restitution=0.0):
    world = fresh_world(surface_contact=True)
    world.add_ground(0.0, restitution=restitution)
    body = world.add_body(model, position, orientation, restitution=restitution)
    for _ in range(int(round(seconds / 0.02))):
        world.advance(0.02, 10)
    return world.body_state([body])


def test_patches_are_the_members_boundary_triangles():
    """Every vertex of a group's members' boundary faces is in its patch, once; a flat
    group's normal is its face normal; a closed tet's patch has no normal."""
    model = box_model(0.1, 0.1, 0.1)
    patches = model.boundary_patches
    off = model.boundary_member_offsets
    for g in range(model.boundary_particle_count):
        members = set(model.boundary_members[off[g]:off[g + 1]].tolist())
        faces = model.surface_faces[np.isin(model.surface_face_tet, list(members))]
        expected = model.vertices[np.unique(faces)]
        got = patches.points[patches.offsets[g]:patches.offsets[g + 1]]
        assert len(got) == len(expected)
        np.testing.assert_allclose(np.sort(got, axis=0), np.sort(expected, axis=0))
    top = np.all(np.isclose(model.vertices[np.unique(model.surface_faces[
        np.isin(model.surface_face_tet, model.boundary_members[off[0]:off[1]])])][:, 2], model.vertices[:, 2].max()))
    if top:
        np.testing.assert_allclose(patches.normals[0], [0, 0, 1], atol=1e-12)
    tet = single_tet_model()
    chip = contact_patches(tet, tet.boundary_member_offsets, tet.boundary_members)
    assert len(chip.points) == 4 and np.all(chip.normals == 0.0)


def test_cube_rests_flat_at_half_its_edge():
    state = _settle(box_model(0.1, 0.1, 0.1), (0, 0, 0.06), (1, 0, 0, 0), 1.0)
    assert state["position"][0][2] == pytest.approx(0.05, abs=REST_TOLERANCE)
    assert state["sleeping"][0]


def test_cube_on_its_edge_rests_at_half_the_face_diagonal():
    half = math.pi / 8  # 45 degrees about x
    state = _settle(box_model(0.1, 0.1, 0.1), (0, 0, 0.0717), (math.cos(half), math.sin(half), 0, 0), 0.3)
    assert state["position"][0][2] == pytest.approx(0.05 * math.sqrt(2.0), abs=REST_TOLERANCE)


def test_torus_rests_flat_at_its_minor_radius():
    model = ring_model()
    assert -model.vertices[:, 2].min() == pytest.approx(0.025, abs=1e-9)  # (a vertex on the true bottom)
    state = _settle(model, (0, 0, 0.05), (1, 0, 0, 0), 1.5, restitution=0.2)
    assert state["position"][0][2] == pytest.approx(0.025, abs=REST_TOLERANCE)
    # ... where sphere contacts leave it on its spheres, which stand proud of the tube.
    world = fresh_world(surface_contact=False)
    world.add_ground(0.0)
    body = world.add_body(model, (0, 0, 0.05))
    for _ in range(75):
        world.advance(0.02, 10)
    assert world.body_state([body])["position"][0][2] > 0.025 + 2 * REST_TOLERANCE


def test_chip_dropped_at_10_m_s_never_falls_through_a_flat_body():
    """Forty one-tet chips (1 cm) dropped at 10 m/s, spinning, on a 0.6 m slab resting on
    the ground, more than one collision-sphere radius in from its edges: every one ends
    on the slab's top face (COM above it by at most the chip's size), none inside it or
    under it. (Within a sphere radius of the edges, where the patches fold over the
    edge, 3 of 40 still sank: docs/guide/contact.md.)"""
    mesh = tetrahedralize(trimesh.creation.box((0.6, 0.6, 0.1)), target_tets=3000)
    slab = build_body_model(mesh.vertices, mesh.tets, 2400.0)
    chip = single_tet_model(0.01)
    world = fresh_world(surface_contact=True)
    world.add_ground(0.0)
    world.add_body(slab, (0, 0, 0.05))
    xy = np.random.default_rng(0).uniform(-0.2, 0.2, size=(40, 2))
    chips = [world.add_body(chip, (x, y, 0.2), (1, 0, 0, 0), (0, 0, -10.0), (3, 1, 0)) for x, y in xy]
    lowest = np.inf
    for _ in range(40):
        world.advance(0.01, 10)
        state = world.body_state(chips)
        for x, q in zip(state["position"], state["orientation"]):
            lowest = min(lowest, float(np.min((chip.vertices @ rotation(q).T + x)[:, 2])))
    top = 0.1
    assert lowest > top - 2e-3  # no chip's surface ever more than 2 mm into the slab
    z = world.body_state(chips)["position"][:, 2]
    assert np.all(z > top) and np.all(z < top + 0.01)


def test_chips_on_the_ground_come_to_rest_and_sleep():
    """Thirty-six one-tet chips (2 cm) thrown spinning onto the ground come to rest on a
    face and sleep within 2 s, as they do on their spheres: each patch holds the ground
    at up to four points of its face (``surface.manifold``), where one contact under the
    face's middle let a chip rock from corner to corner forever. At rest every chip lies
    on a face: its lowest three vertices on the ground (within 0.5 mm)."""
    chip = single_tet_model(0.02)
    world = fresh_world(surface_contact=True, sleep_time=0.25)
    world.add_ground(0.0)
    rng = np.random.default_rng(1)
    chips = []
    for k in range(36):
        q = rng.normal(size=4)
        chips.append(world.add_body(chip, ((k % 6) * 0.06, (k // 6) * 0.06, 0.05 + 0.03 * rng.random()),
                                    tuple(q / np.linalg.norm(q)), (0, 0, -1.0), tuple(rng.normal(0, 3, 3))))
    for _ in range(100):
        world.advance(0.02, 10)
    state = world.body_state(chips)
    assert state["sleeping"].all()
    for x, q in zip(state["position"], state["orientation"]):
        heights = np.sort((chip.vertices @ rotation(q).T + x)[:, 2])
        np.testing.assert_allclose(heights[:3], 0.0, atol=REST_TOLERANCE)


def test_a_resting_ring_stands_on_a_few_contacts_that_carry_its_weight():
    """A torus of many spheres resting flat touches the ground with every patch along its
    bottom circle; ``collision.reduction`` keeps the deepest and the outermost of them in
    each of ``DIRECTIONS`` directions (of the touching ones and of the near ones). The
    touching ones outline the circle (two of them a major diameter apart, within 10 %),
    carry the ring's weight (summed normal impulse
    m g dt per substep, within 2 %: static equilibrium) and hold it at its rest height."""
    from taichi_frac.collision import reduction

    model = ring_model()
    world = fresh_world(surface_contact=True, sleep_time=100.0)
    world.add_ground(0.0, restitution=0.0)
    body = world.add_body(model, (0, 0, 0.0255), restitution=0.0)
    for _ in range(50):
        world.advance(0.02, 10)
    state = world.body_state([body])
    assert not state["sleeping"][0]
    assert state["position"][0][2] == pytest.approx(0.025, abs=REST_TOLERANCE)
    n = int(world.contacts.count[None])
    ground = world.contacts.body_b.to_numpy()[:n] < 0
    assert 3 <= ground.sum() <= 1 + 2 * reduction.DIRECTIONS
    touching = ground & (world.contacts.separation.to_numpy()[:n] < REST_TOLERANCE)
    points = world.contacts.point.to_numpy()[:n][touching]
    spread = np.max(np.linalg.norm(points[:, None, :2] - points[None, :, :2], axis=2))
    assert spread == pytest.approx(0.2, rel=0.1)
    impulse = world.contacts.normal_impulse.to_numpy()[:n][ground].sum()
    assert impulse == pytest.approx(model.mass * 9.81 * 0.002, rel=0.02)


def test_rings_stacked_flat_rest_on_their_tubes():
    """Three tori stacked flat (unbreakable, restitution 0) rest each one tube diameter
    above the one below (COM heights 25, 75 and 125 mm, exact for the mesh: its vertices
    at the top and bottom of the tube lie on the true surface), within 0.5 mm per ring,
    and fall asleep without drifting: the contact between two bodies' patches is their
    hulls' distance (``surface.hull_pair``). On their spheres each ring stands about 5 mm
    higher than the one below."""
    world = fresh_world(surface_contact=True)
    rings = stack_rings(world, ring_model(), 3)
    for _ in range(50):
        world.advance(0.02, 10)
    settled = world.body_state(rings)["position"]
    for _ in range(25):
        world.advance(0.02, 10)
    state = world.body_state(rings)
    for k in range(3):
        assert state["position"][k][2] == pytest.approx(0.025 + 0.05 * k, abs=(k + 1) * REST_TOLERANCE)
    assert np.max(np.abs(state["position"] - settled)) < 1e-4
    assert state["sleeping"].all()


def test_ring_rests_on_a_slab_at_its_minor_radius():
    """A torus lying flat on a tet-meshed slab (a box-shaped body of many patches) rests
    at the slab's top plus its minor radius, within 0.5 mm."""
    mesh = tetrahedralize(trimesh.creation.box((0.4, 0.4, 0.05)), target_tets=1500)
    slab = build_body_model(mesh.vertices, mesh.tets, 2400.0)
    model = ring_model()
    world = fresh_world(surface_contact=True)
    world.add_ground(0.0, restitution=0.0)
    world.add_body(slab, (0, 0, 0.025), restitution=0.0)
    ring = world.add_body(model, (0, 0, 0.0505 + 0.0255), restitution=0.0)
    for _ in range(50):
        world.advance(0.02, 10)
    assert world.body_state([ring])["position"][0][2] == pytest.approx(0.075, abs=REST_TOLERANCE)
