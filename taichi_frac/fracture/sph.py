"""SPH kernel, neighbour lists and the displacement gradient (BRIEF.md §1 step 6, eq. 7).

Conventions:
- ``smoothing_length`` h is the kernel's **support radius**: W(r, h) = 0 for r >= h (the
  convention of Mueller et al. 2003 and SPlisHSPlasH). The default h is
  ``FractureOptions.smoothing_length_factor`` (2.0) x the mean particle spacing
  (mean of V^(1/3)), which gives about 4/3 pi 2^3 ~ 33 neighbours per interior particle.
- Kernel: the cubic B-spline (Monaghan 1992) scaled to support h,
  W(q) = 8 / (pi h^3) * {6 q^3 - 6 q^2 + 1 (q <= 1/2); 2 (1 - q)^3 (q <= 1)}, q = r / h.
- Neighbour lists are CSR: row i of (offsets, indices) lists j with 0 < |x_i - x_j| < h,
  in increasing j order; i itself is not listed.
- Gradients are f64, (grad u)_ab = d u_a / d x_b.

All kernels take ``ti.types.ndarray`` arguments with fixed dtype/ndim, so each compiles once
per process whatever the array sizes.
"""


import math

import numpy as np

from ..runtime import ti
from .. import runtime
from ..kinematics import linalg3 as la
from .stress import sym_eig3_extremes_f64

_vec3 = ti.types.vector(3, ti.f64)
_mat3 = ti.types.matrix(3, 3, ti.f64)

# The Bonet-Lok correction matrix M_i is symmetric positive semi-definite; when its smallest
# eigenvalue is below this fraction of its largest (neighbours nearly coplanar or collinear,
# or fewer than 3) inverting it would amplify noise without bound, so the particle falls back
# to the plain sum and is flagged.
CORRECTION_MIN_EIGEN_RATIO = 1.0e-3

# Grid cells are at least the search radius wide; a sparse or very elongated point set would
# need very many empty cells, so the cell grows until there are at most this many per point.
_MAX_CELLS_PER_POINT = 8


def default_smoothing_length(volumes, factor: float = 2.0) -> float:
    """h [m] = factor x mean particle spacing, the spacing of a particle being V^(1/3)."""
    vol = np.asarray(volumes, dtype=np.float64)
    if vol.size == 0 or np.any(~np.isfinite(vol)) or np.any(vol <= 0.0):
        raise ValueError("volumes must be a non-empty array of positive finite values")
    return float(factor) * float(np.mean(np.cbrt(vol)))


@ti.func
def cubic_spline_dwdr(r: ti.f64, h: ti.f64) -> ti.f64:
    """dW/dr of the cubic spline with support h [1/m^4]; 0 outside (0, h)."""
    q = r / h
    # ti.f64(pi): bare float literals in kernels are f32 constants (runtime default_fp).
    k = 8.0 / (ti.f64(math.pi) * h * h * h * h)  # 8 / (pi h^3), times 1/h for d/dr
    result = ti.cast(0.0, ti.f64)  # a bare literal would be the default f32
    if q <= 0.5:
        result = k * (18.0 * q * q - 12.0 * q)
    elif q < 1.0:
        result = -6.0 * k * (1.0 - q) * (1.0 - q)
    return result


@ti.func
def cubic_spline_w(r: ti.f64, h: ti.f64) -> ti.f64:
    """W(r, h) of the cubic spline with support h [1/m^3]; integrates to 1 over R^3."""
    q = r / h
    k = 8.0 / (ti.f64(math.pi) * h * h * h)
    result = ti.cast(0.0, ti.f64)  # a bare literal would be the default f32
    if q <= 0.5:
        result = k * (6.0 * q * q * q - 6.0 * q * q + 1.0)
    elif q < 1.0:
        result = 2.0 * k * (1.0 - q) * (1.0 - q) * (1.0 - q)
    return result


