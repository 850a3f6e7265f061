"""The written-out 3-vector and 3x3 products (kinematics/linalg3.py) against Taichi's own
operators and against numpy in float64: each helper must give, in a kernel of its own, the
very bits the operator gives (so that swapping one for the other in a kernel changes only
what LLVM's fast-math may reorder), and the product numpy computes."""

import numpy as np
import pytest
import taichi as ti

from taichi_frac.kinematics import linalg3 as la

N = 257


@pytest.fixture(scope="module")
def data(ti_cpu):
    rng = np.random.default_rng(7)
    a = ti.Matrix.field(3, 3, ti.f32, shape=N)
    b = ti.Matrix.field(3, 3, ti.f32, shape=N)
    u = ti.Vector.field(3, ti.f32, shape=N)
    w = ti.Vector.field(3, ti.f32, shape=N)
    arrays = dict(a=rng.normal(size=(N, 3, 3)) * 10.0 ** rng.integers(-3, 3, size=(N, 1, 1)),
                  b=rng.normal(size=(N, 3, 3)), u=rng.normal(size=(N, 3)) * 10.0 ** rng.integers(-3, 3, size=(N, 1)),
                  w=rng.normal(size=(N, 3)))
    arrays = {k: v.astype(np.float32) for k, v in arrays.items()}
    for field, key in ((a, "a"), (b, "b"), (u, "u"), (w, "w")):
        field.from_numpy(arrays[key])
    return a, b, u, w, arrays


def _vector_pair(expr_ours, expr_taichi):
    """Two kernels writing (N,3) results of each expression (functions of a, b, u, w, i)."""
    out_ours = ti.Vector.field(3, ti.f32, shape=N)
    out_taichi = ti.Vector.field(3, ti.f32, shape=N)

    @ti.kernel
    def ours(a: ti.template(), b: ti.template(), u: ti.template(), w: ti.template()):
        for i in range(N):
            out_ours[i] = expr_ours(a[i], b[i], u[i], w[i])

    @ti.kernel
    def theirs(a: ti.template(), b: ti.template(), u: ti.template(), w: ti.template()):
        for i in range(N):
            out_taichi[i] = expr_taichi(a[i], b[i], u[i], w[i])

    return ours, theirs, out_ours, out_taichi


@ti.func
def _mat_vec(a, b, u, w):
    return la.mat_vec(a, u)


@ti.func
def _mat_vec_ti(a, b, u, w):
    return a @ u


@ti.func
def _mat_t_vec(a, b, u, w):
    return la.mat_t_vec(a, u)


@ti.func
def _mat_t_vec_ti(a, b, u, w):
    return a.transpose() @ u


@ti.func
def _cross(a, b, u, w):
    return la.cross(u, w)


@ti.func
def _cross_ti(a, b, u, w):
    return u.cross(w)


@ti.func
def _scalars(a, b, u, w):
    return ti.Vector([la.dot(u, w), la.norm(u), la.norm_sqr(w)])


@ti.func
def _scalars_ti(a, b, u, w):
    return ti.Vector([u.dot(w), u.norm(), w.norm_sqr()])


def _numpy_vectors(name, arrays):
    a, u, w = (arrays[k].astype(np.float64) for k in "auw")
    return {"mat_vec": np.einsum("nij,nj->ni", a, u), "mat_t_vec": np.einsum("nji,nj->ni", a, u),
            "cross": np.cross(u, w),
            "scalars": np.stack([np.einsum("ni,ni->n", u, w), np.linalg.norm(u, axis=1),
                                 np.einsum("ni,ni->n", w, w)], axis=1)}[name]


@pytest.mark.parametrize("name, ours, theirs", [("mat_vec", _mat_vec, _mat_vec_ti),
                                                ("mat_t_vec", _mat_t_vec, _mat_t_vec_ti),
                                                ("cross", _cross, _cross_ti),
                                                ("scalars", _scalars, _scalars_ti)])
def test_vector_helpers_match_taichi_bit_for_bit(data, name, ours, theirs):
    a, b, u, w, arrays = data
    k_ours, k_theirs, out_ours, out_theirs = _vector_pair(ours, theirs)
    k_ours(a, b, u, w)
    k_theirs(a, b, u, w)
    got, want = out_ours.to_numpy(), out_theirs.to_numpy()
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    exact = _numpy_vectors(name, arrays)
    scale = np.abs(exact).max(axis=1, keepdims=True) + 1e-30
    # float32 round-off of a three-term sum, relative to the largest component
    assert np.max(np.abs(got - exact) / scale) < 1e-5


