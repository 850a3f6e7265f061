"""Controllable cracks (BRIEF.md steps 8-9): grouping, Rankine, bond cutting, and the
ring's fragment counts against crack_count."""

import numpy as np
import pytest

from support.fracture_ring import RING_CONTACT, RING_FORCE, RING_NORMAL, struck_ring_model
from taichi_frac.fracture.cracks import (CrackPlane, RingCrack, analyze_impact, cut_bonds, group_neighbors,
                                        tangent_frame)
from taichi_frac.fracture.fragments import split_body
from taichi_frac.fracture.sph import displacement_gradient
from taichi_frac.model import build_body_model
from taichi_frac.options import FractureOptions, Material

# The documented controllability material (docs/guide/fracture-controls.md): porcelain-like
# stiffness, a tensile strength the 10 kN impact exceeds at the analysis point.
RING_MATERIAL = Material(name="ring", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1.0e6)


def two_tets():
    """Two tets sharing the face z = 0 triangle; centroids at z = +1/4 and -1/4."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    return build_body_model(v, np.array([[0, 1, 2, 3], [0, 2, 1, 4]]), 1000.0)


def test_sectors_follow_azimuth_from_seeded_start():
    normal = np.array([0.0, 0.0, 1.0])
    e1, e2 = tangent_frame(normal)
    assert abs(e1 @ normal) < 1e-15 and abs(e2 @ normal) < 1e-15 and abs(np.cross(e1, e2) @ normal - 1) < 1e-15
    angles = np.radians([10.0, 100.0, 190.0, 280.0, 359.0])
    pts = np.stack([np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2][0]) + 0.3 * normal
    sector = group_neighbors(pts, np.arange(5), np.zeros(3), normal, 4, np.radians(5.0))
    np.testing.assert_array_equal(sector, [0, 1, 2, 3, 3])
    sector = group_neighbors(pts, np.arange(5), np.zeros(3), normal, 2, np.radians(50.0))
    np.testing.assert_array_equal(sector, [1, 0, 0, 1, 1])  # 10 deg lies 320 deg past 50


def test_cut_bonds_by_plane_and_extent():
    model = two_tets()
    c = model.particle_position.mean(axis=0)
    across = CrackPlane(point=c, normal=np.array([0.0, 0.0, 1.0]), extent=0.01, peak_stress=1.0)
    assert cut_bonds(model, [across]).tolist() == [True]
    far = CrackPlane(point=c + [5.0, 0, 0], normal=np.array([0.0, 0.0, 1.0]), extent=1.0, peak_stress=1.0)
    assert cut_bonds(model, [far]).tolist() == [False]  # crossing point 5 m outside the disc
    parallel = CrackPlane(point=c, normal=np.array([1.0, 0.0, 0.0]), extent=10.0, peak_stress=1.0)
    assert cut_bonds(model, [parallel]).tolist() == [False]  # segment lies along the plane side
    split = split_body(model, [across], FractureOptions(min_fragment_particles=1))
    assert split.fragment_count == 2 and [t.tolist() for t in split.fragment_tets] == [[0], [1]]


@pytest.mark.parametrize("plane_count", [9, 70])
def test_many_planes_cut_what_each_cuts_alone(plane_count):
    """cut_bonds with many crack planes at once (their sides packed as the bits of one
    integer per particle up to 62 planes, compared plane by plane above) cuts exactly the
    union of what each plane cuts alone, on the ring's bonds."""
    from support.fracture_ring import struck_ring_model

    model = struck_ring_model()
    rng = np.random.default_rng(plane_count)
    planes = []
    for _ in range(plane_count):
        normal = rng.normal(size=3)
        # (points off the particles: a plane through a centroid puts it on the plane only
        # up to the last bit, which one product and another round differently)
        point = model.particle_position[rng.integers(model.tet_count)] + rng.normal(size=3) * 1e-3
        planes.append(CrackPlane(point=point,
                                 normal=normal / np.linalg.norm(normal), extent=float(rng.uniform(0.005, 0.05)),
                                 peak_stress=1.0))
    union = np.zeros(len(model.bonds), dtype=bool)
    for plane in planes:
        union |= cut_bonds(model, [plane])
    together = cut_bonds(model, planes)
    assert union.sum() > 100 and np.array_equal(together, union)


