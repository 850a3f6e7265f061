"""SPH kernel, grid neighbour lists and displacement gradient (fracture/sph.py)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from taichi_frac.fracture import (
    default_smoothing_length,
    displacement_gradient,
    kernel_values,
    neighbor_lists,
)
from taichi_frac.fracture import sph


def jittered_block(per_side, spacing=0.1, jitter=0.2, seed=0):
    rng = np.random.default_rng(seed)
    g = np.arange(per_side) * spacing
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = pts + rng.uniform(-jitter, jitter, pts.shape) * spacing
    return pts, np.full(len(pts), spacing**3)


def brute_force_lists(points, radius):
    tree = cKDTree(points)
    rows = [sorted(j for j in tree.query_ball_point(p, radius) if j != i and
                   np.linalg.norm(points[j] - p) < radius) for i, p in enumerate(points)]
    return rows


def test_cubic_spline_is_normalised_and_derivative_consistent():
    h = 0.3
    r = (np.arange(20000) + 0.5) * h / 20000
    w, dw = kernel_values(r, h)
    integral = np.sum(4 * np.pi * r**2 * w) * (h / 20000)
    assert integral == pytest.approx(1.0, rel=1e-7)
    # dW/dr against central differences of W (C1 spline: second order away from q = 1/2).
    w_plus, _ = kernel_values(r + 1e-7, h)
    w_minus, _ = kernel_values(r - 1e-7, h)
    np.testing.assert_allclose(dw, (w_plus - w_minus) / 2e-7, rtol=0, atol=1e-5 * np.abs(dw).max())
    w_out, dw_out = kernel_values([h, 1.5 * h], h)
    assert np.all(w_out == 0) and np.all(dw_out == 0)


@pytest.mark.parametrize("case", ["block", "line", "coincident", "single"])
def test_neighbor_lists_match_brute_force(case):
    rng = np.random.default_rng(1)
    if case == "block":
        pts, _ = jittered_block(9)
        radius = 0.21
    elif case == "line":  # very elongated: the grid must grow its cells, not allocate 1e9
        pts = np.zeros((300, 3))
        pts[:, 0] = np.sort(rng.uniform(0, 1e4, 300))
        pts[:, 1] = rng.uniform(0, 1e-3, 300)
        radius = 1e-2
    elif case == "coincident":
        pts = np.zeros((20, 3))
        radius = 1.0
    else:
        pts = np.ones((1, 3))
        radius = 1.0
    offsets, indices = neighbor_lists(pts, radius)
    assert offsets.dtype == np.int32 and indices.dtype == np.int32
    assert offsets[0] == 0 and offsets[-1] == len(indices)
    expected = brute_force_lists(pts, radius) if case != "coincident" else [[]] * len(pts)
    got = [list(indices[offsets[i]:offsets[i + 1]]) for i in range(len(pts))]
    if case == "coincident":
        # Coincident points are at distance 0 < radius: all are neighbours of each other.
        expected = [[j for j in range(len(pts)) if j != i] for i in range(len(pts))]
    assert got == expected


def linear_field(points):
    a = np.array([[1.0, 2.0, -0.5], [0.3, -1.0, 0.7], [2.0, 0.1, 0.4]]) * 1e-6
    return points @ a.T + [1e-3, -2e-3, 5e-4], a


def test_corrected_gradient_is_exact_for_linear_fields_and_plain_is_biased_at_surface():
    pts, vol = jittered_block(10)
    h = default_smoothing_length(vol)
    assert h == pytest.approx(0.2)
    u, a = linear_field(pts)
    offsets, indices = neighbor_lists(pts, h)
    corrected, fallback = displacement_gradient(pts, vol, u, offsets, indices, h, True,
                                                return_fallback=True)
    assert not fallback.any()
    assert np.abs(corrected - a).max() < 1e-9 * np.abs(a).max()
    plain = displacement_gradient(pts, vol, u, offsets, indices, h, False)
    lo, hi = pts.min(0), pts.max(0)
    surface = np.any((pts - lo < 0.5 * h) | (hi - pts < 0.5 * h), axis=1)
    err = np.linalg.norm(plain - a, axis=(1, 2)) / np.linalg.norm(a)
    assert np.median(err[surface]) > 0.2  # missing neighbours: the plain sum is biased
    assert np.median(err[~surface]) < 0.2


def test_custom_csr_rows_per_query_and_per_point():
    pts, vol = jittered_block(7, seed=2)
    h = default_smoothing_length(vol)
    rng = np.random.default_rng(5)
    u = rng.normal(size=pts.shape) * 1e-6
    offsets, indices = neighbor_lists(pts, h)
    full = displacement_gradient(pts, vol, u, offsets, indices, h, False)
    # Per point, subset of queries.
    query = np.array([5, 100, 7, 5])
    sub = displacement_gradient(pts, vol, u, offsets, indices, h, False, query=query)
    np.testing.assert_array_equal(sub, full[query])
    # Per query: the same point twice, each with half of its neighbours (crack groups).
    i = 171
    nbrs = indices[offsets[i]:offsets[i + 1]]
    groups = [nbrs[::2], nbrs[1::2]]
    g_off = np.array([0, len(groups[0]), len(nbrs)])
    g_idx = np.concatenate(groups).astype(np.int64)
    got = displacement_gradient(pts, vol, u, g_off, g_idx, h, False, query=[i, i])
    for k, grp in enumerate(groups):
        d = pts[grp] - pts[i]
        r = np.linalg.norm(d, axis=1)
        _, dw = kernel_values(r, h)
        grad_w = -(dw / r)[:, None] * d
        ref = np.einsum("j,ja,jb->ab", vol[grp], u[grp] - u[i], grad_w)
        np.testing.assert_allclose(got[k], ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    # The two halves add up to the full plain sum (it is linear in the neighbour set).
    np.testing.assert_allclose(got[0] + got[1], full[i], rtol=1e-12, atol=1e-20)


def test_singular_correction_falls_back_to_plain_sum():
    # Collinear neighbours: M has rank 1, the correction is skipped and flagged.
    pts = np.zeros((5, 3))
    pts[:, 0] = np.arange(5) * 0.1
    vol = np.full(5, 1e-3)
    u = np.zeros((5, 3))
    u[:, 1] = pts[:, 0] * 1e-6
    offsets, indices = neighbor_lists(pts, 0.25)
    corrected, fallback = displacement_gradient(pts, vol, u, offsets, indices, 0.25, True,
                                                return_fallback=True)
    plain = displacement_gradient(pts, vol, u, offsets, indices, 0.25, False)
    assert fallback.all()
    np.testing.assert_array_equal(corrected, plain)
    assert np.all(np.isfinite(corrected))
    # An isolated particle (no neighbours) gets a zero gradient.
    lone = displacement_gradient(pts[:1], vol[:1], u[:1], [0, 0], np.zeros(0, int), 0.25, True)
    assert np.all(lone == 0)


def _compiled(kernel):
    return len(kernel._primal.compiled_kernels)


def test_kernels_compile_once_for_any_size():
    for per_side in (5, 8):  # different N, M, Q: no new compilation on the second size
        pts, vol = jittered_block(per_side)
        h = default_smoothing_length(vol)
        u, _ = linear_field(pts)
        offsets, indices = neighbor_lists(pts, h)
        displacement_gradient(pts, vol, u, offsets, indices, h, True)
        displacement_gradient(pts, vol, u, offsets, indices, h, False, query=[0, 3])
        if per_side == 5:
            # (the neighbour walk: one kernel for its count and fill passes)
            counts = [_compiled(k) for k in (sph._walk_neighbors, sph._gradient_kernel)]
            assert counts == [1, 1]
    assert [_compiled(k) for k in (sph._walk_neighbors, sph._gradient_kernel)] == [1, 1]


def test_bad_csr_raises():
    pts, vol = jittered_block(3)
    u = np.zeros_like(pts)
    with pytest.raises(ValueError):
        displacement_gradient(pts, vol, u, [0, 1, 2], [0, 1], 0.2)  # wrong length
    with pytest.raises(ValueError):
        displacement_gradient(pts, vol, u, np.zeros(len(pts) + 1), [], 0.2, query=[99])
