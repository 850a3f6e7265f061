"""Orthonormal frames in Taichi."""


from ..runtime import ti
from . import linalg3 as la

vec3 = ti.math.vec3


@ti.func
def tangent_basis(n):
    """Two unit vectors (t1, t2) with (t1, t2, ``n``) right-handed across the unit ``n``: t1
    is x (or y, when n lies within 55 degrees of x) with its n part removed. Depends on n
    alone, so contacts of one normal share their directions (the solver's friction axes,
    the contact reduction's directions)."""
    t1 = vec3(1.0, 0.0, 0.0)
    if ti.abs(n[0]) > 0.57735:
        t1 = vec3(0.0, 1.0, 0.0)
    t1 = (t1 - la.dot(t1, n) * n).normalized()
    return t1, la.cross(n, t1)
