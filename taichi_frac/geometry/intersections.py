"""Self-intersecting face pairs of a triangle mesh, in time linear in its size.

Broad phase: a hierarchical uniform grid. Faces are sorted into levels by the size of their
bounding box (level L holds boxes up to ``h0 * 4**L`` wide, ``h0`` about the median face)
and each face is binned by its box's minimum corner in a grid of its own level's cell size,
so a face lies in one cell and two boxes can overlap only if the smaller face's box reaches
the 3 x 3 x 3 cells around the larger one's bin. Each face visits those 27 cells on its own
level and every level above (a huge face among small ones costs nothing extra), so the work
is about 30 box tests a face whatever the sizes: 1,000,000 faces take ~1 s on two cores.

Narrow phase: an edge of one face crossing the interior of the other (Moller-Trumbore), in
float64. Faces sharing a vertex are skipped (neighbours always touch; folds between
neighbours show up as inconsistent winding or degenerate faces); coplanar overlaps are not
reported. One Taichi kernel does both phases, a face a thread.
"""


import contextlib
import sys

import numpy as np

from ..runtime import ti

#: Levels of the grid; boxes grow 2x a level, so 16 levels span sizes 32,768 : 1 (larger
#: faces all go in the top level, whose cell grows to fit them).
LEVELS = 16
_LEVEL_GROWTH = 2.0
#: Bits per cell coordinate in a packed cell key (3 x 19 + 4 level bits < 63).
_COORD_BITS = 19


@ti.func
def _segment_crosses(p0, p1, a, b, c) -> ti.i32:
    """Does segment p0-p1 cross triangle abc in both interiors (not parallel)?"""
    eps = 1e-12
    d = p1 - p0
    e1 = b - a
    e2 = c - a
    h = d.cross(e2)
    det = e1.dot(h)
    scale = d.norm() * e1.norm() * e2.norm()
    hit = 0
    if ti.abs(det) > 1e-9 * ti.max(scale, 1e-300):
        inv = 1.0 / det
        s = p0 - a
        u = inv * s.dot(h)
        q = s.cross(e1)
        w = inv * d.dot(q)
        t = inv * e2.dot(q)
        if u > eps and w > eps and u + w < 1.0 - eps and t > eps and t < 1.0 - eps:
            hit = 1
    return hit


@ti.func
def _faces_cross(vertices: ti.template(), faces: ti.template(), i, j) -> ti.i32:
    pi = ti.Matrix.zero(ti.f64, 3, 3)
    pj = ti.Matrix.zero(ti.f64, 3, 3)
    for k in ti.static(range(3)):
        for c in ti.static(range(3)):
            pi[k, c] = vertices[faces[i, k], c]
            pj[k, c] = vertices[faces[j, k], c]
    a0 = ti.Vector([pi[0, 0], pi[0, 1], pi[0, 2]])
    a1 = ti.Vector([pi[1, 0], pi[1, 1], pi[1, 2]])
    a2 = ti.Vector([pi[2, 0], pi[2, 1], pi[2, 2]])
    b0 = ti.Vector([pj[0, 0], pj[0, 1], pj[0, 2]])
    b1 = ti.Vector([pj[1, 0], pj[1, 1], pj[1, 2]])
    b2 = ti.Vector([pj[2, 0], pj[2, 1], pj[2, 2]])
    hit = (_segment_crosses(b0, b1, a0, a1, a2) | _segment_crosses(b1, b2, a0, a1, a2)
           | _segment_crosses(b2, b0, a0, a1, a2) | _segment_crosses(a0, a1, b0, b1, b2)
           | _segment_crosses(a1, a2, b0, b1, b2) | _segment_crosses(a2, a0, b0, b1, b2))
    return hit


@ti.func
def _hash(key, mask):
    return ((key * ti.i64(0x7F4A7C159E3779B1)) >> 29) & mask


@ti.func
def _find_key(table: ti.template(), key) -> ti.i32:
    """Slot of ``key`` in the open-addressing ``table`` (S,2) of (key, cell index), or -1."""
    mask = ti.cast(table.shape[0] - 1, ti.i64)
    slot = _hash(key, mask)
    found = -1
    while table[slot, 0] != -1:
        if table[slot, 0] == key:
            found = ti.cast(table[slot, 1], ti.i32)
            break
        slot = (slot + 1) & mask
    return found


@ti.kernel
def _fill_table(keys: ti.types.ndarray(dtype=ti.i64, ndim=1), table: ti.types.ndarray(dtype=ti.i64, ndim=2)):
    """Insert each key (K,) with its index into ``table`` (S,2) (linear probing, serial)."""
    mask = ti.cast(table.shape[0] - 1, ti.i64)
    ti.loop_config(serialize=True)
    for k in range(keys.shape[0]):
        slot = _hash(keys[k], mask)
        while table[slot, 0] != -1:
            slot = (slot + 1) & mask
        table[slot, 0] = keys[k]
        table[slot, 1] = k


