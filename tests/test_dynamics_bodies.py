"""Adding bodies to the World: a batch (``add_bodies``, a split's pieces in one launch)
against the same bodies added one at a time, the cluster spheres the launch computes
against a numpy reference, and a batch that does not fit adding nothing."""

import numpy as np
import pytest

from taichi_frac.dynamics import CapacityError
from taichi_frac.dynamics.state import MAX_CLUSTERS
from support.bodies import single_tet_model
from support.dynamics import fresh_world, with_spheres


def reference_clusters(offsets: np.ndarray, radii: np.ndarray, count: int) -> np.ndarray:
    """(K,4) cluster spheres (centre [m], radius [m]) in numpy, f64: farthest-point seeds
    (the first the sphere farthest from the mean, ties to the lower index), each sphere
    with its nearest seed, each cluster at its members' mean, reaching the far side of
    every member."""
    seeds = [int(np.argmax(((offsets - offsets.mean(axis=0)) ** 2).sum(axis=1)))]
    nearest = ((offsets - offsets[seeds[0]]) ** 2).sum(axis=1)
    while len(seeds) < min(count, len(offsets)) and nearest.max() > 0.0:
        seeds.append(int(np.argmax(nearest)))
        nearest = np.minimum(nearest, ((offsets - offsets[seeds[-1]]) ** 2).sum(axis=1))
    label = np.argmin(((offsets[:, None, :] - offsets[seeds][None, :, :]) ** 2).sum(axis=2), axis=1)
    out = np.zeros((len(seeds), 4))
    for m in range(len(seeds)):
        mine = label == m
        out[m, :3] = offsets[mine].mean(axis=0)
        out[m, 3] = (np.linalg.norm(offsets[mine] - out[m, :3], axis=1) + radii[mine]).max()
    return out


def random_bodies(rng, count):
    models, poses = [], []
    for n in rng.integers(1, 400, size=count):
        offsets = rng.normal(size=(n, 3)) * rng.uniform(0.005, 0.05, size=3)
        if n > 50:  # a few coincident centres: fewer seeds than asked
            offsets[-3:] = offsets[0]
        models.append(with_spheres(single_tet_model(), offsets, rng.uniform(0.002, 0.008, size=n)))
        q = rng.normal(size=4)
        poses.append((rng.uniform(-1, 1, 3), q / np.linalg.norm(q), rng.normal(size=3), rng.normal(size=3)))
    return models, poses


def body_fields(world, ids):
    """Every field of the bodies ``ids`` and of their particle ranges (numpy)."""
    out = {}
    for name, f in vars(world.bodies).items():
        if hasattr(f, "to_numpy") and f.shape and f.shape[0] == world.capacity.max_bodies:
            out["bodies." + name] = f.to_numpy()[ids]
    rows = np.concatenate([np.arange(s, s + n) for s, n in (world.slots.body_range[b] for b in ids)])
    for name in ("body", "offset", "radius", "grid_sphere", "grid_slot"):
        out["particles." + name] = getattr(world.particles, name).to_numpy()[rows]
    return out


def test_a_batch_writes_what_one_at_a_time_writes():
    """World.add_bodies writes every body field and particle range exactly as the same
    bodies added one at a time (and the same slots, in order)."""
    rng = np.random.default_rng(7)
    models, poses = random_bodies(rng, 12)
    world = fresh_world()
    ids = world.add_bodies(models, *[[p[k] for p in poses] for k in range(4)], friction=0.3, restitution=0.1,
                           breakable=[k % 2 == 0 for k in range(12)], young_modulus=5e9)
    batched = body_fields(world, ids)
    assert [world.breakable[b] for b in ids] == [k % 2 == 0 for k in range(12)]
    world = fresh_world()
    singles = [world.add_body(m, *p, friction=0.3, restitution=0.1, young_modulus=5e9) for m, p in zip(models, poses)]
    assert singles == ids
    alone = body_fields(world, singles)
    for name, values in batched.items():
        assert np.array_equal(values, alone[name]), name


def test_cluster_spheres_match_numpy_and_enclose_their_members():
    """The cluster spheres ``body_fields.write_bodies`` computes: as many as asked (fewer only when
    centres coincide), the numpy reference's to f32 rounding, and each sphere of the
    body inside one of them (to that rounding)."""
    rng = np.random.default_rng(11)
    models, poses = random_bodies(rng, 20)
    # 64 spheres on 2 distinct centres: 4 clusters asked, 2 seeds found
    models.append(with_spheres(single_tet_model(), np.repeat([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0]], 32, axis=0), 0.004))
    poses.append(poses[0])
    world = fresh_world()
    ids = world.add_bodies(models, *[[p[k] for p in poses] for k in range(4)])
    clusters, counts = world.bodies.cluster.to_numpy(), world.bodies.cluster_count.to_numpy()
    asked_fewer = 0
    for b, m in zip(ids, models):
        offsets, radii = m.collision_position, m.boundary_radius
        expected = reference_clusters(offsets, radii, min(MAX_CLUSTERS, max(1, len(radii) // 16)))
        got = clusters[b, :counts[b]].astype(np.float64)
        assert got.shape == expected.shape
        asked_fewer += len(expected) < min(MAX_CLUSTERS, max(1, len(radii) // 16))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6 * np.abs(offsets).max() + 1e-9)
        # (inside to the f32 rounding of the stored centres and radii: a few ulps of the
        # body's largest coordinate, nanometres, far below the narrowphase's margins)
        reach = np.linalg.norm(offsets[:, None, :] - got[None, :, :3], axis=2) + radii[:, None]
        assert np.all((reach <= got[None, :, 3] + 8 * 2.0 ** -23 * np.abs(offsets).max()).any(axis=1))
    assert counts[ids].max() == MAX_CLUSTERS and asked_fewer == 1


def test_a_batch_that_does_not_fit_adds_nothing():
    """A batch whose last body overflows max_boundary_particles raises CapacityError
    naming it, and a batch with a malformed pose ValueError; either leaves the World as it
    was: no body added, every slot and particle range free again (the next bodies go where
    they would have gone)."""
    rng = np.random.default_rng(5)
    models, poses = random_bodies(rng, 4)
    world = fresh_world()
    huge = with_spheres(single_tet_model(), np.zeros((world.capacity.max_boundary_particles + 1, 3)), 0.01)
    with pytest.raises(CapacityError, match="max_boundary_particles"):
        world.add_bodies(models + [huge], *[[p[k] for p in poses] + [np.zeros(3) if k != 1 else np.array(
            [1.0, 0, 0, 0])] for k in range(4)])
    assert world.body_ids == [] and world.slots.particles_in_use == 0
    bad = [[p[k] for p in poses] for k in range(4)]
    bad[1][-1] = np.array([1.0, 0.0, 0.0])  # a 3-component orientation: refused before any slot is taken
    with pytest.raises(ValueError, match="orientation_wxyz"):
        world.add_bodies(models, *bad)
    assert world.body_ids == [] and world.slots.particles_in_use == 0
    ids = world.add_bodies(models, *[[p[k] for p in poses] for k in range(4)])
    assert ids == [0, 1, 2, 3]
    starts = np.cumsum([0] + [len(m.boundary_radius) for m in models])[:-1]
    assert [world.slots.body_range[b][0] for b in ids] == list(starts)
