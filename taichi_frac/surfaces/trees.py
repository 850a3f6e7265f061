"""KD-trees of a body's tet centroids, built once while one split is cut.

A cut asks again and again which tets lie nearest a point: its parts' votes, the reach and
overreach checks, the divides and trims, each pass of the crack fit again (1,300 trees in
the 13 rings' 72 cut passes, 7 % of their time), mostly of a few sets: the body's
centroids and each piece's. A tree is kept for the set named by the arrays it is built
from (the same array objects, which a split's cut passes everywhere), the most recent few.
"""

from __future__ import annotations

import numpy as np

from ..memo import made_for

#: Trees kept: a split of a hundred pieces has a tree per piece and per its complement.
KEPT = 256

_TREES: dict = {}  # (memo.made_for) -> ((positions, labels), tree)


def centroid_tree(model, labels: np.ndarray | None = None, k: int | None = None, *, others: bool = False):
    """``scipy.spatial.cKDTree`` of ``model``'s tet centroids (``particle_position`` (T,3)
    [m]): all of them, or those with ``labels == k`` (``labels != k`` with ``others``), in
    their order in the model."""
    from scipy.spatial import cKDTree

    positions = model.particle_position

    def build():
        return cKDTree(positions if labels is None else positions[(labels != k) if others else (labels == k)])

    return made_for(_TREES, (positions, labels), (k, others), build, KEPT)
