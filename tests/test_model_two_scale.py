"""The two-scale BodyModel against closed forms and conservation laws."""

import math

import numpy as np
import pytest
import trimesh

from taichi_frac.geometry import primitives
from taichi_frac.geometry.tetra import tetrahedralize
from taichi_frac.geometry.rays import ray_exit_distance
from taichi_frac.model import build_body_model

DENSITY = 2400.0


@pytest.fixture(scope="module")
def ring_tets():
    return tetrahedralize(primitives.torus(0.1, 0.025, edge_length=0.006), target_tets=12000)


@pytest.fixture(scope="module")
def ring(ring_tets):
    return build_body_model(ring_tets.vertices, ring_tets.tets, DENSITY)


def test_torus_mass_com_inertia_closed_form(ring):
    R, r = 0.1, 0.025
    m = DENSITY * 2 * math.pi**2 * R * r**2
    assert ring.mass == pytest.approx(m, rel=5e-3)
    assert np.linalg.norm(ring.com_in_source) < 1e-3 * R
    izz = m * (R**2 + 0.75 * r**2)            # solid torus about its axis
    ixx = m * (0.5 * R**2 + 0.625 * r**2)     # about a diameter
    assert np.diag(ring.inertia) == pytest.approx([ixx, ixx, izz], rel=5e-3)
    off = ring.inertia - np.diag(np.diag(ring.inertia))
    assert np.abs(off).max() < 1e-3 * izz


def test_offset_box_mass_com_inertia_closed_form():
    a, b, c = 0.3, 0.2, 0.1
    surface = primitives.box((a, b, c))
    surface.apply_translation((1.0, -2.0, 0.5))
    tm = tetrahedralize(surface, target_tets=2000)
    model = build_body_model(tm.vertices, tm.tets, DENSITY)
    m = DENSITY * a * b * c
    assert model.mass == pytest.approx(m, rel=1e-9)
    assert model.com_in_source == pytest.approx([1.0, -2.0, 0.5], abs=1e-9)
    expected = m / 12.0 * np.array([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    assert model.inertia == pytest.approx(np.diag(expected), rel=5e-3, abs=1e-9 * expected.max())
    # The body frame is centred: mass-weighted particle centroid at the origin.
    assert np.abs(model.particle_mass @ model.particle_position).max() < 1e-12


def test_particles_are_tet_centroids_with_volume_radius(ring):
    p = ring.vertices[ring.tets]
    assert np.allclose(ring.particle_position, p.mean(axis=1))
    assert np.allclose(ring.particle_mass, DENSITY * ring.tet_volume)
    assert np.allclose(4 / 3 * math.pi * ring.particle_radius**3, ring.tet_volume)
    assert ring.particle_mass.sum() == pytest.approx(ring.mass, rel=1e-12)


def test_bonds_are_shared_faces(ring):
    shared = [len(set(ring.tets[i]) & set(ring.tets[j])) for i, j in ring.bonds[:2000]]
    assert set(shared) == {3}
    # Euler-type count: every tet face is either a bond side or a boundary face.
    assert 2 * len(ring.bonds) + len(ring.surface_faces) == 4 * ring.tet_count


def test_surface_particles_are_tets_with_boundary_faces(ring):
    assert np.array_equal(ring.surface_particles, np.unique(ring.surface_face_tet))
    assert np.array_equal(np.nonzero(ring.is_surface)[0], ring.surface_particles)
    # Boundary faces tile the closed surface: their area-weighted normals sum to zero.
    v = ring.vertices[ring.surface_faces]
    assert np.abs(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]).sum(axis=0)).max() < 1e-12