def test_ring_crack_cuts_the_bonds_across_its_sphere():
    """A RingCrack cuts a bond when one centroid lies inside its sphere and the other not;
    on the ring, a sphere about a point of the tube cuts out exactly the tets whose
    centroids lie within its radius (checked against the distances, independently of the
    bonds)."""
    model = two_tets()
    top, bottom = model.particle_position
    assert cut_bonds(model, [RingCrack(point=top, radius=0.3, peak_stress=1.0)]).tolist() == [True]
    assert cut_bonds(model, [RingCrack(point=top, radius=0.6, peak_stress=1.0)]).tolist() == [False]  # both in
    assert cut_bonds(model, [RingCrack(point=top + 5.0, radius=0.6, peak_stress=1.0)]).tolist() == [False]
    ring = struck_ring_model()
    centre, radius = np.array([0.1, 0.0, 0.0]), 0.03
    split = split_body(ring, [RingCrack(point=centre, radius=radius, peak_stress=1.0)],
                       FractureOptions(min_fragment_particles=1))
    inside = np.linalg.norm(ring.particle_position - centre, axis=1) < radius
    assert 0 < inside.sum() < ring.tet_count // 10
    # Every piece lies wholly inside or wholly outside, and the inside ones make the ball
    # (a tet whose face neighbours all lie across the sphere is a piece of its own).
    sides = [set(inside[t].tolist()) for t in split.fragment_tets]
    assert all(len(side) == 1 for side in sides)
    chips = [t for t, side in zip(split.fragment_tets, sides) if side == {True}]
    np.testing.assert_array_equal(np.sort(np.concatenate(chips)), np.nonzero(inside)[0])
    assert max(len(t) for t in split.fragment_tets) > 0.9 * ring.tet_count  # the rest of the ring


def test_ring_cracks_cut_the_wedges_into_rings():
    """ring_crack_count = m adds m spheres about each cracking contact's analysis point,
    radii crack_length x j / (m + 1), after its n planes; they cut the planar cracks'
    pieces further, and 0 (the default) changes nothing."""
    model = struck_ring_model()
    counts = {}
    for rings in (0, 2):
        opts = FractureOptions(crack_count=3, crack_length=0.3, seed=0, ring_crack_count=rings, stress_model="sph")
        a = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, RING_MATERIAL, opts)
        planes = [c for c in a.cracks if isinstance(c, CrackPlane)]
        spheres = [c for c in a.cracks if isinstance(c, RingCrack)]
        assert len(planes) == 3 and len(spheres) == rings
        assert [s.radius for s in spheres] == pytest.approx([0.1, 0.2][:rings], rel=1e-12)
        for s in spheres:
            np.testing.assert_array_equal(s.point, a.analysis_point[0])
        split = split_body(model, a, opts)
        assert sum(len(t) for t in split.fragment_tets) == model.tet_count
        counts[rings] = split.fragment_count
    assert counts[0] == 5  # the documented crack_count 3 (docs/guide/fracture-controls.md)
    assert counts[2] > counts[0], counts


def test_rankine_and_one_group_is_the_physical_answer():
    model = struck_ring_model()
    strong = Material(name="strong", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1e9)
    none = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, strong,
                          FractureOptions(crack_count=3, stress_model="halfspace"))
    assert not none.any_crack and none.peak_principal_stress < 1e9
    one = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, RING_MATERIAL,
                         FractureOptions(crack_count=1, stress_model="halfspace"))
    assert one.any_crack and len(one.cracks) == 1
    i = int(one.analysis_particle[0])
    # The analysis point carries the largest principal stress within 2 h of the contact ...
    near = np.linalg.norm(model.particle_position - RING_CONTACT, axis=1) <= 2 * one.smoothing_length
    assert one.particle_principal_stress[i] == pytest.approx(one.particle_principal_stress[near].max(), rel=0)
    assert one.particle_principal_stress[i] > RING_MATERIAL.tensile_strength
    # ... and n = 1 is the full-neighbourhood stress there: same tensor, normal along its
    # largest principal direction (up to sign).
    np.testing.assert_allclose(one.group_stress[0, 0], one.particle_stress[i], rtol=1e-9, atol=1e-6)
    w, v = np.linalg.eigh(one.particle_stress[i])
    assert abs(abs(one.cracks[0].normal @ v[:, -1]) - 1.0) < 1e-9
    # Below the force threshold nothing is analysed.
    quiet = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, RING_MATERIAL,
                           FractureOptions(impact_force_threshold=2e4, stress_model="halfspace"))
    assert len(quiet.contact_point) == 0 and not quiet.any_crack