@ti.kernel
def _kernel_values(r: ti.types.ndarray(dtype=ti.f64, ndim=1), h: ti.f64,
                   w_out: ti.types.ndarray(dtype=ti.f64, ndim=1),
                   dwdr_out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    for i in range(r.shape[0]):
        w_out[i] = cubic_spline_w(r[i], h)
        dwdr_out[i] = cubic_spline_dwdr(r[i], h)


def kernel_values(r, smoothing_length):
    """W and dW/dr of the cubic spline at distances r [m] (for tests): two (K,) arrays."""
    runtime.init()
    rr = np.ascontiguousarray(r, dtype=np.float64).reshape(-1)
    w, dw = np.zeros_like(rr), np.zeros_like(rr)
    if rr.size:
        _kernel_values(rr, float(smoothing_length), w, dw)
    return w, dw


# --- neighbour lists on a uniform grid ---------------------------------------------------

@ti.kernel
def _walk_neighbors(
    # Model:
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m]
    sorted_points: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (N,) point ids by cell, stable
    cell_start: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (C+1,) CSR over cells
    cell_of: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (N,3) integer cell coords
    dims: ti.types.vector(3, ti.i32), radius: ti.f64,
    fill: ti.i32,  # 0: count each row; 1: fill the rows of ``offsets``
    offsets: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (N+1,) when filling
    # Data out:
    count_out: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (N,) when counting
    indices_out: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (M,) when filling
):
    """The pairs closer than ``radius`` over the 27 cells around each point: counted per
    row (``fill`` 0), then written into the rows, each sorted by index (``fill`` 1). One
    walk for both passes, so the two agree pair for pair."""
    r2 = radius * radius
    for i in range(points.shape[0]):
        xi = _vec3(points[i, 0], points[i, 1], points[i, 2])
        begin = 0
        if fill != 0:
            begin = offsets[i]
        slot = begin
        # Plain loops over the 27 cells, not ti.static: unrolled, the 27 copies cost
        # Taichi's front end time in every new process.
        for dz, dy, dx in ti.ndrange((-1, 2), (-1, 2), (-1, 2)):
            cx = cell_of[i, 0] + dx
            cy = cell_of[i, 1] + dy
            cz = cell_of[i, 2] + dz
            if 0 <= cx < dims[0] and 0 <= cy < dims[1] and 0 <= cz < dims[2]:
                cell = (cz * dims[1] + cy) * dims[0] + cx
                for s in range(cell_start[cell], cell_start[cell + 1]):
                    j = sorted_points[s]
                    d = _vec3(points[j, 0], points[j, 1], points[j, 2]) - xi
                    if j != i and la.dot(d, d) < r2:
                        if fill != 0:
                            indices_out[slot] = j
                        slot += 1
        if fill == 0:
            count_out[i] = slot
        else:
            # Insertion sort of the row by index: rows are short (~30), and sorted rows make
            # every later sum independent of the grid layout.
            for a in range(begin + 1, slot):
                value = indices_out[a]
                b = a - 1
                while b >= begin and indices_out[b] > value:
                    indices_out[b + 1] = indices_out[b]
                    b -= 1
                indices_out[b + 1] = value


def neighbor_lists(points, radius):
    """All pairs closer than ``radius``, as CSR lists, from a uniform grid (no O(N^2)).

    Particles are binned into cells at least ``radius`` wide; the cell order is a stable
    numpy argsort of the cell keys (O(N log N), vectorised, deterministic); the pair search
    over the 27 surrounding cells -- the O(N k) part -- runs in one f64 Taichi kernel, twice
    (count, then fill; each row is sorted by index). A per-impact call, so the small host
    part is not in any per-substep loop.

    Args:
        points: (N,3) [m].
        radius: search radius [m] (> 0), normally the smoothing length h.

    Returns:
        offsets (N+1,) int32 and indices (M,) int32: the neighbours of i are
        ``indices[offsets[i]:offsets[i+1]]``, sorted, excluding i, with |x_i - x_j| < radius.
    """
    runtime.init()
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N,3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0.0):
        raise ValueError(f"radius must be > 0, got {radius!r}")
    n = len(pts)
    if n == 0:
        return np.zeros(1, np.int32), np.zeros(0, np.int32)
    low = pts.min(axis=0)
    extent = pts.max(axis=0) - low
    cell = radius
    while True:
        dims = np.floor(extent / cell).astype(np.int64) + 1
        if int(np.prod(dims)) <= _MAX_CELLS_PER_POINT * n + 64:
            break
        cell *= 1.5
    cell_of = np.minimum(np.floor((pts - low) / cell).astype(np.int64), dims - 1)
    key = (cell_of[:, 2] * dims[1] + cell_of[:, 1]) * dims[0] + cell_of[:, 0]
    sorted_points = np.argsort(key, kind="stable").astype(np.int32)
    counts = np.bincount(key, minlength=int(np.prod(dims)))
    cell_start = np.zeros(len(counts) + 1, np.int32)
    np.cumsum(counts, out=cell_start[1:])
    cell_of32 = np.ascontiguousarray(cell_of, dtype=np.int32)
    dims_v = ti.types.vector(3, ti.i32)(*[int(d) for d in dims])
    row_count = np.zeros(n, np.int32)
    unused = np.zeros(1, np.int32)
    _walk_neighbors(pts, sorted_points, cell_start, cell_of32, dims_v, radius, 0, unused, row_count, unused)
    total = int(row_count.sum(dtype=np.int64))
    if total >= 2**31:
        raise ValueError(f"{total} neighbour pairs overflow int32: use a smaller radius")
    offsets = np.zeros(n + 1, np.int32)
    np.cumsum(row_count, out=offsets[1:])
    indices = np.zeros(total, np.int32)
    if total:
        _walk_neighbors(pts, sorted_points, cell_start, cell_of32, dims_v, radius, 1, offsets, row_count, indices)
    return offsets, indices


