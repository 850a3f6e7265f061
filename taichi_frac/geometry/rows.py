"""Row-wise operations on arrays of 3-vectors, (N,3) -> (N,) or (N,3).

numpy's reductions along a short last or middle axis (``(a * b).sum(axis=1)`` over 3
components, ``p.mean(axis=1)`` over a tet's 4 corners) and ``np.cross`` pay a generic
strided loop per row: on 20,000 rows ``(a * b).sum(axis=1)`` took 314 us against 94 us
for the ``einsum`` below, ``np.cross`` 765 us, and the mean of 5,000 tets' corners 382 us
against 125 us for the explicit sum. The fragment model build runs them on every piece.
``corner_mean`` and ``cross`` do the same floating-point operations as numpy's, so their
results are identical; ``dot``'s may differ in the last bit (summation order).
"""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) the dot product of each row of ``a`` and ``b`` (N,3)."""
    return np.einsum("ij,ij->i", a, b)


def norm(a: np.ndarray) -> np.ndarray:
    """(N,) the length of each row of ``a`` (N,3)."""
    return np.sqrt(np.einsum("ij,ij->i", a, a))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,3) the cross product of each row of ``a`` and ``b`` (N,3)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def corner_sum(p: np.ndarray) -> np.ndarray:
    """(N,3) the sum over axis 1 of ``p`` (N,K,3) (K corners), added in corner order."""
    total = p[:, 0].copy()
    for k in range(1, p.shape[1]):
        total += p[:, k]
    return total


def corner_mean(p: np.ndarray) -> np.ndarray:
    """(N,3) the mean over axis 1 of ``p`` (N,K,3): a tet's (K = 4) or face's (3) centre."""
    return corner_sum(p) / p.shape[1]
