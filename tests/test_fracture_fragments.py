"""Fragments (BRIEF.md step 10): conservation at every split, small-fragment policies,
a one-tet fragment, refracture with composed source_tet."""

import numpy as np
import pytest

from support.fracture_ring import RING_CONTACT, RING_FORCE, RING_NORMAL, corner_cracks, struck_ring_model
from taichi_frac.fracture.cracks import CrackPlane, analyze_impact
from taichi_frac.fracture.fragments import make_fragments, split_body
from taichi_frac.kinematics.quaternion import quaternion_matrix
from taichi_frac.geometry.mass import tet_mass_properties
from taichi_frac.options import FractureOptions, Material, ParticleOptions

MATERIAL = Material(name="ring", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1.0e6)
PARTICLES = ParticleOptions(boundary_group_size=4)
POSE = dict(position=np.array([0.3, -0.2, 1.1]), orientation_wxyz=np.array([0.8, 0.2, -0.4, 0.4]),
            linear_velocity=np.array([1.5, -0.4, -3.0]), angular_velocity=np.array([4.0, -7.0, 2.5]))
ORIGIN = np.array([-1.0, 2.0, 0.5])  # fixed world point for angular momentum [m]
TOL = 1e-6


def rigid_totals(vertices, tets, density, position, rot, velocity, omega):
    """Mass, linear momentum and angular momentum about ORIGIN of a rigid tet set whose
    vertices are given in a frame placed at ``position`` with rotation ``rot``: integrated
    here from the tets (geometry.mass), not read from any BodyModel."""
    props = tet_mass_properties(vertices, tets, density)
    com_world = position + rot @ props.center_of_mass
    v_com = velocity + np.cross(omega, rot @ props.center_of_mass)
    inertia_world = rot @ props.inertia @ rot.T
    angular = props.mass * np.cross(com_world - ORIGIN, v_com) + inertia_world @ omega
    return props.mass, props.mass * v_com, angular


def fragment_totals(frags):
    mass, linear, angular = 0.0, np.zeros(3), np.zeros(3)
    for f in frags:
        rot = quaternion_matrix(f.orientation)
        m = f.model
        # Each fragment integrated from its own tets in its own body frame.
        fm, fp, fl = rigid_totals(m.vertices, m.tets, m.density, f.position, rot, f.linear_velocity,
                                  f.angular_velocity)
        assert fm == pytest.approx(m.mass, rel=1e-12)
        mass, linear, angular = mass + fm, linear + fp, angular + fl
    return mass, linear, angular


def assert_conserved(parent, frags, pose, dropped_mass=0.0):
    rot = quaternion_matrix(pose["orientation_wxyz"])
    pm, pp, pl = rigid_totals(parent.vertices, parent.tets, parent.density, pose["position"], rot,
                              pose["linear_velocity"], pose["angular_velocity"])
    fm, fp, fl = fragment_totals(frags)
    assert abs(fm + dropped_mass - pm) <= TOL * pm
    if dropped_mass == 0.0:
        assert np.linalg.norm(fp - pp) <= TOL * np.linalg.norm(pp)
        assert np.linalg.norm(fl - pl) <= TOL * np.linalg.norm(pl)


@pytest.fixture(scope="module")
def ring_split():
    model = struck_ring_model()
    opts = FractureOptions(crack_count=3, crack_length=0.3, seed=0)
    analysis = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, MATERIAL, opts)
    split = split_body(model, analysis, opts)
    frags = make_fragments(model, split, **POSE, material=MATERIAL, particle_options=PARTICLES, options=opts,
                           analysis=analysis, birth_frame=17, parent=4)
    return model, opts, analysis, split, frags


