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
    stages.collide(world.bodies, world.statics, world.particles, world.grid, world.contacts, margin, 1e-3,
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
