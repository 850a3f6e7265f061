"""A synthetic fracture cache with closed-form motion, shared by the main-environment tests
and the checks run inside Blender (numpy only; no taichi_frac, no pxr, no bpy).

Frames 0..48 at 24 fps. Fragments (name, birth, death, parent):
    slab      0   20   -      falls and spins about z
    shard_a  20   -    slab   drifts and turns about (1,1,0)/sqrt2
    shard_b  20   35   slab   tumbles about x fast (turns past 180 degrees)
    sliver_1 35   -    shard_b
    sliver_2 35   -    shard_b
Each is a box of 12 triangles; faces listed in INNER_FACES are crack faces. shard_a rests
over frames 30-38 and sliver_2 from frame 42 to the end (``RESTS``).
"""

from __future__ import annotations

import numpy as np

FPS = 24.0
START_FRAME = 0
END_FRAME = 48

# name: (birth, death or None, parent or None, box half extents [m])
FRAGMENTS = {
    "slab": (0, 20, None, (0.4, 0.3, 0.1)),
    "shard_a": (20, None, "slab", (0.2, 0.15, 0.1)),
    "shard_b": (20, 35, "slab", (0.2, 0.15, 0.1)),
    "sliver_1": (35, None, "shard_b", (0.1, 0.15, 0.1)),
    "sliver_2": (35, None, "shard_b", (0.1, 0.15, 0.1)),
}
# Triangles (indices into box_mesh()'s faces) flagged as crack faces.
INNER_FACES = {"slab": [], "shard_a": [0, 1], "shard_b": [2, 3], "sliver_1": [0, 1, 4, 5], "sliver_2": [6, 7]}
IMPACT = {"point": (0.05, -0.02, 0.0), "force": (0.0, 0.0, 1500.0)}


def box_mesh(half):
    """8 corners and 12 outward-wound triangles of an axis-aligned box centred at 0."""
    hx, hy, hz = half
    v = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    return v, np.array(faces, dtype=np.int64)


def axis_angle_quat(axis, angle):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


# Rests: the pose held over frames first..last (a sleeping body). The cache writer samples
# none of the frames strictly between (and none after a rest to the end); the held pose is
# written at ``last`` when the body moves again, so every frame still reads its pose.
RESTS = {"shard_a": (30, 38), "sliver_2": (42, END_FRAME)}


def sampled(name, frame) -> bool:
    """Whether the cache holds a pose sample of ``name`` at ``frame`` (a live frame)."""
    if name not in RESTS:
        return True
    first, last = RESTS[name]
    return not (first < frame < last or (last == END_FRAME and frame == last and first < frame))


def pose(name, frame):
    """World position (3,) [m] and orientation (w,x,y,z) of fragment ``name`` at ``frame``."""
    if name in RESTS:
        first, last = RESTS[name]
        frame = first if first < frame <= last else frame - (last - first) if frame > last else frame
    t = frame / FPS
    if name == "slab":
        return np.array([0.0, 0.0, 2.0 - 0.5 * 9.81 * t * t]), axis_angle_quat((0, 0, 1), 1.5 * t)
    if name == "shard_a":
        return np.array([0.3 + 0.5 * t, 0.1, 1.0 + 0.2 * t]), axis_angle_quat((1, 1, 0), 2.0 * t)
    if name == "shard_b":
        return np.array([-0.3 - 0.4 * t, -0.2 * t, 1.2 - 0.1 * t]), axis_angle_quat((1, 0, 0), 9.0 * t)
    if name == "sliver_1":
        return np.array([-1.0, 0.5 * t, 0.5]), axis_angle_quat((0, 1, 0.5), -3.0 * t)
    if name == "sliver_2":
        return np.array([-1.2 + 0.1 * t, -0.4, 0.3 + t]), axis_angle_quat((0.2, 0.3, 1), 4.0 * t)
    raise KeyError(name)


def alive(name, frame) -> bool:
    birth, death, _, _ = FRAGMENTS[name]
    return frame >= birth and (death is None or frame < death)


def world_matrix(position, quaternion):
    """4x4 column-vector matrix x_world = R(q) x_body + position."""
    w, x, y, z = quaternion
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = position
    return m


def peak_stress(name):
    """Fragment peak principal stress [Pa] (arbitrary, distinct per fragment)."""
    return 1.0e6 * (1 + list(FRAGMENTS).index(name))


def face_stress(name, face_count):
    """Per-face peak principal stress [Pa] (arbitrary, distinct per face)."""
    return 1.0e5 * (1 + list(FRAGMENTS).index(name)) + 1.0e3 * np.arange(face_count)