@pytest.mark.parametrize("group_size,keep", [(4, True), (4, False), (3, True), (8, False), (1, True)])
def test_boundary_groups_partition_enclose_and_conserve(ring_tets, group_size, keep):
    model = build_body_model(ring_tets.vertices, ring_tets.tets, DENSITY,
                             boundary_group_size=group_size, keep_leftovers=keep)
    members = model.boundary_members
    # Every surface particle is in exactly one boundary particle, or reported dropped.
    everything = np.concatenate([members, model.dropped_surface_particles])
    assert len(everything) == len(np.unique(everything))
    assert np.array_equal(np.sort(everything), model.surface_particles)
    if keep:
        assert len(model.dropped_surface_particles) == 0
    sizes = np.diff(model.boundary_member_offsets)
    assert sizes.min() >= 1 and sizes.max() <= group_size
    if group_size > 1:
        assert sizes.mean() > 0.8 * group_size  # groups are mostly full
    owner = np.repeat(np.arange(model.boundary_particle_count), sizes)
    # Each boundary sphere encloses its members' spheres.
    reach = np.linalg.norm(model.particle_position[members] - model.boundary_position[owner], axis=1)
    assert np.all(reach + model.particle_radius[members] <= model.boundary_radius[owner] * (1 + 1e-12))
    # Centroid of members; mass = sum of members; total mass conserved.
    centroid = np.stack([np.bincount(owner, model.particle_position[members, k]) for k in range(3)], 1) / sizes[:, None]
    assert np.allclose(model.boundary_position, centroid)
    dropped_mass = model.particle_mass[model.dropped_surface_particles].sum()
    assert model.boundary_mass.sum() + dropped_mass == pytest.approx(model.particle_mass[model.surface_particles].sum(), rel=1e-12)


def test_groups_are_adjacent_patches(ring):
    # Members of a group lie close together: within a few particle radii of their centroid.
    sizes = np.diff(ring.boundary_member_offsets)
    owner = np.repeat(np.arange(ring.boundary_particle_count), sizes)
    reach = np.linalg.norm(ring.particle_position[ring.boundary_members] - ring.boundary_position[owner], axis=1)
    assert np.percentile(reach / ring.particle_radius.mean(), 99) < 6.0


def test_collision_spheres_sit_closer_to_the_true_surface_and_cover_their_members(ring):
    # Torus R = 0.1, r = 0.025 (the fixture): a point's distance to the tube's centre circle
    # plus a sphere's radius is how far the sphere reaches from the tube axis; 0.025 is the
    # true surface. Enclosing spheres stand ~6.6 mm proud of it on average; the collision
    # spheres, moved inward along the group's normal, less than half of that. They still
    # hold every member's centroid, so their union leaves no hole between groups.
    def reach(centres):
        rho = np.hypot(centres[:, 0], centres[:, 1])
        return np.hypot(rho - 0.1, centres[:, 2]) + ring.boundary_radius - 0.025

    enclosing = reach(ring.boundary_position)
    contact = reach(ring.collision_position)
    assert enclosing.mean() > 4e-3
    assert contact.mean() < 0.5 * enclosing.mean() and contact.min() > -1e-3
    sizes = np.diff(ring.boundary_member_offsets)
    owner = np.repeat(np.arange(len(sizes)), sizes)
    to_member = np.linalg.norm(ring.particle_position[ring.boundary_members] - ring.collision_position[owner], axis=1)
    assert np.all(to_member <= ring.boundary_radius[owner] * (1 + 1e-9))
    assert np.all(np.linalg.norm(ring.collision_position - ring.boundary_position, axis=1) <= ring.boundary_radius)


def test_ray_exit_distance_matches_a_hand_computed_box():
    # Unit cube [0,1]^3 (12 triangles). Rays from inside: exit distances by hand; a ray
    # whose exit lies beyond its reach reports inf.
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    vertices, faces = np.asarray(box.vertices) + 0.5, np.asarray(box.faces)
    origin = np.array([[0.5, 0.5, 0.5], [0.2, 0.3, 0.9], [0.1, 0.5, 0.5], [0.5, 0.5, 0.5]])
    direction = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    reach = np.array([2.0, 2.0, 2.0, 0.3])
    got = ray_exit_distance(vertices, faces, origin, direction, reach)
    np.testing.assert_allclose(got[:3], [0.5, 0.9, 0.5 * np.sqrt(2.0)], rtol=1e-12)
    assert got[3] == np.inf


