"""Boundary groups: adjacent surface particles merged into groups of about n (BRIEF.md
step 3: the coarse boundary layer), by a greedy walk in one serial Taichi kernel.

The walk is sequential (each group takes the nearest particles still free), so numpy
cannot vectorise it, and in Python it costs ~5-10 us a particle (tens of milliseconds
for a ring). The adjacency it walks is built in numpy beforehand.
"""


import numpy as np

from ..runtime import ti
from .. import runtime


def surface_adjacency(owner: np.ndarray, faces: np.ndarray, count: int) :
    """CSR lists (offsets (count+1,) int32, indices int32) of the particles that share a
    boundary vertex with each particle (itself included), each row ascending. ``owner``
    (F,): the particle (0..count-1) of each boundary face, ``faces`` (F,3) its vertices."""
    owner = np.asarray(owner, dtype=np.int64)
    vertex = np.asarray(faces, dtype=np.int64).reshape(-1)
    # (vertex, particle) incidences, unique, sorted by vertex then particle.
    touch = np.unique(vertex * count + np.repeat(owner, 3))
    touch_vertex, touch_particle = np.divmod(touch, count)
    starts = np.flatnonzero(np.r_[True, touch_vertex[1:] != touch_vertex[:-1]])
    sizes = np.diff(np.r_[starts, len(touch)])
    # Every pair of particles at one vertex: entry i pairs with each entry of its vertex.
    per_entry = np.repeat(sizes, sizes)
    first = np.repeat(starts, sizes)
    ends = np.cumsum(per_entry)
    partner = np.repeat(first - (ends - per_entry), per_entry) + np.arange(ends[-1] if len(ends) else 0)
    pairs = np.unique(np.repeat(touch_particle, per_entry) * count + touch_particle[partner])
    row, column = np.divmod(pairs, count)
    offsets = np.zeros(count + 1, dtype=np.int32)
    np.cumsum(np.bincount(row, minlength=count), out=offsets[1:])
    return offsets, column.astype(np.int32)


@ti.kernel
def _greedy_groups(
    offsets: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (n+1,) adjacency CSR
    neighbors: ti.types.ndarray(dtype=ti.i32, ndim=1),  # adjacency, each row ascending
    position: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (n,3) [m]
    group_size: ti.i32,
    keep_leftovers: ti.i32,
    scratch: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (4,n): state (zeros: 1 visited, 2 taken),
    #   mark (-1: the last round that listed each), the breadth-first queue, candidates
    candidate_d2: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (n,) scratch [m^2]
    out: ti.types.ndarray(dtype=ti.i32, ndim=2),  # (3,n+1): members group after group, sizes,
    #   leftovers dropped; column n: how many of each
):
    ti.loop_config(serialize=True)
    for _ in range(1):
        n = position.shape[0]
        groups = 0
        written = 0
        dropped = 0
        round_id = 0
        for start in range(n):
            if scratch[0, start] & 1 == 0:
                scratch[0, start] |= 1
                scratch[2, 0] = start
                head = 0
                tail = 1
                while head < tail:
                    seed = scratch[2, head]
                    head += 1
                    for e in range(offsets[seed], offsets[seed + 1]):
                        m = neighbors[e]
                        if scratch[0, m] & 1 == 0:
                            scratch[0, m] |= 1
                            scratch[2, tail] = m
                            tail += 1
                    if scratch[0, seed] & 2 == 0:
                        scratch[0, seed] |= 2
                        first = written
                        out[0, written] = seed
                        written += 1
                        # The seed's own ring first, then (twice at most) the ring of every
                        # member so far; each round takes its free particles nearest the
                        # seed (ties: the lower index) until the group is full.
                        for widen in range(3):
                            if written - first < group_size:
                                round_id += 1
                                found = 0
                                sources = 1 if widen == 0 else written - first
                                for s in range(sources):
                                    src = out[0, first + s]
                                    for e in range(offsets[src], offsets[src + 1]):
                                        m = neighbors[e]
                                        if scratch[0, m] & 2 == 0 and scratch[1, m] != round_id:
                                            scratch[1, m] = round_id
                                            d = ti.Vector([position[m, 0] - position[seed, 0],
                                                           position[m, 1] - position[seed, 1],
                                                           position[m, 2] - position[seed, 2]])
                                            scratch[3, found] = m
                                            candidate_d2[found] = d.dot(d)
                                            found += 1
                                take = ti.min(group_size - (written - first), found)
                                for t in range(take):
                                    best = -1
                                    for c in range(found):
                                        if scratch[3, c] >= 0:
                                            if best < 0:
                                                best = c
                                            elif candidate_d2[c] < candidate_d2[best] or (
                                                    candidate_d2[c] == candidate_d2[best]
                                                    and scratch[3, c] < scratch[3, best]):
                                                best = c
                                    m = scratch[3, best]
                                    scratch[3, best] = -1
                                    scratch[0, m] |= 2
                                    out[0, written] = m
                                    written += 1
                        if written - first == 1 and keep_leftovers == 0:
                            out[2, dropped] = seed
                            dropped += 1
                            written = first
                        else:
                            out[1, groups] = written - first
                            groups += 1
        out[0, n] = written
        out[1, n] = groups
        out[2, n] = dropped


def group_surface_particles(
    positions: np.ndarray,
    surface: np.ndarray,
    face_tet: np.ndarray,
    faces: np.ndarray,
    group_size: int,
    keep_leftovers: bool = True,
):
    """Merge adjacent surface particles into groups of about ``group_size``.

    Two surface particles are adjacent when their tets share a boundary vertex. Seeds are
    taken in breadth-first order over that graph (so groups tile the surface without gaps);
    each seed takes its nearest still-free neighbours, widening to neighbours of the group
    when the seed's own ring runs out, until the group has ``group_size`` members. A group
    that ends with one member is a leftover: kept as its own boundary particle or dropped.
    Particles of separate bodies given together (``face_tet`` and ``faces`` with no vertex
    in common) are grouped as each body alone would be, one body after another.

    ``positions`` (T,3) [m] the particles, ``surface`` (S,) the surface particles among them
    (ascending), ``face_tet`` (F,) and ``faces`` (F,3) the boundary faces over those.
    Returns (members (M,) tet indices, group after group (the seed first, then in the order
    taken), sizes (G,), dropped (D,) tet indices), int64.
    """
    surface = np.asarray(surface, dtype=np.int64)
    count = len(surface)
    if group_size == 1 or count == 0:
        return surface.copy(), np.ones(count, dtype=np.int64), np.zeros(0, dtype=np.int64)
    local = np.full(int(surface.max()) + 1, -1, dtype=np.int64)
    local[surface] = np.arange(count)
    offsets, neighbors = surface_adjacency(local[face_tet], faces, count)
    runtime.init()
    # (Scratch and outputs packed into few arrays: each ndarray argument costs Python time
    # at every launch.)
    scratch = np.empty((4, count), dtype=np.int32)
    scratch[0] = 0
    scratch[1] = -1
    out = np.empty((3, count + 1), dtype=np.int32)
    _greedy_groups(offsets, neighbors, np.ascontiguousarray(positions[surface], dtype=np.float64), int(group_size),
                   int(bool(keep_leftovers)), scratch, np.empty(count), out)
    written, groups, leftovers = (int(c) for c in out[:, count])
    return surface[out[0, :written]], out[1, :groups].astype(np.int64), surface[out[2, :leftovers]]
