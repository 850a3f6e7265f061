"""Hashed-grid broadphase + sphere narrowphase against a brute-force numpy pair search."""

import numpy as np

from taichi_frac.dynamics import stages
from test_dynamics_support import fresh_world, single_tet_model, with_spheres


def test_particle_contacts_match_brute_force():
    world = fresh_world(gravity=(0.0, 0.0, 0.0))
    rng = np.random.default_rng(3)
    centres, radii, owners = [], [], []
    for body in range(40):
        offsets = rng.uniform(-0.05, 0.05, (12, 3))
        r = rng.uniform(0.004, 0.012, 12)
        model = with_spheres(single_tet_model(), offsets, r)
        position = rng.uniform(-0.25, 0.25, 3)
        b = world.add_body(model, position, (1, 0, 0, 0))
        centres.append(offsets + position)
        radii.append(r)
        owners.append(np.full(12, b))
    centres, radii, owners = np.concatenate(centres), np.concatenate(radii), np.concatenate(owners)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, 1e-3,
                   world.options.sleep_time)
    count = int(world.contacts.count[None])
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    gap = d - radii[:, None] - radii[None]
    close = (gap < margin * 0.5 * (radii[:, None] + radii[None])) & (owners[:, None] != owners[None])
    expected = np.sort(gap[np.triu(close, 1)])
    assert count == len(expected) and count > 20
    got = np.sort(world.contacts.separation.to_numpy()[:count])
    np.testing.assert_allclose(got, expected, atol=2e-6)
    assert world.contacts.overflow[None] == 0


def test_moving_ring_contacts_match_brute_force_with_the_speculative_reach():
    """Rings of spheres (the cluster spheres must leave out their holes, not the particles
    near them), turned and moving at random: the sphere pairs made equal a brute-force
    search with the speculative reach of narrowphase._speculative, written out here: the
    gap may close by the two points' approach speed along the normal x dt, plus
    (|w_a|^2 |arm_a| + |w_b|^2 |arm_b|) / 2 dt^2 + |g| dt^2."""
    from taichi_frac.geometry.rotation import quaternion_matrix

    g = 9.81
    world = fresh_world(gravity=(0.0, 0.0, -g))
    rng = np.random.default_rng(7)
    dt = 4e-3
    angle = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    ring = np.stack([0.08 * np.cos(angle), 0.08 * np.sin(angle), 0.01 * np.sin(3 * angle)], axis=1)
    centres, radii, owners, slots, velocity, spin = [], [], [], [], [], []
    for body in range(24):
        r = rng.uniform(0.006, 0.012, len(ring))
        model = with_spheres(single_tet_model(), ring, r)
        position = rng.uniform(-0.2, 0.2, 3)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        v, w = rng.normal(0.0, 1.5, 3), rng.normal(0.0, 8.0, 3)
        b = world.add_body(model, position, q, v, w)
        x = position + ring @ quaternion_matrix(q).T
        start, count = world._body_range[b]
        centres.append(x)
        radii.append(r)
        owners.append(np.full(count, b))
        slots.append(start + np.arange(count))
        velocity.append(v + np.cross(w, x - position))
        spin.append(np.full(count, w @ w) * np.linalg.norm(x - position, axis=1))
    x, r, owner, slot = map(np.concatenate, (centres, radii, owners, slots))
    vel, curve = np.concatenate(velocity), 0.5 * np.concatenate(spin)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, dt,
                   world.options.sleep_time)

    d = x[:, None] - x[None]
    dist = np.linalg.norm(d, axis=-1)
    n = d / np.maximum(dist, 1e-12)[..., None]
    approach = -np.einsum("ijk,ijk->ij", vel[:, None] - vel[None], n)
    reach = margin * 0.5 * (r[:, None] + r[None]) + np.maximum(approach, 0.0) * dt \
        + (curve[:, None] + curve[None] + g) * dt * dt
    excess = dist - r[:, None] - r[None] - reach
    other = owner[:, None] != owner[None]
    expected = {(int(slot[i]), int(slot[j])) for i, j in zip(*np.nonzero(np.triu((excess < 0) & other, 1)))}
    borderline = {(int(slot[i]), int(slot[j])) for i, j in zip(*np.nonzero(np.triu((np.abs(excess) < 1e-6) & other, 1)))}

    count = int(world.contacts.count[None])
    sphere = world.contacts.body_b.to_numpy()[:count] >= 0
    query, key = world.contacts.query.to_numpy()[:count][sphere], world.contacts.key.to_numpy()[:count][sphere]
    made = {(int(min(a, b)), int(max(a, b))) for a, b in zip(query, key)}
    assert len(made) == sphere.sum()  # each pair once
    assert made - borderline == expected - borderline and len(expected) > 50
    # Receding pairs make no speculative contact: fewer pairs than the bodies' whole motion
    # bounds ((|v| + |g| dt + |w| R) dt each, the rule before) reach.
    state = world.body_state()
    bounding = np.max(np.linalg.norm(ring, axis=1)) + 0.012
    motion = (np.linalg.norm(state["linear_velocity"], axis=1) + g * dt
              + np.linalg.norm(state["angular_velocity"], axis=1) * bounding) * dt
    motion_of = dict(zip(state["id"], motion))
    m = np.array([motion_of[b] for b in owner])
    old_rule = (dist - r[:, None] - r[None] < margin * 0.5 * (r[:, None] + r[None]) + m[:, None] + m[None]) & other
    assert len(expected) < 0.8 * np.triu(old_rule, 1).sum()
    assert world.contacts.overflow[None] == 0