def test_ring_split_conserves_mass_and_momenta(ring_split):
    model, _, analysis, split, frags = ring_split
    assert len(frags) == split.fragment_count >= 2
    assert_conserved(model, frags, POSE)
    # Every parent tet in exactly one fragment; fragments follow the parent's velocity field.
    np.testing.assert_array_equal(np.sort(np.concatenate([f.parent_tets for f in frags])), np.arange(model.tet_count))
    rot = quaternion_matrix(POSE["orientation_wxyz"])
    for f in frags:
        c = f.model.com_in_source
        np.testing.assert_allclose(f.position, POSE["position"] + rot @ c, rtol=0, atol=1e-12)
        np.testing.assert_allclose(f.linear_velocity, POSE["linear_velocity"]
                                   + np.cross(POSE["angular_velocity"], rot @ c), rtol=0, atol=1e-12)
        np.testing.assert_array_equal(f.source_tets, model.source_tet[f.parent_tets])
        assert f.birth_frame == 17 and f.parent == 4 and f.generation == 1 and f.breakable
        assert f.peak_principal_stress == pytest.approx(analysis.particle_principal_stress[f.parent_tets].max())
        np.testing.assert_allclose(f.impact.point, POSE["position"] + rot @ RING_CONTACT, atol=1e-12)
        np.testing.assert_allclose(f.impact.force, rot @ RING_FORCE, atol=1e-9)
        # Crack faces are new surface: more surface particles than the parent had there.
        assert f.model.surface_particle_count > np.count_nonzero(model.is_surface[f.parent_tets])


def test_refracture_composes_source_tets(ring_split):
    model, opts, _, _, frags = ring_split
    piece = max(frags, key=lambda f: f.model.tet_count)
    pose = dict(position=piece.position, orientation_wxyz=piece.orientation,
                linear_velocity=piece.linear_velocity, angular_velocity=piece.angular_velocity)
    # Hit the piece on its particle farthest from its centre, pushing toward the centre.
    x = piece.model.particle_position
    far = x[np.argmax(np.linalg.norm(x, axis=1))]
    normal = -far / np.linalg.norm(far)
    again_opts = FractureOptions(crack_count=2, crack_length=0.3, seed=1)
    a = analyze_impact(piece.model, far, normal, 1e4 * normal, MATERIAL, again_opts)
    split = split_body(piece.model, a, again_opts)
    assert a.any_crack and split.fragment_count >= 2
    kids = make_fragments(piece.model, split, **pose, material=MATERIAL, particle_options=PARTICLES,
                          options=again_opts, analysis=a, parent_generation=piece.generation)
    assert_conserved(piece.model, kids, pose)
    root_volume = model.tet_volume
    for k in kids:
        assert k.generation == 2
        # source_tet indexes the ROOT mesh: the same tets, so the same volumes.
        assert np.isin(k.source_tets, piece.source_tets).all()
        np.testing.assert_allclose(k.model.tet_volume, root_volume[k.source_tets], rtol=1e-9)
    np.testing.assert_array_equal(np.sort(np.concatenate([k.source_tets for k in kids])), np.sort(piece.source_tets))
    last = make_fragments(piece.model, split, **pose, material=MATERIAL, particle_options=PARTICLES,
                          options=FractureOptions(max_generations=1), parent_generation=1)
    assert not any(f.breakable for f in last)  # generation 2 > max_generations 1