# --- displacement gradient (eq. 7), plain or Bonet-Lok corrected -----------------------------

@ti.func
def gradient_at(points: ti.template(), volumes: ti.template(), i, begin, end, indices: ti.template(),
                smoothing_length, corrected, min_eigen_ratio, displacement: ti.template()):
    """grad u at particle ``i`` from its neighbours ``indices[begin:end]`` (eq. 7, plain or
    Bonet-Lok corrected; the arguments as :func:`_gradient_kernel`'s): (grad (3,3) [-],
    fallback: 1 when the correction was skipped)."""
    xi = _vec3(points[i, 0], points[i, 1], points[i, 2])
    ui = _vec3(displacement[i, 0], displacement[i, 1], displacement[i, 2])
    grad = _mat3(0.0)
    moment = _mat3(0.0)  # M_i = sum_j V_j (x_j - x_i) (x) grad_i W_ij  (= L_i^-T)
    for k in range(begin, end):
        j = indices[k]
        d = _vec3(points[j, 0], points[j, 1], points[j, 2]) - xi
        r = la.norm(d)
        if j != i and r > 0.0 and r < smoothing_length:
            # grad_i W(x_i - x_j, h) = W'(r) (x_i - x_j) / r
            grad_w = -cubic_spline_dwdr(r, smoothing_length) / r * d
            uj = _vec3(displacement[j, 0], displacement[j, 1], displacement[j, 2])
            grad += volumes[j] * (uj - ui).outer_product(grad_w)
            moment += volumes[j] * d.outer_product(grad_w)
    fallback = 0
    if corrected != 0:
        # Bonet & Lok 1999: grad~W = L grad W with L = (sum V grad W (x) (x_j - x_i))^-1,
        # so grad u = (sum V (u_j - u_i) (x) grad W) L^T = G M^-1, exact for linear u.
        # M is symmetric PSD (grad W is parallel to x_j - x_i); its eigenvalue ratio
        # guards the inverse (f64 cofactor formula). The extreme eigenvalues in closed
        # form: Jacobi sweeps for them would cost as much as the rest of the kernel.
        scale = moment.trace()
        fallback = 1
        if scale > 0.0:
            low, high = sym_eig3_extremes_f64(moment / scale)
            if low > min_eigen_ratio * high:
                grad = grad @ moment.inverse()
                fallback = 0
    return grad, fallback


@ti.kernel
def _gradient_kernel(
    # Model:
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m]
    volumes: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (N,) [m^3]
    query: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,) analysis points
    row_begin: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,) CSR row of query q ...
    row_end: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,) ... in indices[begin:end]
    indices: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (M,) neighbour ids
    smoothing_length: ti.f64, corrected: ti.i32, min_eigen_ratio: ti.f64,
    # Data in:
    displacement: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m]
    # Data out:
    grad_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [-]
    fallback_out: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,) 1 = correction skipped
):
    for q in range(query.shape[0]):
        grad, fallback = gradient_at(points, volumes, query[q], row_begin[q], row_end[q], indices, smoothing_length,
                                     corrected, min_eigen_ratio, displacement)
        fallback_out[q] = fallback
        for a, b in ti.static(ti.ndrange(3, 3)):
            grad_out[q, a, b] = grad[a, b]


