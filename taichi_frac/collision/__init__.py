"""Collision detection on particles: hashed-grid broadphase and sphere narrowphase."""

from .grid import HashGrid, body_cull, bucket_scan, bucket_scatter, particle_cells
from .narrowphase import GROUND, STATIC_BOX, Contacts, clear_contacts, particle_contacts

__all__ = [
    "HashGrid", "body_cull", "bucket_scan", "bucket_scatter", "particle_cells",
    "GROUND", "STATIC_BOX", "Contacts", "clear_contacts", "particle_contacts",
]
