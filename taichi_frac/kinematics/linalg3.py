"""3-vector and 3x3-matrix products written out, for kernels.

Taichi's own operators on small vectors and matrices (``@``, ``.dot``, ``.norm``,
``.cross``, ``.transpose()``) are Taichi-Python functions whose bodies are static loops: its
front end transforms them again at every call site in every new process (the offline cache
keeps only what comes after): a kernel that calls them a hundred times spends about half of
its build in a new process on them. Written out, a call costs a few expressions. Each function builds the
expressions Taichi's operator builds, in the same order (a left fold over components; a
product's sums start from its first term times 0, a norm adds 0.0 under its root), so that
in a kernel of its own it gives the operator's bits (tests/test_linalg3.py). Within a large
kernel, LLVM's fast-math contraction may still round a few sums differently after the swap,
as it may after any edit of that kernel.
"""

from ..runtime import ti


@ti.func
def dot(a, b):
    """a . b of two 3-vectors."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@ti.func
def norm_sqr(a):
    """|a|^2 of a 3-vector."""
    return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]


@ti.func
def norm(a):
    """|a| of a 3-vector."""
    return ti.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 0.0)


@ti.func
def cross(a, b):
    """a x b of two 3-vectors."""
    return ti.Vector([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@ti.func
def mat_vec(m, v):
    """m v: a 3x3 matrix times a 3-vector."""
    zero = m[0, 0] * v[0] * 0
    return ti.Vector([zero + m[0, 0] * v[0] + m[0, 1] * v[1] + m[0, 2] * v[2],
                      zero + m[1, 0] * v[0] + m[1, 1] * v[1] + m[1, 2] * v[2],
                      zero + m[2, 0] * v[0] + m[2, 1] * v[1] + m[2, 2] * v[2]])


@ti.func
def mat_t_vec(m, v):
    """m^T v: a 3x3 matrix's transpose times a 3-vector (a world vector in a body's frame
    when m is the body's rotation)."""
    zero = m[0, 0] * v[0] * 0
    return ti.Vector([zero + m[0, 0] * v[0] + m[1, 0] * v[1] + m[2, 0] * v[2],
                      zero + m[0, 1] * v[0] + m[1, 1] * v[1] + m[2, 1] * v[2],
                      zero + m[0, 2] * v[0] + m[1, 2] * v[1] + m[2, 2] * v[2]])


@ti.func
def mat_mat(a, b):
    """a b of two 3x3 matrices."""
    zero = a[0, 0] * b[0, 0] * 0
    return ti.Matrix([[zero + a[0, 0] * b[0, 0] + a[0, 1] * b[1, 0] + a[0, 2] * b[2, 0],
                       zero + a[0, 0] * b[0, 1] + a[0, 1] * b[1, 1] + a[0, 2] * b[2, 1],
                       zero + a[0, 0] * b[0, 2] + a[0, 1] * b[1, 2] + a[0, 2] * b[2, 2]],
                      [zero + a[1, 0] * b[0, 0] + a[1, 1] * b[1, 0] + a[1, 2] * b[2, 0],
                       zero + a[1, 0] * b[0, 1] + a[1, 1] * b[1, 1] + a[1, 2] * b[2, 1],
                       zero + a[1, 0] * b[0, 2] + a[1, 1] * b[1, 2] + a[1, 2] * b[2, 2]],
                      [zero + a[2, 0] * b[0, 0] + a[2, 1] * b[1, 0] + a[2, 2] * b[2, 0],
                       zero + a[2, 0] * b[0, 1] + a[2, 1] * b[1, 1] + a[2, 2] * b[2, 1],
                       zero + a[2, 0] * b[0, 2] + a[2, 1] * b[1, 2] + a[2, 2] * b[2, 2]]])


@ti.func
def mat_mat_t(a, b):
    """a b^T of two 3x3 matrices (rows of ``a`` taken to the world by the rotation ``b``)."""
    zero = a[0, 0] * b[0, 0] * 0
    return ti.Matrix([[zero + a[0, 0] * b[0, 0] + a[0, 1] * b[0, 1] + a[0, 2] * b[0, 2],
                       zero + a[0, 0] * b[1, 0] + a[0, 1] * b[1, 1] + a[0, 2] * b[1, 2],
                       zero + a[0, 0] * b[2, 0] + a[0, 1] * b[2, 1] + a[0, 2] * b[2, 2]],
                      [zero + a[1, 0] * b[0, 0] + a[1, 1] * b[0, 1] + a[1, 2] * b[0, 2],
                       zero + a[1, 0] * b[1, 0] + a[1, 1] * b[1, 1] + a[1, 2] * b[1, 2],
                       zero + a[1, 0] * b[2, 0] + a[1, 1] * b[2, 1] + a[1, 2] * b[2, 2]],
                      [zero + a[2, 0] * b[0, 0] + a[2, 1] * b[0, 1] + a[2, 2] * b[0, 2],
                       zero + a[2, 0] * b[1, 0] + a[2, 1] * b[1, 1] + a[2, 2] * b[1, 2],
                       zero + a[2, 0] * b[2, 0] + a[2, 1] * b[2, 1] + a[2, 2] * b[2, 2]]])


@ti.func
def mat_t_mat(a, b):
    """a^T b of two 3x3 matrices."""
    zero = a[0, 0] * b[0, 0] * 0
    return ti.Matrix([[zero + a[0, 0] * b[0, 0] + a[1, 0] * b[1, 0] + a[2, 0] * b[2, 0],
                       zero + a[0, 0] * b[0, 1] + a[1, 0] * b[1, 1] + a[2, 0] * b[2, 1],
                       zero + a[0, 0] * b[0, 2] + a[1, 0] * b[1, 2] + a[2, 0] * b[2, 2]],
                      [zero + a[0, 1] * b[0, 0] + a[1, 1] * b[1, 0] + a[2, 1] * b[2, 0],
                       zero + a[0, 1] * b[0, 1] + a[1, 1] * b[1, 1] + a[2, 1] * b[2, 1],
                       zero + a[0, 1] * b[0, 2] + a[1, 1] * b[1, 2] + a[2, 1] * b[2, 2]],
                      [zero + a[0, 2] * b[0, 0] + a[1, 2] * b[1, 0] + a[2, 2] * b[2, 0],
                       zero + a[0, 2] * b[0, 1] + a[1, 2] * b[1, 1] + a[2, 2] * b[2, 1],
                       zero + a[0, 2] * b[0, 2] + a[1, 2] * b[1, 2] + a[2, 2] * b[2, 2]]])