def displacement_gradient(points, volumes, displacement, offsets, indices, smoothing_length,
                          corrected=True, query=None, *, return_fallback=False):
    """SPH displacement gradient (BRIEF.md eq. 7), optionally Bonet-Lok corrected.

    grad u_i = sum_j V_j (u_j - u_i) (x) grad_i W(x_i - x_j, h)            (plain)
    grad u_i = [sum_j V_j (u_j - u_i) (x) grad_i W] M_i^-1,
        M_i = sum_j V_j (x_j - x_i) (x) grad_i W                            (corrected)

    The corrected form (Bonet & Lok, CMAME 180, 1999, eq. 32) reproduces any linear field
    exactly, so it is unbiased at free surfaces where the plain sum's missing neighbours
    shrink the gradient. Where M_i is near singular (smallest/largest eigenvalue below
    :data:`CORRECTION_MIN_EIGEN_RATIO`, e.g. fewer than 3 non-coplanar neighbours) that
    particle falls back to the plain sum; a particle with no neighbours gets 0.

    Args:
        points: (N,3) [m]; volumes: (N,) [m^3] (m_j / rho_j); displacement: (N,3) [m].
        offsets, indices: CSR neighbour lists (any int dtype), in either layout:
            - per query: ``len(offsets) == Q + 1``, row q lists the neighbours used for
              ``query[q]`` -- any subset, the same point may appear in several rows (e.g.
              one row per crack group);
            - per point: ``len(offsets) == N + 1`` (and Q != N), row ``query[q]`` is used
              (e.g. the output of :func:`neighbor_lists` with a subset ``query``).
            Entries equal to the row's own point and those at distance >= h are skipped.
        smoothing_length: h [m], kernel support radius.
        corrected: apply the Bonet-Lok correction.
        query: (Q,) indices of the analysis points; default all N (then offsets has N+1).
        return_fallback: also return a (Q,) bool array, True where the correction was asked
            for but skipped.

    Returns:
        (Q,3,3) float64, (grad u)_ab = d u_a / d x_b [-]; with ``return_fallback``, a tuple
        (grad, fallback).
    """
    runtime.init()
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n = len(pts)
    vol = np.ascontiguousarray(volumes, dtype=np.float64).reshape(-1)
    disp = np.ascontiguousarray(displacement, dtype=np.float64)
    if pts.shape != (n, 3) or disp.shape != (n, 3) or vol.shape != (n,):
        raise ValueError(f"points {pts.shape}, displacement {disp.shape} and volumes "
                         f"{vol.shape} must be (N,3), (N,3), (N,)")
    off = np.ascontiguousarray(offsets, dtype=np.int64).reshape(-1)
    idx = np.ascontiguousarray(indices, dtype=np.int32).reshape(-1)
    if query is None:
        q_ids = np.arange(n, dtype=np.int32)
    else:
        q_ids = np.ascontiguousarray(query, dtype=np.int32).reshape(-1)
    n_query = len(q_ids)
    if n_query and (q_ids.min() < 0 or q_ids.max() >= n):
        raise ValueError("query indices out of range")
    if len(off) == n_query + 1:
        begin, end = off[:-1], off[1:]
    elif len(off) == n + 1:
        begin, end = off[q_ids], off[q_ids + 1]
    else:
        raise ValueError(f"offsets has length {len(off)}: expected Q+1 = {n_query + 1} "
                         f"(rows per query) or N+1 = {n + 1} (rows per point)")
    if len(off) and (off[0] < 0 or off[-1] > len(idx) or np.any(np.diff(off) < 0)):
        raise ValueError("offsets must be non-decreasing within [0, len(indices)]")
    if len(idx) and (idx.min() < 0 or idx.max() >= n):
        raise ValueError("neighbour indices out of range")
    h = float(smoothing_length)
    if not (np.isfinite(h) and h > 0.0):
        raise ValueError(f"smoothing_length must be > 0, got {smoothing_length!r}")
    grad = np.zeros((n_query, 3, 3))
    fallback = np.zeros(n_query, np.int32)
    if n_query:
        _gradient_kernel(pts, vol, q_ids, np.ascontiguousarray(begin, dtype=np.int32),
                         np.ascontiguousarray(end, dtype=np.int32), idx if len(idx) else np.zeros(1, np.int32),
                         h, int(bool(corrected)), CORRECTION_MIN_EIGEN_RATIO, disp, grad, fallback)
    if return_fallback:
        return grad, fallback.astype(bool)
    return grad
