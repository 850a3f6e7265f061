"""Body-pair broadphase, body-frame sphere grids and the sphere narrowphase, against
brute-force numpy pair searches."""

import numpy as np

import taichi as ti

from taichi_frac.collision import broadphase
from taichi_frac.collision.grid import CELLS_PER_SPHERE, body_grid
from taichi_frac.dynamics import stages
from support.bodies import single_tet_model
from support.dynamics import fresh_world, with_spheres


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
    stages.collide(world.fields, margin, 1e-3, world.options.sleep_time, world.has_contact_patches)
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
    from taichi_frac.kinematics.quaternion import quaternion_matrix

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
        start, count = world.slots.body_range[b]
        centres.append(x)
        radii.append(r)
        owners.append(np.full(count, b))
        slots.append(start + np.arange(count))
        velocity.append(v + np.cross(w, x - position))
        spin.append(np.full(count, w @ w) * np.linalg.norm(x - position, axis=1))
    x, r, owner, slot = map(np.concatenate, (centres, radii, owners, slots))
    vel, curve = np.concatenate(velocity), 0.5 * np.concatenate(spin)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, dt, world.options.sleep_time, world.has_contact_patches)

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
    owners = np.concatenate([np.full(len(r), b) for b, r in enumerate(radii)])
    centres, radii = np.concatenate(centres), np.concatenate(radii)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, 1e-3, world.options.sleep_time, world.has_contact_patches)
    count = int(world.contacts.count[None])
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=-1) - radii[:, None] - radii[None]
    close = (gap < margin * 0.5 * (radii[:, None] + radii[None])) & (owners[:, None] != owners[None])
    expected = np.sort(gap[np.triu(close, 1)])
    assert len(expected) >= 12 and count == len(expected)
    np.testing.assert_allclose(np.sort(world.contacts.separation.to_numpy()[:count]), expected, atol=2e-6)
    assert world.contacts.overflow[None] == 0


def test_body_grid_puts_every_sphere_in_its_cell_and_fits_its_share():
    """``body_grid``: the entries of each cell are exactly the spheres whose centre falls in
    it (checked against the cell computed here for every sphere), each sphere once, and the
    cell starts fit the body's share (cells + 1 <= CELLS_PER_SPHERE x spheres) for a compact
    body, a long thin one (its cells grow longer instead) and a single sphere."""
    rng = np.random.default_rng(11)
    cases = [rng.uniform(-0.05, 0.05, (300, 3)), np.c_[np.linspace(0.0, 3.0, 40), np.zeros((40, 2))],
             np.zeros((1, 3))]
    for offsets in cases:
        radii = rng.uniform(0.004, 0.006, len(offsets))
        origin, edge, dims, first, order = body_grid(offsets, radii, 0.25)
        assert len(first) == np.prod(dims) + 1 <= CELLS_PER_SPHERE * len(offsets)
        assert first[0] == 0 and first[-1] == len(offsets) and np.all(np.diff(first) >= 0)
        np.testing.assert_array_equal(np.sort(order), np.arange(len(offsets)))
        index = np.minimum(np.floor((offsets - origin) / edge).astype(int), dims - 1)
        assert np.all(index >= 0)
        cell = (index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2]
        for c in range(int(np.prod(dims))):
            np.testing.assert_array_equal(np.sort(order[first[c]:first[c + 1]]), np.nonzero(cell == c)[0])
    # the compact body: cells of about 3 median radii (1 + margin / 2), not grown
    origin, edge, dims, first, order = body_grid(cases[0], np.full(300, 0.005), 0.25)
    assert edge == 3.0 * 0.005 * 1.125