def test_group_gradient_uses_only_its_sector():
    """A group's stress equals an independent plain-sum gradient over that sector's
    neighbours (recomputed here from the neighbour list and the sector rule)."""
    model = struck_ring_model()
    opts = FractureOptions(crack_count=3, seed=4, stress_model="halfspace")
    a = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, RING_MATERIAL, opts)
    i = int(a.analysis_particle[0])
    x = model.particle_position
    d = np.linalg.norm(x - x[i], axis=1)
    nbrs = np.nonzero((d > 0) & (d < a.smoothing_length))[0]
    from taichi_frac.fracture.cracks import start_angle

    sector = group_neighbors(x, nbrs, x[i], RING_NORMAL, 3, start_angle(4, 0))
    np.testing.assert_array_equal(np.bincount(sector, minlength=3), a.group_neighbor_count[0])
    assert a.group_neighbor_count[0].sum() == len(nbrs)
    assert len(a.cracks) == 3
    normals = np.stack([c.normal for c in a.cracks])
    assert np.all(np.abs(normals @ normals.T - np.eye(3)) < 0.999)  # three different planes


def test_several_contacts_analysed_together_give_the_union():
    model = struck_ring_model()
    second = np.array([-0.125, 0.0, 0.0])
    opts = FractureOptions(crack_count=2, crack_length=0.05, stress_model="halfspace")
    both = analyze_impact(model, np.stack([RING_CONTACT, second]), np.stack([RING_NORMAL, -RING_NORMAL]),
                          np.stack([RING_FORCE, -RING_FORCE]), RING_MATERIAL, opts)
    assert sorted({c.impact_index for c in both.cracks}) == [0, 1] and len(both.cracks) == 4
    assert np.all(np.isfinite(both.particle_stress))
    cut = cut_bonds(model, both.cracks)
    per_contact = [cut_bonds(model, [c for c in both.cracks if c.impact_index == k]) for k in (0, 1)]
    np.testing.assert_array_equal(cut, per_contact[0] | per_contact[1])
    assert per_contact[0].any() and per_contact[1].any() and not (per_contact[0] & per_contact[1]).any()
    split = split_body(model, both, opts)
    assert split.fragment_count >= 1 and np.isfinite(split.fragment_peak_stress).all()


def ring_counts(crack_counts, seed=0):
    model = struck_ring_model()
    counts = []
    for n in crack_counts:
        opts = FractureOptions(crack_count=n, crack_length=0.3, seed=seed, stress_model="sph")
        a = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, RING_MATERIAL, opts)
        counts.append(split_body(model, a, opts).fragment_count)
    return counts


def test_ring_fragment_count_grows_with_crack_count_and_repeats():
    counts = ring_counts(range(1, 7))
    assert all(b >= a for a, b in zip(counts, counts[1:])), counts
    # The documented settings under the paper's SPH stress: n = 1, 3, 5 give 2, 5 and about 10 fragments.
    assert counts[0] == 2 and counts[2] == 5 and 9 <= counts[4] <= 12, counts
    assert ring_counts([3, 5]) == [counts[2], counts[4]]  # same seed, same answer


