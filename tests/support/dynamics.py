"""Shared fixtures for the dynamics and collision tests.

One World for the whole session: its kernels compile once (Taichi compilation dominates the
run time); each test calls ``fresh_world()`` which clears bodies and statics and restores
the options. The bodies come from ``support.bodies``, which the report's
stability table simulates too.
"""

import dataclasses
import functools

import numpy as np

from taichi_frac.dynamics import DynamicsOptions, World, WorldCapacity


@functools.lru_cache(maxsize=None)
def _world():
    return World(WorldCapacity(max_bodies=1100, max_boundary_particles=40000, max_contacts=60000,
                               max_impacts=20000), DynamicsOptions())


def fresh_world(**options) -> World:
    world = _world()
    world.clear()
    world.set_options(DynamicsOptions(**options))
    return world


def kinetic_energy(world: World, models: dict) -> float:
    """Total kinetic energy [J]; models maps body id -> BodyModel."""
    state = world.body_state(list(models))
    energy = 0.0
    for k, (body, model) in enumerate(models.items()):
        q = state["orientation"][k]
        rot = rotation(q)
        inertia_world = rot @ model.inertia @ rot.T
        v, w = state["linear_velocity"][k], state["angular_velocity"][k]
        energy += 0.5 * model.mass * v @ v + 0.5 * w @ inertia_world @ w
    return energy


def rotation(q) -> np.ndarray:
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def with_spheres(model, centres, radii):
    """The same rigid body (mass, inertia) colliding through the given body-frame spheres:
    makes the collision geometry exact where a test checks the solver against a closed form
    (a tet-meshed box's boundary spheres make a bumpy bottom, a tet sphere's an uneven one)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    # (no members: each sphere is its own surface, so the contacts are the spheres')
    return dataclasses.replace(model, boundary_position=centres, boundary_contact_position=None,
                               boundary_radius=np.broadcast_to(np.asarray(radii, float), len(centres)).copy(),
                               boundary_member_offsets=np.zeros(len(centres) + 1, dtype=np.int32),
                               boundary_members=np.zeros(0, dtype=np.int32))


def lowest_point(model, group_radius=True) -> float:
    """Lowest z of the collision spheres in the body frame (to place a body touching z=0)."""
    return float(np.min(model.collision_position[:, 2] - model.boundary_radius))
