"""A body model's SPH neighbour lists: static model data (the paper's preprocessing).

The lists of a body's physics particles within the smoothing length h are fixed in the body
frame, so they are built once, when a breakable body is set up (``scene_setup.py``), and
kept here beside its model, by h, for as long as the model lives: the model itself never
changes after it is built. A fragment's are its root's restricted to its particles
(``BodyModel.root``, ``source_tet``): the same pairs, the distances being the root's, instead
of a grid search; they are made on the fragment's first analysis, or read row by row from the
root's before that (:func:`neighbor_rows`).
"""

from __future__ import annotations

import weakref

import numpy as np

from ..model import BodyModel
from ..options import FractureOptions
from .sph import neighbor_lists

# model -> {h [m]: (offsets, indices)}: the lists of every live model, dropped with it.
_LISTS: "weakref.WeakKeyDictionary[BodyModel, dict]" = weakref.WeakKeyDictionary()


def smoothing_length(model: BodyModel, options: FractureOptions) -> float:
    """h [m] = ``options.smoothing_length_factor`` x the model's particle spacing (a
    fragment's is its root's, so its particles keep their neighbours)."""
    return float(options.smoothing_length_factor) * model.spacing


def model_neighbor_lists(model: BodyModel, h: float):
    """The full-field SPH neighbour lists (CSR offsets int64, indices int32) of a body model's
    physics particles within ``h`` [m], built on first use and kept while the model lives, so
    a body struck again, or several bodies built from one model, reuse them."""
    per_model = _LISTS.setdefault(model, {})
    if h not in per_model:
        if model.root is not None:
            per_model[h] = restrict_neighbor_lists(*model_neighbor_lists(model.root, h), model.source_tet,
                                                   model.root.tet_count)
        else:
            offsets, indices = neighbor_lists(model.particle_position, h)
            # int32 indices: what the gradient kernel takes, so no analysis converts a copy.
            per_model[h] = (np.asarray(offsets, dtype=np.int64), np.asarray(indices, dtype=np.int32))
    return per_model[h]


def restrict_neighbor_lists(offsets, indices, subset, count):
    """CSR neighbour lists of the points ``subset`` (S,) (ascending indices of ``count``
    points) from lists over all of them: row s keeps the neighbours of point subset[s] that
    are in the subset, renumbered to positions in it (still ascending)."""
    subset = np.asarray(subset, dtype=np.int64)
    local = np.full(count, -1, dtype=np.int32)
    local[subset] = np.arange(len(subset), dtype=np.int32)
    return _gather_rows(offsets, indices, subset, local)


def neighbor_rows(model: BodyModel, h: float, query: np.ndarray):
    """CSR lists (offsets (Q+1,) int64, indices int32) of the SPH neighbours of the
    particles ``query`` (Q,) only: row q is :func:`model_neighbor_lists`' row
    ``query[q]``, the same neighbours in the same order. A piece whose own lists are not
    built yet reads its root's rows and maps them to its particles, so a local analysis
    of a new piece (a few hundred rows) does not restrict its root's lists over the whole
    piece first (2.5 ms on a ring's big piece)."""
    query = np.asarray(query, dtype=np.int64)
    if h in _LISTS.get(model, ()) or model.root is None:
        return _gather_rows(*model_neighbor_lists(model, h), query)
    local = np.full(model.root.tet_count, -1, dtype=np.int32)
    local[model.source_tet] = np.arange(model.tet_count, dtype=np.int32)
    return _gather_rows(*model_neighbor_lists(model.root, h), model.source_tet[query].astype(np.int64), local)


def _gather_rows(offsets, indices, rows, renumber=None):
    """CSR lists (offsets int64, indices int32) of the rows ``rows`` (R,) of the CSR lists
    ``offsets``, ``indices``, in that order; with ``renumber`` (int32, -1 = drop), each
    neighbour j becomes renumber[j] and the dropped ones leave their row."""
    begin = offsets[rows]
    lengths = offsets[rows + 1] - begin
    starts = np.cumsum(lengths) - lengths
    found = indices[np.arange(int(lengths.sum())) + np.repeat(begin - starts, lengths)]
    out_offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    if renumber is None:
        np.cumsum(lengths, out=out_offsets[1:])
        return out_offsets, np.asarray(found, dtype=np.int32)
    found = renumber[found]
    keep = found >= 0
    np.cumsum(np.bincount(np.repeat(np.arange(len(rows)), lengths)[keep], minlength=len(rows)), out=out_offsets[1:])
    return out_offsets, found[keep]
