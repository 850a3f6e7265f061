"""KD-trees of a body's tet centroids, built once while one split is cut.

A cut asks again and again which tets lie nearest a point: its parts' votes, the reach and
overreach checks, the divides and trims, each pass of the crack fit again (1,300 trees in
the 13 rings' 72 cut passes, 7 % of their time), mostly of a few sets: the body's
centroids and each piece's. A tree is kept for the set named by the arrays it is built
from (the same array objects, which a split's cut passes everywhere), the most recent few.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

#: Trees kept: a split of a hundred pieces has a tree per piece and per its complement.
KEPT = 256

_TREES: OrderedDict = OrderedDict()  # key -> (positions, labels, tree)


def centroid_tree(model, labels: np.ndarray | None = None, k: int | None = None, *, others: bool = False):
    """``scipy.spatial.cKDTree`` of ``model``'s tet centroids (``particle_position`` (T,3)
    [m]): all of them, or those with ``labels == k`` (``labels != k`` with ``others``), in
    their order in the model."""
    from scipy.spatial import cKDTree

    positions = model.particle_position
    key = (id(positions), None if labels is None else id(labels), k, others)
    found = _TREES.get(key)
    if found is not None and found[0] is positions and found[1] is labels:
        _TREES.move_to_end(key)
        return found[2]
    points = positions if labels is None else positions[(labels != k) if others else (labels == k)]
    tree = cKDTree(points)
    _TREES[key] = (positions, labels, tree)  # (the arrays kept: their ids are not reused meanwhile)
    while len(_TREES) > KEPT:
        _TREES.popitem(last=False)
    return tree