def reference_groups(positions, surface, face_tet, faces, group_size, keep_leftovers):
    """The greedy grouping walk of ``geometry.surface_groups`` written plainly in Python
    (adjacency from sets of the particles at each boundary vertex): the reference the
    kernel is checked against. Returns (groups: lists of tet indices, dropped)."""
    local = {int(t): k for k, t in enumerate(surface)}
    at_vertex = {}
    for t, face in zip(face_tet.tolist(), faces.tolist()):
        for v in face:
            at_vertex.setdefault(v, set()).add(local[t])
    adjacent = [set() for _ in surface]
    for sharing in at_vertex.values():
        for p in sharing:
            adjacent[p] |= sharing
    adjacent = [sorted(a) for a in adjacent]
    pos = positions[surface].tolist()
    free, visited = [True] * len(surface), [False] * len(surface)
    groups, dropped = [], []
    for start in range(len(surface)):
        if visited[start]:
            continue
        queue, visited[start] = [start], True
        for seed in queue:  # (the list grows while it is walked: breadth first)
            for m in adjacent[seed]:
                if not visited[m]:
                    visited[m] = True
                    queue.append(m)
            if not free[seed]:
                continue
            members, free[seed], frontier = [seed], False, adjacent[seed]
            for _ in range(3):
                cand = sorted({m for m in frontier if free[m]}, key=lambda m: (math.dist(pos[m], pos[seed]), m))
                for m in cand[:group_size - len(members)]:
                    free[m] = False
                    members.append(m)
                if len(members) >= group_size:
                    break
                frontier = [m for member in members for m in adjacent[member]]
            if len(members) == 1 and not keep_leftovers:
                dropped.append(int(surface[seed]))
            else:
                groups.append([int(surface[m]) for m in members])
    return groups, dropped


@pytest.mark.parametrize("group_size,keep", [(4, True), (3, False), (8, True)])
def test_grouping_walk_matches_a_python_reference(ring, group_size, keep):
    """The kernel's greedy walk makes the groups the plain Python walk makes, member for
    member and in order, on the ring's whole surface and on a patch of it (a crack side's
    few hundred particles). They may part only at near-ties: two candidates whose
    distances to the seed round to the same value in one arithmetic and not the other
    (the kernel compares squared distances), so >= 99 % of the groups must agree."""
    from taichi_frac.geometry.surface_groups import group_surface_particles

    for surface in (ring.surface_particles, ring.surface_particles[:300]):
        on = np.isin(ring.surface_face_tet, surface)
        args = (ring.particle_position, surface, ring.surface_face_tet[on], ring.surface_faces[on], group_size, keep)
        members, sizes, dropped = group_surface_particles(*args)
        expected, expected_dropped = reference_groups(*args)
        got = [g.tolist() for g in np.split(members, np.cumsum(sizes)[:-1])]
        assert abs(len(got) - len(expected)) <= 0.01 * len(expected)
        same = len({tuple(g) for g in got} & {tuple(g) for g in expected})
        assert same >= 0.99 * len(expected), f"{same} of {len(expected)} groups agree"
        if keep:
            assert len(dropped) == len(expected_dropped) == 0
        else:
            assert abs(len(dropped) - len(expected_dropped)) <= max(2, 0.01 * len(surface))


