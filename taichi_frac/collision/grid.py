"""Body-frame grids over each body's collision spheres, built once when the body is added.

A body's collision spheres never move in its own frame, so their grid is static: built in
numpy by :func:`body_grid` when the body enters the World and kept in the particle fields
(``Particles.grid_sphere`` / ``grid_slot``, ``Particles.cell_first``). A sphere of body a
looking for partners on a neighbouring body o is taken into o's frame (one rotation) and
reads the cells of o's grid within its reach; the narrowphase (``narrowphase.py``) does
this for each neighbour pair the broadphase (``broadphase.py``) lists.

What this replaced: one world-space hashed grid over the active spheres, rebuilt every
substep (count, prefix sum, scatter) with cells sized for the typical sphere plus the
farthest any neighbouring pair of bodies could close in the substep. One fast piece set the
cell size of the whole pile (44 mm cells where the typical reach was 30 mm on the 13
rings), every query read other bodies' and its own body's entries, and a sphere larger than
the cells needed a box of cells and a rule to make each pair in one of them only. Here a
query reads only the partner's spheres, within the reach of that one pair of bodies, and
nothing is rebuilt; it makes the same contacts as a world grid, pair for pair.

Layout of one body's grid (N spheres, particle slots [start, start + N)):
- the cell edge ``CELL_FACTOR`` x its median sphere radius x (1 + margin / 2), grown when
  the box would need more than 4 N - 1 cells (so the cell starts fit the body's share,
  ``cell_first[4 start .. 4 (start + N))``; a long thin body gets longer cells, never more
  memory);
- dims = ceil((highest centre - lowest centre) / edge) per axis, at least 1; a sphere is
  in the cell its centre falls in (clamped to the grid);
- cell c (x-major: (ix dims_y + iy) dims_z + iz) holds the entries
  ``cell_first[4 start + c] .. cell_first[4 start + c + 1]`` (absolute indices into
  ``grid_sphere`` / ``grid_slot``, which hold the body's spheres in cell order within its
  own slot range).
"""

from __future__ import annotations

import numpy as np

#: Cell edge in median sphere radii (times 1 + margin / 2): 3 was a little faster than 2 on
#: the 13-ring pile (fewer, larger cells: a query reads 8-27 of them either way).
CELL_FACTOR = 3.0

#: Cell starts per collision sphere a body may use (its grid has at most this many
#: minus one cells).
CELLS_PER_SPHERE = 4


def body_grid(offsets: np.ndarray, radii: np.ndarray, margin: float):
    """The static grid of one body's collision spheres (``offsets`` (N,3) [m], body frame;
    ``radii`` (N,) [m]) for a contact margin ``margin`` [sphere radii].

    Returns (origin (3,) [m], edge [m], dims (3,) int, first (cells + 1,) int: the
    body-relative start of each cell's entries, order (N,) int: the spheres in cell order
    (entry k holds sphere ``order[k]``)), with cells + 1 <= CELLS_PER_SPHERE x N."""
    offsets = np.asarray(offsets, dtype=np.float64)
    count = len(offsets)
    if count == 0:
        raise ValueError("a body grid needs at least one collision sphere")
    lower = offsets.min(axis=0)
    extent = offsets.max(axis=0) - lower
    edge = CELL_FACTOR * _median(radii) * (1.0 + 0.5 * margin)
    if not edge > 0.0:
        edge = max(float(extent.max()), 1e-6)
    limit = CELLS_PER_SPHERE * count - 1
    while True:
        dims = np.maximum(np.ceil(extent / edge).astype(np.int64), 1)
        if int(dims.prod()) <= limit:
            break
        # Grow the edge by at least the factor that would fit the volume, then check again
        # (the ceilings can need one more step).
        edge *= max(1.05, (float(dims.prod()) / limit) ** (1.0 / 3.0))
    index = np.minimum(np.floor((offsets - lower) / edge).astype(np.int64), dims - 1)
    cell = (index[:, 0] * dims[1] + index[:, 1]) * dims[2] + index[:, 2]
    order = np.argsort(cell, kind="stable")
    first = np.zeros(int(dims.prod()) + 1, dtype=np.int64)
    np.cumsum(np.bincount(cell, minlength=int(dims.prod())), out=first[1:])
    return lower, edge, dims, first, order


def _median(values: np.ndarray) -> float:
    """The median (the mean of the two middle values for an even count): np.percentile's
    argument handling costs more than the sort."""
    ordered = np.sort(values)
    n = len(ordered)
    return float(0.5 * (ordered[(n - 1) // 2] + ordered[n // 2]))
