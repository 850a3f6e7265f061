"""Connected components of a tet set whose face bonds a crack has cut (``fragments.split_body``),
by union-find in one serial Taichi kernel: scipy's connected_components spends most of
its time on matrix conversions at this size (a ring's 5,450 tets)."""

import numpy as np

from ..runtime import ti
from .. import runtime


@ti.kernel
def _union_find(bonds: ti.types.ndarray(dtype=ti.i32, ndim=2), cut: ti.types.ndarray(dtype=ti.i8, ndim=1),
                root: ti.types.ndarray(dtype=ti.i32, ndim=1), label: ti.types.ndarray(dtype=ti.i32, ndim=1)) -> ti.i32:
    """Union-find over the tets (``root`` (T,) scratch) joined by the bonds (B,2) not
    ``cut``; ``label`` (T,) gets each tet's component, numbered in the order of their
    smallest tets (as scipy's connected_components numbers them). Returns the count."""
    count = 0
    ti.loop_config(serialize=True)
    for _ in range(1):
        for t in range(root.shape[0]):
            root[t] = t
        for e in range(bonds.shape[0]):
            if cut[e] == 0:
                a = bonds[e, 0]
                while root[a] != a:  # (path halving)
                    root[a] = root[root[a]]
                    a = root[a]
                b = bonds[e, 1]
                while root[b] != b:
                    root[b] = root[root[b]]
                    b = root[b]
                if a < b:  # every set's root is its smallest tet
                    root[b] = a
                elif b < a:
                    root[a] = b
        for t in range(root.shape[0]):
            r = t
            while root[r] != r:
                r = root[r]
            if r == t:
                label[t] = count
                count += 1
            else:
                label[t] = label[r]
    return count


def connected_tets(t_count: int, bonds: np.ndarray, cut: np.ndarray):
    """Connected components of ``t_count`` tets joined by the bonds (B,2) not ``cut`` (B,)
    bool: (count, labels (T,) int32), numbered in the order of their smallest tets."""
    bonds = np.ascontiguousarray(bonds, dtype=np.int32).reshape(-1, 2)
    if len(bonds) == 0:  # (a kernel cannot take an empty array)
        return t_count, np.arange(t_count, dtype=np.int32)
    runtime.init()
    label = np.empty(t_count, dtype=np.int32)
    count = _union_find(bonds, np.ascontiguousarray(cut, dtype=np.int8), np.empty(t_count, dtype=np.int32), label)
    return int(count), label
