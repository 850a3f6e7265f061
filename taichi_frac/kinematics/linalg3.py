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

They are not ``ti.func``: the front end reads and transforms a ``ti.func``'s source at each
call site (about 0.3 ms each, and a new process's kernels call these some 600 times), while
a plain function called in a kernel runs once there on its arguments' expressions. Each
builds what the same ``ti.func`` would (its arguments copied, as a ``ti.func`` takes untyped
ones by value; a named intermediate in a local variable), so the compiled kernels are the
same.
"""
from taichi.lang import impl
from taichi.lang.matrix import make_matrix

from ..runtime import ti


def _built(build):
    """``build`` as a function kernels call: the front end passes it its arguments'
    expressions, and it reads their components (``_vector``, ``_matrix``)."""
    # (the front end warns of a call to a function that is not Taichi's unless it has this
    # attribute, and records a ti.func's prints only where it is true)
    build._is_taichi_function = False
    return build


def _vector(v):
    """The 3 component expressions of a 3-vector argument, read from a copy of it (a
    ``ti.func`` takes its untyped arguments by value)."""
    v = impl.expr_init_func(v)
    return [impl.subscript(None, v, i) for i in range(3)]


def _matrix(m):
    """The 3x3 component expressions of a 3x3 matrix argument, row by row, read from a copy
    of it."""
    m = impl.expr_init_func(m)
    return [[impl.subscript(None, m, i, j) for j in range(3)] for i in range(3)]


def _local(value):
    """``value`` held in a local variable, as an assignment in a ``ti.func`` holds it."""
    return impl.expr_init(value)


@_built
def dot(a, b):
    """a . b of two 3-vectors."""
    a, b = _vector(a), _vector(b)
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@_built
def norm_sqr(a):
    """|a|^2 of a 3-vector."""
    a = _vector(a)
    return a[0] * a[0] + a[1] * a[1] + a[2] * a[2]


@_built
def norm(a):
    """|a| of a 3-vector."""
    a = _vector(a)
    return ti.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 0.0)


@_built
def cross(a, b):
    """a x b of two 3-vectors."""
    a, b = _vector(a), _vector(b)
    return make_matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@_built
def mat_vec(m, v):
    """m v: a 3x3 matrix times a 3-vector."""
    m, v = _matrix(m), _vector(v)
    zero = _local(m[0][0] * v[0] * 0)
    return make_matrix([zero + m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2] for i in range(3)])


@_built
def mat_t_vec(m, v):
    """m^T v: a 3x3 matrix's transpose times a 3-vector (a world vector in a body's frame
    when m is the body's rotation)."""
    m, v = _matrix(m), _vector(v)
    zero = _local(m[0][0] * v[0] * 0)
    return make_matrix([zero + m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2] for i in range(3)])


@_built
def mat_mat(a, b):
    """a b of two 3x3 matrices."""
    a, b = _matrix(a), _matrix(b)
    zero = _local(a[0][0] * b[0][0] * 0)
    return make_matrix([[zero + a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)]
                        for i in range(3)])


@_built
def mat_mat_t(a, b):
    """a b^T of two 3x3 matrices (rows of ``a`` taken to the world by the rotation ``b``)."""
    a, b = _matrix(a), _matrix(b)
    zero = _local(a[0][0] * b[0][0] * 0)
    return make_matrix([[zero + a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2] for j in range(3)]
                        for i in range(3)])


@_built
def mat_t_mat(a, b):
    """a^T b of two 3x3 matrices."""
    a, b = _matrix(a), _matrix(b)
    zero = _local(a[0][0] * b[0][0] * 0)
    return make_matrix([[zero + a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j] for j in range(3)]
                        for i in range(3)])