def test_local_analysis_of_a_crack_of_given_length_needs_no_full_field():
    """With crack_length given, a cracking impact's analysis stays local: the crack planes
    (origin, normal, extent) are those of the full field, the stress is NaN away from the
    contact; the simulation computes the whole field only when the cracks split the body."""
    model = struck_ring_model()
    material = Material(name="m", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=1.0e6)
    options = FractureOptions(crack_count=3, seed=4, crack_length=0.04, stress_model="halfspace")
    full = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, material, options)
    fast = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, material, options, full_field=False)
    assert len(full.cracks) == len(fast.cracks) == 3
    assert fast.field_particles is not None and 0 < len(fast.field_particles) < model.tet_count / 10
    for a, b in zip(fast.cracks, full.cracks):
        np.testing.assert_allclose(a.point, b.point, rtol=0, atol=0)
        np.testing.assert_allclose(a.normal, b.normal, rtol=0, atol=1e-12)
        assert a.extent == b.extent == 0.04
    np.testing.assert_array_equal(cut_bonds(model, fast.cracks), cut_bonds(model, full.cracks))


@pytest.mark.parametrize("strength", [1.0e6, 1.0e9], ids=["cracks", "no-crack"])
def test_local_first_analysis_matches_the_full_field(strength):
    """analyze_impact(full_field=False) (the simulation's call) computes the stress first at
    the particles within reach of the contact: the same analysis point, Rankine decision,
    cracks and stress there as the full field; the whole field, and the sector stresses of
    step 9, only when it cracks."""
    model = struck_ring_model()
    material = Material(name="m", density=2400.0, young_modulus=70e9, poisson_ratio=0.2, tensile_strength=strength)
    options = FractureOptions(crack_count=3, seed=4, stress_model="halfspace")
    full = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, material, options)
    fast = analyze_impact(model, RING_CONTACT, RING_NORMAL, RING_FORCE, material, options, full_field=False)
    assert full.field_particles is None
    np.testing.assert_array_equal(fast.analysis_particle, full.analysis_particle)
    assert len(fast.cracks) == len(full.cracks) == (3 if strength == 1.0e6 else 0)
    for a, b in zip(fast.cracks, full.cracks):
        np.testing.assert_allclose(a.normal, b.normal, rtol=0, atol=1e-12)
        assert a.extent == pytest.approx(b.extent, rel=1e-12)
    if strength == 1.0e6:  # cracked: the whole field and the groups were computed
        np.testing.assert_allclose(fast.group_stress, full.group_stress, rtol=1e-12, atol=1e-6)
        assert fast.field_particles is None
        np.testing.assert_allclose(fast.particle_stress, full.particle_stress, rtol=1e-12, atol=1e-6)
    else:  # only the particles within reach of the contact, a small part of the ring
        local = fast.field_particles
        assert 0 < len(local) < model.tet_count / 10
        np.testing.assert_allclose(fast.particle_stress[local], full.particle_stress[local], rtol=1e-12, atol=1e-6)
        assert np.isnan(fast.particle_principal_stress).sum() == model.tet_count - len(local)
        assert fast.peak_principal_stress <= full.peak_principal_stress
        # No contact passed the Rankine test: its sector stresses (crack directions) are
        # not needed, and not computed.
        assert np.isnan(fast.group_stress).all() and not fast.group_neighbor_count.any()


def test_neighbor_rows_of_a_piece_are_its_restricted_lists_rows():
    """neighbors.neighbor_rows: the rows of a piece's SPH neighbour lists, read from its
    root's lists without restricting them over the whole piece, equal those rows of the
    whole restriction (same neighbours, same order); a local analysis of the piece then
    finds the same cracks as a full-field one."""
    from taichi_frac.fracture.neighbors import (model_neighbor_lists, neighbor_rows, restrict_neighbor_lists,
                                                smoothing_length)
    from taichi_frac.model import build_fragment_model

    root = struck_ring_model()
    options = FractureOptions(crack_count=3, seed=4, crack_length=0.04, stress_model="halfspace")
    h = smoothing_length(root, options)
    piece = build_fragment_model(root, np.arange(300, root.tet_count, dtype=np.int64), boundary_group_size=4)
    off, idx = restrict_neighbor_lists(*model_neighbor_lists(root, h), piece.source_tet, root.tet_count)
    query = np.sort(np.random.default_rng(2).choice(piece.tet_count, 150, replace=False))
    r_off, r_idx = neighbor_rows(piece, h, query)
    assert len(r_off) == len(query) + 1
    for q, i in enumerate(query):
        np.testing.assert_array_equal(r_idx[r_off[q]:r_off[q + 1]], idx[off[i]:off[i + 1]])
    fast = analyze_impact(piece, RING_CONTACT - piece.com_in_source, RING_NORMAL, RING_FORCE, RING_MATERIAL, options,
                          full_field=False)
    full = analyze_impact(piece, RING_CONTACT - piece.com_in_source, RING_NORMAL, RING_FORCE, RING_MATERIAL, options)
    assert len(fast.cracks) == len(full.cracks) == 3
    for a, b in zip(fast.cracks, full.cracks):
        np.testing.assert_allclose(a.normal, b.normal, rtol=0, atol=1e-12)


