"""Rotations of unit quaternions (w, x, y, z), body -> world, in numpy (host-side code:
placing bodies, fragments and static colliders; Taichi kernels use dynamics/quaternion.py)."""

from __future__ import annotations

import numpy as np


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrix (3,3) of a quaternion (w, x, y, z), normalised first."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