def test_a_body_with_more_neighbours_than_its_list_holds_still_makes_every_contact():
    """A plate with more neighbouring bodies than ``Bodies.max_neighbors`` (its list
    overflows, count -1): its spheres then try every body. Added first (lowest slot), it is
    the side that makes every plate-piece pair, so a lost pair would show: the contacts
    equal a brute-force search."""
    world = fresh_world(gravity=(0.0, 0.0, 0.0))
    rng = np.random.default_rng(2)
    side = np.arange(-0.3, 0.3001, 0.012)
    plate = np.stack(np.meshgrid(side, side, [0.0], indexing="ij"), -1).reshape(-1, 3)
    plate_r = np.full(len(plate), 0.006)
    centres, radii = [plate], [plate_r]
    world.add_body(with_spheres(single_tet_model(), plate, plate_r), (0.0, 0.0, 0.0), (1, 0, 0, 0))
    pieces = world.bodies.max_neighbors + 20
    for k in range(pieces):
        offsets = rng.uniform(-0.004, 0.004, (2, 3))
        position = np.r_[rng.uniform(-0.28, 0.28, 2), rng.uniform(0.008, 0.012)]
        world.add_body(with_spheres(single_tet_model(), offsets, 0.003), position, (1, 0, 0, 0))
        centres.append(offsets + position)
        radii.append(np.full(2, 0.003))
    owners = np.concatenate([np.full(len(r), b) for b, r in enumerate(radii)])
    centres, radii = np.concatenate(centres), np.concatenate(radii)
    margin = world.options.contact_margin
    stages.collide(world.fields, margin, 1e-3, world.options.sleep_time, world.has_contact_patches)
    assert world.bodies.neighbor_count[0] == -1
    count = int(world.contacts.count[None])
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=-1) - radii[:, None] - radii[None]
    close = (gap < margin * 0.5 * (radii[:, None] + radii[None])) & (owners[:, None] != owners[None])
    expected = np.sort(gap[np.triu(close, 1)])
    assert count == len(expected) and close[owners == 0].sum() > 50
    np.testing.assert_allclose(np.sort(world.contacts.separation.to_numpy()[:count]), expected, atol=2e-6)


def _scattered_bodies():
    """A World holding a large plate (over MAX_BODY_CELLS cells) and 150 bodies of three
    sizes, moving and spinning fast, every third of the first 40 asleep."""
    world = fresh_world(gravity=(0.0, 0.0, -9.81))
    rng = np.random.default_rng(4)
    side = np.arange(-0.5, 0.5001, 0.02)
    plate = np.stack(np.meshgrid(side, side, [0.0], indexing="ij"), -1).reshape(-1, 3)
    bodies = [world.add_body(with_spheres(single_tet_model(), plate, np.full(len(plate), 0.01)), (0.0, 0.0, -0.05),
                             (1, 0, 0, 0))]
    for k in range(150):
        size = rng.choice([0.005, 0.02, 0.06])
        offsets = rng.uniform(-size, size, (5, 3))
        q = rng.normal(size=4)
        bodies.append(world.add_body(with_spheres(single_tet_model(), offsets, rng.uniform(0.2, 0.5) * size),
                                     rng.uniform(-0.45, 0.45, 3) * [1, 1, 0.3], q / np.linalg.norm(q),
                                     rng.normal(0.0, 2.0, 3), rng.normal(0.0, 20.0, 3)))
    asleep = bodies[1:40:3]
    for b in asleep:
        world.bodies.sleeping[b] = 1
    return world, bodies, asleep