@pytest.mark.parametrize("corrected", [True, False])
def test_fused_stress_kernel_equals_the_three_kernels(corrected):
    """``fused.stress_at`` (displacement, SPH gradient and stress in one launch, the
    analysis's path) against ``point_loads_displacement``, ``displacement_gradient`` and
    ``stress_from_gradient`` run one after the other on a ring's impact: the displacement
    where asked, zero elsewhere, and the stress at a few hundred particles near the
    contact and at scattered ones (the same functions: to 1e-12 of the largest stress).
    Its principal stresses (the largest in closed form, and with ``decompose`` all three
    and their directions) against ``largest_principal_stress`` and ``principal_stresses``
    on the separate stress."""
    from taichi_frac.fracture.neighbors import model_neighbor_lists, neighbor_rows, smoothing_length
    from taichi_frac.fracture.field import load_rows, point_loads_displacement
    from taichi_frac.fracture.fused import stress_at
    from taichi_frac.fracture.stress import stress_from_gradient

    model = struck_ring_model()
    material = RING_MATERIAL
    h = smoothing_length(model, FractureOptions())
    points = np.ascontiguousarray(model.particle_position)
    near = np.nonzero(np.linalg.norm(points - RING_CONTACT, axis=1) < 2.5 * h)[0]
    query = np.union1d(near, np.arange(0, model.tet_count, 97)).astype(np.int32)
    model_neighbor_lists(model, h)
    offsets, indices = neighbor_rows(model, h, query)
    where = np.unique(np.concatenate([query, indices]))
    radius = [float(model.particle_radius[near[0]])]
    loads = load_rows(RING_CONTACT[None], RING_NORMAL[None], RING_FORCE[None], radius)

    fused_u = np.zeros((model.tet_count, 3))
    fused, largest = stress_at(points, model.tet_volume, fused_u, loads, where, query, offsets, indices, h, corrected,
                               material)
    _, largest_again, values, directions = stress_at(points, model.tet_volume, np.zeros_like(fused_u), loads, where,
                                                     query, offsets, indices, h, corrected, material, decompose=True)
    u = np.zeros((model.tet_count, 3))
    u[where] = point_loads_displacement(points[where], RING_CONTACT[None], RING_NORMAL[None], RING_FORCE[None],
                                        material.shear_modulus, material.poisson_ratio, radius)
    grad = displacement_gradient(points, model.tet_volume, u, offsets, indices, h, corrected, query)
    separate = stress_from_gradient(grad, material.young_modulus, material.poisson_ratio)
    assert len(query) > 200 and np.abs(separate).max() > 1e6
    np.testing.assert_allclose(fused_u, u, rtol=1e-12, atol=1e-12 * np.abs(u).max())
    np.testing.assert_allclose(fused, separate, rtol=0, atol=1e-12 * np.abs(separate).max())
    from taichi_frac.fracture.stress import largest_principal_stress, principal_stresses

    scale = np.abs(separate).max()
    np.testing.assert_allclose(largest, largest_principal_stress(separate), rtol=0, atol=1e-8 * scale)
    assert np.array_equal(largest, largest_again)
    expected_values, expected_directions = principal_stresses(separate)
    np.testing.assert_allclose(values, expected_values, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(values[:, 0], largest, rtol=0, atol=1e-8 * scale)
    np.testing.assert_allclose(np.abs(np.einsum("qke,qke->qe", directions, expected_directions)), 1.0, atol=1e-6)