def test_a_large_sphere_whose_cells_share_buckets_makes_each_pair_once():
    """A sphere much larger than its body's typical one occupies a box of cells, one
    bucket entry each; with few particles in use the hash table is small, so cells of
    that box share buckets. Each contact must still be made once, in one cell: the
    brute-force pairs, no more (the pair used to be made again for every other cell of
    the box hashed to the scanned bucket)."""
    world = fresh_world(gravity=(0.0, 0.0, 0.0))
    rng = np.random.default_rng(5)
    big = np.vstack([[0.0, 0.0, 0.0], rng.uniform(-0.01, 0.01, (8, 3))])
    big_r = np.r_[0.04, np.full(8, 0.005)]  # typical (median) radius 5 mm, one 40 mm sphere
    centres, radii = [], []
    for k in range(12):  # small bodies on the big sphere's surface, a touch inside it
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        offsets = rng.uniform(-0.004, 0.004, (3, 3))
        position = direction * (0.04 + 0.005 - 0.0005)
        world.add_body(with_spheres(single_tet_model(), offsets, 0.005), position, (1, 0, 0, 0))
        centres.append(offsets + position)
        radii.append(np.full(3, 0.005))
    # Added last: the small spheres (lower slots) make the pairs, the large one is the
    # partner found in its bucket entries.
    world.add_body(with_spheres(single_tet_model(), big, big_r), (0.0, 0.0, 0.0), (1, 0, 0, 0))
    centres.append(big)
    radii.append(big_r)
    assert world.grid.table_size[None] <= 128  # few particles: a small table
    owners = np.concatenate([np.full(len(r), b) for b, r in enumerate(radii)])
    centres, radii = np.concatenate(centres), np.concatenate(radii)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, 1e-3, world.options.sleep_time)
    count = int(world.contacts.count[None])
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=-1) - radii[:, None] - radii[None]
    close = (gap < margin * 0.5 * (radii[:, None] + radii[None])) & (owners[:, None] != owners[None])
    expected = np.sort(gap[np.triu(close, 1)])
    assert len(expected) >= 12 and count == len(expected)
    np.testing.assert_allclose(np.sort(world.contacts.separation.to_numpy()[:count]), expected, atol=2e-6)
    assert world.contacts.overflow[None] == 0 and world.grid.overflow[None] == 0