def test_broadphase_neighbour_lists_equal_testing_every_pair():
    """The body grid's neighbour lists (bodies.neighbors) against testing every pair in
    numpy with the same rule (grown bounding spheres overlap by margin x largest radius
    and ``bounds.pair_motion``, at least one of the two awake), in ascending slot order:
    bodies of many sizes, moving and spinning fast, some asleep, and one plate far larger
    than the cells (kept out of the grid, tested against every body; it has more
    neighbours than its list holds, so its count is -1). A sleeping body gets no list (it
    makes no contacts of its own: its awake neighbours' lists hold it)."""
    world, bodies, asleep = _scattered_bodies()
    margin, dt, g = world.options.contact_margin, 4e-3, 9.81
    stages.collide(world.fields, margin, dt, world.options.sleep_time, world.has_contact_patches)
    assert world.grid.large_count[None] >= 1  # the plate

    f = world.bodies
    ids = np.array(bodies)
    x = f.position.to_numpy()[ids].astype(np.float64)
    v = f.linear_velocity.to_numpy()[ids].astype(np.float64)
    w = f.angular_velocity.to_numpy()[ids].astype(np.float64)
    radius = f.bounding_radius.to_numpy()[ids].astype(np.float64)
    largest = f.max_particle_radius.to_numpy()[ids].astype(np.float64)
    idle = np.isin(ids, asleep)
    v[idle], w[idle] = 0.0, 0.0
    spin = np.linalg.norm(w, axis=1) * radius
    curve = 0.5 * np.linalg.norm(w, axis=1) ** 2 * radius
    closing = (np.linalg.norm(v[:, None] - v[None], axis=-1) + spin[:, None] + spin[None]) * dt \
        + (curve[:, None] + curve[None] + g) * dt * dt
    grown = radius + margin * largest
    reach = grown[:, None] + grown[None] + closing
    excess = np.linalg.norm(x[:, None] - x[None], axis=-1) - reach
    pair = (excess < 0) & ~(idle[:, None] & idle[None]) & ~np.eye(len(ids), dtype=bool)
    borderline = np.abs(excess) < 1e-6
    counts = f.neighbor_count.to_numpy()[ids]
    lists = f.neighbors.to_numpy()[ids]
    assert pair.sum() > 150
    assert idle.sum() >= 3 and np.all(counts[idle] == 0)
    for k, b in enumerate(ids):
        if idle[k]:
            continue
        if counts[k] < 0:  # more neighbours than the list holds (the plate, under everyone)
            assert pair[k].sum() > f.max_neighbors
            continue
        got = lists[k, :counts[k]]
        assert np.all(np.diff(got) > 0)  # ascending, each once
        expected = set(ids[pair[k]].tolist())
        loose = set(ids[borderline[k]].tolist())
        assert set(got.tolist()) - loose == expected - loose, b


@ti.kernel
def _cull_parallel(f: ti.template(), margin: ti.f32, dt: ti.f32):
    broadphase.body_cull_passes(f.bodies, f.statics, f.grid, margin, dt, False)


@ti.kernel
def _cull_serial(f: ti.template(), margin: ti.f32, dt: ti.f32):
    broadphase.body_cull_passes(f.bodies, f.statics, f.grid, margin, dt, True)


def test_parallel_broadphase_makes_the_serial_lists():
    """``body_cull_passes`` as parallel loops (the GPU's passes: atomics, entries in any
    order) run on the CPU's threads gives the serial passes' lists, counts and
    static-collider flags."""
    world, bodies, asleep = _scattered_bodies()
    world.add_ground(-0.02)
    margin, dt = world.options.contact_margin, 4e-3
    _cull_serial(world.fields, margin, dt)  # (not collide: its touches would wake sleepers)
    f = world.bodies
    serial = (f.neighbor_count.to_numpy(), f.neighbors.to_numpy(), f.near_static.to_numpy())
    f.neighbors.fill(-7)
    f.neighbor_count.fill(-7)
    _cull_parallel(world.fields, margin, dt)
    parallel = (f.neighbor_count.to_numpy(), f.neighbors.to_numpy(), f.near_static.to_numpy())
    ids = np.array(bodies)
    np.testing.assert_array_equal(parallel[0][ids], serial[0][ids])
    np.testing.assert_array_equal(parallel[2][ids], serial[2][ids])
    assert serial[2][ids].sum() > 0 and (serial[0][ids] > 0).sum() > 100
    for b in ids:
        n = max(serial[0][b], 0)
        np.testing.assert_array_equal(parallel[1][b, :n], serial[1][b, :n])