def test_matrix_products_match_taichi_bit_for_bit(data):
    a, b, _, _, arrays = data
    outs = {k: ti.Matrix.field(3, 3, ti.f32, shape=N) for k in ("mm", "mm_ti", "mmt", "mmt_ti", "mtm", "mtm_ti")}

    @ti.kernel
    def ours(a: ti.template(), b: ti.template()):
        for i in range(N):
            outs["mm"][i] = la.mat_mat(a[i], b[i])
            outs["mmt"][i] = la.mat_mat_t(a[i], b[i])
            outs["mtm"][i] = la.mat_t_mat(a[i], b[i])

    @ti.kernel
    def theirs(a: ti.template(), b: ti.template()):
        for i in range(N):
            outs["mm_ti"][i] = a[i] @ b[i]
            outs["mmt_ti"][i] = a[i] @ b[i].transpose()
            outs["mtm_ti"][i] = a[i].transpose() @ b[i]

    ours(a, b)
    theirs(a, b)
    got = {k: f.to_numpy() for k, f in outs.items()}
    assert np.array_equal(got["mm"].view(np.uint32), got["mm_ti"].view(np.uint32))
    assert np.array_equal(got["mmt"].view(np.uint32), got["mmt_ti"].view(np.uint32))
    assert np.array_equal(got["mtm"].view(np.uint32), got["mtm_ti"].view(np.uint32))
    a64, b64 = arrays["a"].astype(np.float64), arrays["b"].astype(np.float64)
    for key, exact in (("mm", a64 @ b64), ("mmt", a64 @ np.swapaxes(b64, 1, 2)), ("mtm", np.swapaxes(a64, 1, 2) @ b64)):
        scale = np.abs(exact).max(axis=(1, 2), keepdims=True) + 1e-30
        assert np.max(np.abs(got[key] - exact) / scale) < 1e-5


def test_every_helper_builds_in_a_kernel_without_the_outside_function_warning(data):
    """The helpers are plain functions the front end calls on expressions, not ``ti.func``:
    a kernel calling each compiles with no warning (Taichi warns of a call to a function
    that is not its own unless the function says it is) and gives numpy's values."""
    import warnings

    a, b, u, w, arrays = data
    out = ti.field(ti.f32, shape=(N, 9 + 9 + 9 + 3 + 3 + 3 + 3))

    @ti.kernel
    def every(a: ti.template(), b: ti.template(), u: ti.template(), w: ti.template()):
        for i in range(N):
            row = [la.mat_mat(a[i], b[i]), la.mat_mat_t(a[i], b[i]), la.mat_t_mat(a[i], b[i])]
            for k in ti.static(range(3)):
                for r, c in ti.static(ti.ndrange(3, 3)):
                    out[i, 9 * k + 3 * r + c] = row[k][r, c]
            vectors = [la.mat_vec(a[i], u[i]), la.mat_t_vec(a[i], u[i]), la.cross(u[i], w[i])]
            for k in ti.static(range(3)):
                for c in ti.static(range(3)):
                    out[i, 27 + 3 * k + c] = vectors[k][c]
            out[i, 36] = la.dot(u[i], w[i])
            out[i, 37] = la.norm(u[i])
            out[i, 38] = la.norm_sqr(w[i])

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        every(a, b, u, w)
    got = out.to_numpy().astype(np.float64)
    a64, b64, u64, w64 = (arrays[k].astype(np.float64) for k in "abuw")
    exact = np.concatenate([(a64 @ b64).reshape(N, 9), (a64 @ np.swapaxes(b64, 1, 2)).reshape(N, 9),
                            (np.swapaxes(a64, 1, 2) @ b64).reshape(N, 9), np.einsum("nij,nj->ni", a64, u64),
                            np.einsum("nji,nj->ni", a64, u64), np.cross(u64, w64),
                            np.einsum("ni,ni->n", u64, w64)[:, None], np.linalg.norm(u64, axis=1)[:, None],
                            np.einsum("ni,ni->n", w64, w64)[:, None]], axis=1)
    scale = np.abs(exact).max(axis=1, keepdims=True) + 1e-30
    assert np.max(np.abs(got - exact) / scale) < 1e-5