def test_fragment_model_restricted_from_parent_matches_a_fresh_build(ring_split):
    """build_fragment_model restricts the parent's topology and keeps the parent's boundary
    groups away from the cracks; build_body_model rebuilds everything from the tet subset.
    The tets, topology, surface and mass properties are the same; the boundary layer is a
    valid grouping of the same surface (each surface particle in one group, a group's
    sphere encloses its members), keeps the parent's spheres where the surface is the
    parent's, and its collision centres are those contact_sphere_centres computes for
    every group afresh. The SPH neighbour lists restricted from the root's are those a
    grid search over the fragment's particles finds at the root's h."""
    from taichi_frac.fracture.neighbors import model_neighbor_lists, smoothing_length
    from taichi_frac.fracture.sph import neighbor_lists
    from taichi_frac.geometry.collision_centres import contact_sphere_centres
    from taichi_frac.model import build_body_model

    model, opts, _, _, frags = ring_split
    h = smoothing_length(model, opts)
    kept_total = 0
    for f in frags:
        m = f.model
        fresh = build_body_model(model.vertices, model.tets[f.parent_tets], model.density,
                                 boundary_group_size=PARTICLES.boundary_group_size, source_tet=f.source_tets)
        for name in ("tets", "tet_neighbor", "bonds", "surface_faces", "surface_face_tet", "surface_particles",
                     "source_tet"):
            np.testing.assert_array_equal(getattr(m, name), getattr(fresh, name), err_msg=name)
        for name in ("vertices", "tet_volume", "particle_position", "inertia"):
            np.testing.assert_allclose(getattr(m, name), getattr(fresh, name), rtol=1e-9, atol=1e-15, err_msg=name)
        # A valid grouping of the fragment's surface particles.
        off, members = m.boundary_member_offsets, m.boundary_members
        owner = np.repeat(np.arange(len(off) - 1), np.diff(off))
        np.testing.assert_array_equal(np.sort(np.concatenate([members, m.dropped_surface_particles])),
                                      m.surface_particles)
        np.testing.assert_allclose(m.boundary_mass, np.bincount(owner, m.particle_mass[members]), rtol=1e-12)
        reach = np.linalg.norm(m.particle_position[members] - m.boundary_position[owner], axis=1)
        assert np.all(reach + m.particle_radius[members] <= m.boundary_radius[owner] * (1 + 1e-12))
        # The parent's spheres, where the parent's surface is untouched.
        parent_groups = {tuple(model.boundary_members[a:b]): k for k, (a, b) in
                         enumerate(zip(model.boundary_member_offsets[:-1], model.boundary_member_offsets[1:]))}
        for g in range(len(off) - 1):
            k = parent_groups.get(tuple(f.parent_tets[members[off[g]:off[g + 1]]]))
            if k is not None:
                kept_total += 1
                np.testing.assert_allclose(m.boundary_position[g] + m.com_in_source, model.boundary_position[k],
                                           atol=1e-12)
                assert m.boundary_radius[g] == pytest.approx(model.boundary_radius[k], rel=1e-12)
        # Collision centres: those computed for every group afresh.
        centres = contact_sphere_centres(m.vertices, m.surface_faces, m.surface_face_tet, m.particle_position,
                                         members, owner, m.boundary_position, m.boundary_radius)
        np.testing.assert_allclose(m.collision_position, centres, rtol=0, atol=1e-12)
        assert m.root is model and m.spacing == model.spacing
        assert smoothing_length(m, opts) == h
        offsets, indices = model_neighbor_lists(m, h)
        grid_offsets, grid_indices = neighbor_lists(m.particle_position, h)
        np.testing.assert_array_equal(offsets, grid_offsets)
        np.testing.assert_array_equal(indices, grid_indices)
    assert kept_total > 0.3 * sum(f.model.boundary_particle_count for f in frags)  # 294 of 589 here


