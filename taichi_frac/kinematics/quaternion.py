"""Unit quaternions (w, x, y, z), body -> world: their product, rotation matrix and
integration, as Taichi functions for kernels and numpy functions for host code (placing
bodies, fragments and static colliders, reading poses). Each formula in one place per
language: a Taichi function cannot be called from numpy code, nor numpy from a kernel."""

import numpy as np

from ..runtime import ti
from . import linalg3 as la


@ti.func
def quat_mul(a, b):
    """Hamilton product a b (Taichi vec4s); numpy: ``quaternion_multiply``."""
    return ti.math.vec4(
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    )


@ti.func
def quat_to_matrix(q):
    """Rotation matrix (mat3) of a unit quaternion; numpy: ``quaternion_matrix``."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ti.math.mat3(
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )


@ti.func
def quat_integrate(q, omega, dt):
    """q advanced by a constant world angular velocity omega over dt: the exact rotation
    exp(omega dt) applied on the left (renormalised against round-off)."""
    angle = la.norm(omega) * dt
    axis = omega.normalized(1e-30)
    half = 0.5 * angle
    s = ti.sin(half)
    r = ti.math.vec4(ti.cos(half), axis[0] * s, axis[1] * s, axis[2] * s)
    return quat_mul(r, q).normalized()


def quaternion_multiply(a, b) -> np.ndarray:
    """Hamilton product a b of quaternions (..., 4) each (broadcast), float64."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), each normalised first."""
    q = np.asarray(q, dtype=np.float64)
    norm = np.linalg.norm(q) if q.ndim == 1 else np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q / norm, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)
