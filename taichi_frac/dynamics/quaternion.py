"""Quaternion helpers (w, x, y, z), unit, body -> world."""

import taichi as ti


@ti.func
def quat_mul(a, b):
    return ti.math.vec4(
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    )


@ti.func
def quat_to_matrix(q):
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
    angle = omega.norm() * dt
    axis = omega.normalized(1e-30)
    half = 0.5 * angle
    s = ti.sin(half)
    r = ti.math.vec4(ti.cos(half), axis[0] * s, axis[1] * s, axis[2] * s)
    return quat_mul(r, q).normalized()