@ti.kernel
def _crossing_pairs(
    # Mesh:
    vertices: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (V,3) [m]
    faces: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (F,3)
    box_lo: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (F,3) [m] face bounding boxes
    box_hi: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (F,3) [m]
    level: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (F,) grid level of each face
    # Grid:
    origin: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (3,) [m] lower corner, one cell in
    cell_size: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (LEVELS,) [m]
    occupied_level: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (LEVELS,) 1 where a level has faces
    table: ti.types.ndarray(dtype=ti.i64, ndim=2),  # (S,2) hash table: cell key -> cell index
    cell_start: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (K+1,) into binned_faces
    binned_faces: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (F,) faces ordered by cell key
    # Out:
    pairs_out: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (capacity,2) crossing pairs i < j
    count_out: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (1,) pairs found (may exceed capacity)
):
    for i in range(faces.shape[0]):
        for lvl in range(level[i], LEVELS):
            if occupied_level[lvl] == 0:
                continue
            h = cell_size[lvl]
            lo_c = ti.Vector([0, 0, 0], dt=ti.i32)
            hi_c = ti.Vector([0, 0, 0], dt=ti.i32)
            for c in ti.static(range(3)):
                lo_c[c] = ti.cast(ti.floor((box_lo[i, c] - h - origin[c]) / h), ti.i32)
                hi_c[c] = ti.cast(ti.floor((box_hi[i, c] - origin[c]) / h), ti.i32)
            for cx in range(lo_c[0], hi_c[0] + 1):
                for cy in range(lo_c[1], hi_c[1] + 1):
                    for cz in range(lo_c[2], hi_c[2] + 1):
                        key = ((ti.cast(lvl, ti.i64) << (3 * _COORD_BITS)) | (ti.cast(cx, ti.i64) << (2 * _COORD_BITS))
                               | (ti.cast(cy, ti.i64) << _COORD_BITS) | ti.cast(cz, ti.i64))
                        slot = -1
                        if cx >= 0 and cy >= 0 and cz >= 0:
                            slot = _find_key(table, key)
                        if slot >= 0:
                            for n in range(cell_start[slot], cell_start[slot + 1]):
                                j = binned_faces[n]
                                if lvl == level[i] and j <= i:
                                    continue
                                overlap = True
                                for c in ti.static(range(3)):
                                    if box_lo[i, c] > box_hi[j, c] or box_lo[j, c] > box_hi[i, c]:
                                        overlap = False
                                if not overlap:
                                    continue
                                shared = False
                                for a in ti.static(range(3)):
                                    for b in ti.static(range(3)):
                                        if faces[i, a] == faces[j, b]:
                                            shared = True
                                if shared:
                                    continue
                                if _faces_cross(vertices, faces, i, j):
                                    slot_out = ti.atomic_add(count_out[0], 1)
                                    if slot_out < pairs_out.shape[0]:
                                        pairs_out[slot_out, 0] = ti.min(i, j)
                                        pairs_out[slot_out, 1] = ti.max(i, j)


def _ensure_taichi() -> None:
    """Taichi on whatever arch this process already uses (CPU otherwise); its banner goes
    to stderr so that ``info --json`` keeps a clean stdout."""
    with contextlib.redirect_stdout(sys.stderr):
        from .. import runtime

        runtime.init()


def crossing_face_pairs(vertices: np.ndarray, faces: np.ndarray, capacity: int = 1_000_000) -> np.ndarray:
    """Pairs (K,2) int64, i < j, sorted, of faces whose edges cross each other's interiors
    (see the module docstring). No size limit: the pair buffer grows when it overflows."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int32)
    if len(f) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    corners = (v[f[:, 0]], v[f[:, 1]], v[f[:, 2]])
    box_lo = np.minimum(np.minimum(corners[0], corners[1]), corners[2])
    box_hi = np.maximum(np.maximum(corners[0], corners[1]), corners[2])
    extent = (box_hi - box_lo).max(axis=1)
    lowest = box_lo.min(axis=0)
    span = float((box_hi.max(axis=0) - lowest).max())
    span = span if span > 0 else 1.0
    # Level 0's cell fits 90 % of the faces (a cell much larger than its faces holds many
    # faces that every neighbour then tests), but never so small that a coordinate overflows.
    h0 = max(float(np.quantile(extent, 0.9)), span / (2 ** (_COORD_BITS - 2)), 1e-300)
    level = np.ceil(np.log(np.maximum(extent, h0) / h0) / np.log(_LEVEL_GROWTH) - 1e-9).astype(np.int64)
    level = np.clip(level, 0, LEVELS - 1)
    cell_size = h0 * _LEVEL_GROWTH ** np.arange(LEVELS, dtype=np.float64)
    cell_size[-1] = max(cell_size[-1], float(extent.max()) * (1 + 1e-9))
    # One empty cell below the lowest box so that neighbour coordinates stay >= 0.
    origin = lowest - cell_size[-1]
    coords = np.floor((box_lo - origin) / cell_size[level][:, None]).astype(np.int64)
    keys = (level << (3 * _COORD_BITS)) | (coords[:, 0] << (2 * _COORD_BITS)) | (coords[:, 1] << _COORD_BITS) | coords[:, 2]
    order = np.argsort(keys, kind="stable")
    unique, start = np.unique(keys[order], return_index=True)
    cell_start = np.append(start, len(keys)).astype(np.int32)
    _ensure_taichi()
    table = np.full((1 << int(np.ceil(np.log2(2 * len(unique) + 2))), 2), -1, dtype=np.int64)
    _fill_table(unique.astype(np.int64), table)
    occupied = np.zeros(LEVELS, dtype=np.int32)
    occupied[np.unique(level)] = 1
    while True:
        pairs = np.zeros((capacity, 2), dtype=np.int32)
        count = np.zeros(1, dtype=np.int32)
        _crossing_pairs(v, f, box_lo, box_hi, level.astype(np.int32), np.ascontiguousarray(origin),
                        cell_size, occupied, table, cell_start, order.astype(np.int32), pairs, count)
        found = int(count[0])
        if found <= capacity:
            break
        capacity = found
    out = pairs[:found].astype(np.int64)
    return out[np.lexsort((out[:, 1], out[:, 0]))]