def numpy_collision_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius):
    """``contact_sphere_centres``' formula written in numpy, one body (the kernel's
    reference; the rays through ``ray_exit_distance``)."""
    n_groups = len(b_pos)
    group_of_tet = np.full(len(centroids), -1)
    group_of_tet[members] = owner
    group = group_of_tet[face_tet]
    mine = np.nonzero(group >= 0)[0]
    group = group[mine]
    corners = vertices[faces[mine]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal *= np.sign(((corners.mean(axis=1) - centroids[face_tet[mine]]) * normal).sum(axis=1))[:, None]
    n_sum = np.zeros((n_groups, 3))
    np.add.at(n_sum, group, normal)
    length = np.linalg.norm(n_sum, axis=1)
    has_normal = length > 1e-12 * length.max()
    n_unit = np.where(has_normal[:, None], n_sum / np.maximum(length, 1e-300)[:, None], 0.0)
    h = np.full(n_groups, -np.inf)
    np.maximum.at(h, group, ((corners - b_pos[group][:, None, :]) * n_unit[group][:, None, :]).sum(axis=2).max(axis=1))
    rel = centroids[members] - b_pos[owner]
    along = (rel * n_unit[owner]).sum(axis=1)
    rho = np.zeros(n_groups)
    np.maximum.at(rho, owner, np.sqrt(np.maximum((rel * rel).sum(axis=1) - along ** 2, 0.0)))
    shift = np.where(has_normal & np.isfinite(h), np.minimum(b_radius, np.sqrt(np.maximum(b_radius ** 2 - rho ** 2, 0)))
                     - h, 0.0)
    todo = shift > 0
    thickness = np.full(n_groups, np.inf)
    thickness[todo] = ray_exit_distance(vertices, faces, b_pos[todo], -n_unit[todo], shift[todo] + b_radius[todo])
    shift = np.maximum(np.minimum(shift, thickness - b_radius), 0.0)
    return b_pos - shift[:, None] * n_unit


def test_collision_centres_kernel_matches_numpy(ring):
    """The collision centres' kernel (geometry.collision_centres) against the formula in
    numpy: on the ring's every group, and on the pieces of a split built together (each
    piece's inward rays may cross only its own faces) against each piece alone."""
    from support.fracture_ring import RING_CONTACT, RING_FORCE, RING_NORMAL
    from taichi_frac.fracture.cracks import analyze_impact
    from taichi_frac.fracture.fragments import split_body
    from taichi_frac.geometry.collision_centres import contact_sphere_centres
    from taichi_frac.model import build_fragment_models
    from taichi_frac.options import FractureOptions, Material

    def arguments(m):
        owner = np.repeat(np.arange(m.boundary_particle_count), np.diff(m.boundary_member_offsets))
        return (m.vertices, m.surface_faces, m.surface_face_tet, m.particle_position, m.boundary_members, owner,
                m.boundary_position, m.boundary_radius)

    expected = numpy_collision_centres(*arguments(ring))
    assert np.abs(expected - ring.boundary_position).max() > 0.2 * ring.particle_radius.mean()  # they move
    np.testing.assert_allclose(contact_sphere_centres(*arguments(ring)), expected, rtol=0, atol=1e-12)
    material = Material(name="ring", density=DENSITY, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1e6)
    opts = FractureOptions(crack_count=5, crack_length=0.1, seed=1, min_fragment_particles=1)
    pieces = split_body(ring, analyze_impact(ring, RING_CONTACT, RING_NORMAL, RING_FORCE, material, opts),
                        opts).fragment_tets
    assert len(pieces) >= 4
    for piece in build_fragment_models(ring, pieces, boundary_group_size=4):
        np.testing.assert_allclose(piece.collision_position, numpy_collision_centres(*arguments(piece)), rtol=0,
                                   atol=1e-12)


def test_group_sizes_coarsen_only_bodies_with_enough_surface():
    """``model.group_sizes``: the coarse n from COARSE_MIN_SPHERES x n surface particles on
    (hand-computed for 32 x 12 = 384), the fine n below it, for single-scale and when no
    coarse n is given."""
    from taichi_frac.model import COARSE_MIN_SPHERES, group_sizes

    assert COARSE_MIN_SPHERES == 32
    np.testing.assert_array_equal(group_sizes([0, 383, 384, 5000], 4, 12), [4, 4, 12, 12])
    np.testing.assert_array_equal(group_sizes([383, 384], 4, 0), [4, 4])
    np.testing.assert_array_equal(group_sizes([5000], 1, 12), [1])


def test_mass_properties_are_the_same_bits_with_one_or_two_blas_threads():
    """A body's centre of mass and inertia start every pile's chaos: they must not depend on
    how many threads OpenBLAS splits a long product among (a threaded dot product sums in
    another order). The same tets in two processes, one and two BLAS threads, bit for bit."""
    import os
    import subprocess
    import sys

    script = (
        "import numpy as np\n"
        "from taichi_frac.geometry.mass import tet_mass_properties\n"
        "rng = np.random.default_rng(5)\n"
        "vertices = rng.normal(size=(40000, 3)) + [3.0, -1.0, 0.5]\n"
        "tets = rng.integers(0, len(vertices), size=(60000, 4))\n"
        "props = tet_mass_properties(vertices, tets, 2400.0, np.abs(rng.normal(size=len(tets))) + 0.1)\n"
        "print(props.center_of_mass.tobytes().hex(), props.inertia.tobytes().hex())\n")
    answers = {subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                              env=dict(os.environ, OPENBLAS_NUM_THREADS=str(threads))).stdout
               for threads in (1, 2)}
    assert len(answers) == 1
