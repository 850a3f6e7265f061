"""Collision detection on particles: a body broadphase (hashed grid), static body-frame grids over
each body's collision spheres, and the sphere narrowphase."""

from .broadphase import BodyGrid, body_cull
from .grid import body_grid
from .narrowphase import GROUND, STATIC_BOX, Contacts, clear_contacts, particle_contacts

__all__ = [
    "BodyGrid", "body_cull", "body_grid",
    "GROUND", "STATIC_BOX", "Contacts", "clear_contacts", "particle_contacts",
]
