"""Collision detection on particles: a body broadphase (hashed grid), static body-frame grids over
each body's collision spheres, the sphere narrowphase, and the contacts it takes from the true
surface behind the spheres (``surface.py``, with ``DynamicsOptions(surface_contact=True)``)."""

from .broadphase import BodyGrid, body_cull
from .grid import body_grid
from .narrowphase import GROUND, STATIC_BOX, Contacts, clear_contacts, particle_contacts

__all__ = [
    "BodyGrid", "body_cull", "body_grid",
    "GROUND", "STATIC_BOX", "Contacts", "clear_contacts", "particle_contacts",
]