@pytest.mark.parametrize("coarse", [0, 12])
def test_pieces_built_together_are_the_pieces_built_alone(coarse):
    """build_fragment_models builds a split's pieces in one batch. Each model is, array for
    array and to the bit, the one built of that piece alone (a batch of one), also for
    the pieces of a piece: the batch leaks nothing between pieces (their vertices,
    boundary groups, inward rays, normals). Also when the pieces are grouped by
    different n (``coarse_group_size``: the big piece by 12, the chips by 4)."""
    import dataclasses

    from taichi_frac.model import BodyModel, build_body_model, build_fragment_model, build_fragment_models

    model = struck_ring_model()
    if coarse:
        model = build_body_model(model.vertices, model.tets, model.density, coarse_group_size=coarse)
        assert model.boundary_group_size == coarse
    opts = FractureOptions(crack_count=5, crack_length=0.3, seed=0, min_fragment_particles=1)
    analysis = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, MATERIAL, opts)
    pieces = split_body(model, analysis, opts).fragment_tets
    sizes = sorted(len(p) for p in pieces)
    assert len(pieces) >= 6 and sizes[0] < 30 and sizes[-1] > 1000  # chips and a big piece
    parents = [model]
    big = build_fragment_model(model, pieces[int(np.argmax([len(p) for p in pieces]))], boundary_group_size=4)
    assert big.coarse_group_size == coarse
    second = split_body(big, [CrackPlane(point=big.particle_position[k], normal=np.eye(3)[k % 3], extent=0.05,
                                         peak_stress=2e6) for k in (0, big.tet_count // 2)], opts).fragment_tets
    assert len(second) >= 2
    for parent, parts in ((model, pieces), (big, second)):
        together = build_fragment_models(parent, parts, boundary_group_size=4)
        if coarse:
            assert {m.boundary_group_size for m in together} == {4, coarse}
        for tets, batched in zip(parts, together):
            alone = build_fragment_model(parent, tets, boundary_group_size=4)
            for f in dataclasses.fields(BodyModel):
                a, b = getattr(batched, f.name), getattr(alone, f.name)
                if isinstance(a, np.ndarray):
                    assert a.dtype == b.dtype and a.shape == b.shape, f.name
                    assert np.array_equal(a, b), f"{f.name} differs (piece of {len(tets)} tets)"
                else:
                    assert a is b or a == b, f.name
    with pytest.raises(ValueError, match="overlap"):
        build_fragment_models(model, [np.arange(10), np.arange(5, 20)])


def test_pieces_are_grouped_by_their_own_size():
    """With ``coarse_group_size``, each piece of a split is grouped by the coarse n when it
    has at least COARSE_MIN_SPHERES x n surface particles (counted here from its own tets'
    open faces) and by the fine n otherwise; no group is larger than its n, and a piece
    grouped like its parent keeps the parent's groups away from the cracks."""
    from taichi_frac.model import COARSE_MIN_SPHERES, build_body_model, build_fragment_models

    ring = struck_ring_model()
    parent = build_body_model(ring.vertices, ring.tets, ring.density, coarse_group_size=12)
    opts = FractureOptions(crack_count=5, crack_length=0.3, seed=0, min_fragment_particles=1)
    analysis = analyze_impact(parent, RING_CONTACT, RING_NORMAL, RING_FORCE, MATERIAL, opts)
    pieces = split_body(parent, analysis, opts).fragment_tets
    parent_groups = {tuple(parent.boundary_members[a:b]) for a, b in
                     zip(parent.boundary_member_offsets[:-1], parent.boundary_member_offsets[1:])}
    seen = set()
    for tets, m in zip(pieces, build_fragment_models(parent, pieces, boundary_group_size=4)):
        surface = int(np.any(m.tet_neighbor < 0, axis=1).sum())
        n = 12 if surface >= COARSE_MIN_SPHERES * 12 else 4
        seen.add(n)
        assert m.boundary_group_size == n and m.coarse_group_size == 12
        sizes = np.diff(m.boundary_member_offsets)
        assert sizes.max() <= n
        groups = [tuple(tets[m.boundary_members[a:b]]) for a, b in
                  zip(m.boundary_member_offsets[:-1], m.boundary_member_offsets[1:])]
        kept = sum(g in parent_groups for g in groups)
        if n == 12:
            assert sizes.mean() > 9 and kept > 0.3 * len(groups)
        else:
            assert kept == 0
    assert seen == {4, 12}


@pytest.mark.parametrize("policy", ["merge", "debris", "drop"])
def test_small_fragment_policies(policy):
    model = struck_ring_model()
    tet = int(model.surface_particles[0])
    cracks = corner_cracks(model, tet)
    opts = FractureOptions(min_fragment_particles=8, small_fragment_policy=policy)
    split = split_body(model, cracks, opts)
    assert split.component_count >= 2
    frags = make_fragments(model, split, **POSE, material=MATERIAL, particle_options=PARTICLES, options=opts)
    sizes = np.array([len(t) for t in split.fragment_tets])
    tet_mass = model.density * model.tet_volume
    if policy == "merge":
        assert split.fragment_count == 1 and sizes[0] == model.tet_count and not split.broke
        assert_conserved(model, frags, POSE)
    elif policy == "debris":
        assert split.fragment_count == split.component_count
        np.testing.assert_array_equal(split.fragment_is_debris, sizes < 8)
        assert split.fragment_is_debris.any()
        assert [f.breakable for f in frags] == [not d for d in split.fragment_is_debris]
        assert_conserved(model, frags, POSE)
    else:
        assert split.fragment_count == 1 and len(split.dropped_tets) > 0 and split.broke
        assert split.dropped_mass == pytest.approx(tet_mass[split.dropped_tets].sum(), rel=1e-12)
        assert_conserved(model, frags, POSE, dropped_mass=split.dropped_mass)


def test_one_tet_fragment_is_a_valid_body():
    model = struck_ring_model()
    tet = int(model.surface_particles[0])
    opts = FractureOptions(min_fragment_particles=1)
    split = split_body(model, corner_cracks(model, tet), opts)
    frags = make_fragments(model, split, **POSE, material=MATERIAL, particle_options=PARTICLES, options=opts)
    single = [f for f in frags if f.model.tet_count == 1]
    assert single and tet in [int(f.parent_tets[0]) for f in single]
    for f in frags:
        m = f.model
        assert np.isfinite(m.inertia).all() and np.all(np.linalg.eigvalsh(m.inertia) > 0)
        assert m.boundary_particle_count >= 1 and np.isfinite(f.position).all()
        assert np.isfinite(f.linear_velocity).all()
    one = next(f for f in single if int(f.parent_tets[0]) == tet)
    assert one.model.mass == pytest.approx(model.particle_mass[tet], rel=1e-12)
    assert one.model.surface_particle_count == 1 and len(one.model.surface_faces) == 4
    assert_conserved(model, frags, POSE)


@pytest.mark.parametrize("generations", [1, 3])
def test_big_piece_mass_by_subtraction_matches_integration(generations):
    """The big piece left when a chip breaks off gets its mass properties as the parent's
    less the chip's (model._mass_by_subtraction); integrated afresh from its own tets
    they agree to round-off, also after chips broken off three times in a row (each
    generation's parent is itself a subtracted piece)."""
    from taichi_frac.model import build_fragment_model

    model = struck_ring_model()
    piece = model
    for g in range(generations):
        keep = np.arange(40, piece.tet_count)  # a chip of 40 tets off the front
        piece = build_fragment_model(piece, keep, boundary_group_size=4)
    root = model
    direct = tet_mass_properties(root.vertices, root.tets[np.sort(piece.source_tet)], root.density)
    assert piece.mass == pytest.approx(direct.mass, rel=1e-12)
    # The piece's frame is at its own centre of mass, and its inertia is about it.
    own = tet_mass_properties(piece.vertices, piece.tets, piece.density)
    np.testing.assert_allclose(own.center_of_mass, 0.0, atol=1e-12 * np.ptp(root.vertices))
    np.testing.assert_allclose(piece.inertia, own.inertia, rtol=0, atol=1e-11 * np.abs(own.inertia).max())
    np.testing.assert_allclose(piece.inertia, direct.inertia, rtol=0, atol=1e-11 * np.abs(own.inertia).max())


@pytest.mark.parametrize("cut_fraction", [0.0, 0.04, 0.3, 0.7])
def test_connected_tets_match_scipy(cut_fraction):
    """geometry.components.connected_tets (union-find in a kernel) against scipy's
    connected_components on the ring's bonds with a random fraction cut: the same count
    and the same labels (numbered by smallest tet), from one piece to thousands."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from taichi_frac.geometry.components import connected_tets

    model = struck_ring_model()
    cut = np.random.default_rng(int(100 * cut_fraction)).random(len(model.bonds)) < cut_fraction
    kept = model.bonds[~cut]
    graph = sp.coo_matrix((np.ones(len(kept)), (kept[:, 0], kept[:, 1])), shape=(model.tet_count,) * 2)
    expected_count, expected = connected_components(graph, directed=False)
    count, labels = connected_tets(model.tet_count, model.bonds, cut)
    assert count == expected_count and np.array_equal(labels, expected)


def test_a_piece_born_in_the_ground_is_lifted_to_the_allowed_penetration(ring_split):
    """fracture.stage.lift_out_of_ground: a piece whose lowest collision sphere starts 4 mm
    below the highest ground plane is moved straight up until that sphere reaches the
    allowed penetration (the fraction x its mean boundary radius, hand-computed below);
    velocities and orientation are untouched; a piece above the ground, or a scene with
    no ground, is left where it is."""
    import dataclasses

    from taichi_frac.fracture.stage import lift_out_of_ground

    piece = ring_split[4][0]
    m = piece.model
    rot = quaternion_matrix(piece.orientation)

    def lowest(p):
        return float(np.min(p.position[2] + m.collision_position @ rot[2] - m.boundary_radius))

    grounds = [-0.5, 0.1]  # the higher plane is the one that counts
    def moved(dz):
        return dataclasses.replace(piece, position=piece.position + np.array([0.0, 0.0, dz]))

    sunk = moved(grounds[1] - 0.004 - lowest(piece))
    assert lowest(sunk) == pytest.approx(grounds[1] - 0.004, abs=1e-12)
    lifted = lift_out_of_ground(sunk, grounds, 0.01)
    allowed = 0.01 * float(m.boundary_radius.mean())
    assert lowest(lifted) == pytest.approx(grounds[1] - allowed, abs=1e-12)
    np.testing.assert_array_equal(lifted.position[:2], sunk.position[:2])
    np.testing.assert_array_equal(lifted.linear_velocity, sunk.linear_velocity)
    np.testing.assert_array_equal(lifted.orientation, sunk.orientation)
    above = moved(grounds[1] + 0.01 - lowest(piece))
    assert lift_out_of_ground(above, grounds, 0.01) is above
    assert lift_out_of_ground(sunk, [], 0.01) is sunk
