"""Tets of a contoured solid from a cube lattice: a count set by the target, a time set by the
grid, and no mesher that can refuse.

The winding-number solid (``winding_solid``) is given as a signed field on a fine grid and as
its contour. :func:`lattice_tets` keeps every cube of a coarser lattice whose centre lies
inside the field or within :data:`CENTRE_REACH` cubes of it, splits each kept cube into the
six tets of its Kuhn (Freudenthal) subdivision about the main diagonal (the same diagonal in
every cube, so neighbouring cubes' tets share their faces), and moves each vertex on the tets'
boundary to the nearest point of the contour (the staircase alone would be off by up to half
a cube). The moves alternate with smoothing of the interior vertices, which makes room, for
:data:`SETTLE_ROUNDS` rounds; a move that would flatten or invert a tet is halved until none
does, then undone. Tets the moves leave flat (outer corners of cubes the contour only clips)
are dropped. Boundary vertices on the contour cut its convex parts short by their chords, so
the boundary is then fitted to the contour by least squares (:func:`_fit_boundary`, the fit
of ``simplify.fit_to_surface``), given the contour's volume back by a small uniform offset,
held inside the input's box and made to span it. A uniform offset alone gives the volume
back but leaves curved and thin parts in and pushes flat parts out (on a torus a fifth as
thick as it is wide: 4.6 % too thick).

The cube is calibrated so that the tet count lands on the target: 6 tets a cube gives a
first guess of (6 V / target)^(1/3), then the count corrects it by the cube root of the miss,
a few times (each try costs one interpolation of the field at the cube centres and one
round of moves). A part thinner than a cube can miss every cube centre: a cube that holds a
point of the contour but has no kept cube among the eight nearest to that point is kept too,
so the part stays one cube thick and the boundary moves give it its own thickness.

Accuracy at 5,000 particles on the 30 test meshes of ``bench meshes`` (each through this
path): volume within 0.3 % of the contour's (0.9 % on the scorpion), extents within 1.4 % of
the input's, 97.4-99.2 % of the input's winding-number solid inside the tets (98 % or more on
22), less where parts are only a few cubes thick (a scorpion's legs: 94.1 %; a sword's
blade: 95.3 %). Quality: interior tets are Kuhn tets (dihedral angles 45-90 degrees);
boundary tets are flattened by the moves (smallest angle about 2 degrees, 1-2 % of the tets
under 5 degrees).
"""

from __future__ import annotations

import itertools

import numpy as np
import trimesh

from .topology import signed_volumes

#: A cube is kept when its centre lies inside the solid or within this many cubes of it.
CENTRE_REACH = 0.2
#: Tries of the cube size calibration.
CALIBRATION_TRIES = 6
#: A tet whose volume falls under this fraction of a Kuhn tet's (cube^3 / 6) after the
#: boundary moves is nearly inverted: its vertices' moves are halved.
MIN_VOLUME_FRACTION = 1e-3
#: Tets left under this fraction of a Kuhn tet's volume by the moves are dropped (the outer
#: corners of cubes the contour only clips).
FLAT_FRACTION = 0.05
#: Halvings of the moves before the moves around a flattened tet are undone.
MOVE_HALVINGS = 6

# The six Kuhn tets of the unit cube: paths 000 -> 111 through one axis after another.
_KUHN = []
for order in itertools.permutations(range(3)):
    corner = np.zeros(3, dtype=np.int64)
    path = [corner.copy()]
    for axis in order:
        corner[axis] = 1
        path.append(corner.copy())
    _KUHN.append(np.array(path))
_KUHN = np.array(_KUHN)  # (6, 4, 3) corner offsets


def _field_at(values: np.ndarray, origin: np.ndarray, cell: float, points: np.ndarray) -> np.ndarray:
    from scipy.ndimage import map_coordinates

    coords = ((points - origin) / cell).T
    return map_coordinates(values, coords, order=1, mode="nearest")


def _kept_cubes(values, origin, cell, lo, hi, cube, contour_points):
    """Boolean (nx,ny,nz) of the lattice of ``cube`` over [lo, hi], and the lattice origin."""
    shape = np.maximum(np.ceil((hi - lo) / cube).astype(np.int64) + 2, 1)
    start = lo - 0.5 * (shape * cube - (hi - lo))
    axes = [start[k] + cube * (np.arange(shape[k]) + 0.5) for k in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    kept = (_field_at(values, origin, cell, centres) > -CENTRE_REACH * cube).reshape(tuple(shape))
    # Thin parts: a contour point whose eight nearest cube centres are all out keeps the
    # cube it lies in.
    position = (contour_points - start) / cube - 0.5
    base = np.clip(np.floor(position).astype(np.int64), 0, shape - 2)
    covered = np.zeros(len(contour_points), dtype=bool)
    for offset in itertools.product((0, 1), repeat=3):
        k = base + np.array(offset)
        covered |= kept[k[:, 0], k[:, 1], k[:, 2]]
    if not covered.all():
        own = np.clip(np.floor((contour_points[~covered] - start) / cube).astype(np.int64), 0, shape - 1)
        kept[own[:, 0], own[:, 1], own[:, 2]] = True
    return kept, start


def _tets_of(kept: np.ndarray, start: np.ndarray, cube: float):
    """Vertices (V,3) [m] and tets (T,4) of the Kuhn subdivision of the kept cubes."""
    cells = np.argwhere(kept)
    corners = cells[:, None, None, :] + _KUHN[None]  # (C, 6, 4, 3)
    node_shape = np.array(kept.shape) + 1
    flat = np.ravel_multi_index(corners.reshape(-1, 3).T, tuple(node_shape))
    used, inverse = np.unique(flat, return_inverse=True)
    vertices = start + cube * np.stack(np.unravel_index(used, tuple(node_shape)), axis=1).astype(np.float64)
    return vertices, inverse.reshape(-1, 4).astype(np.int64)


def _largest_parts(vertices, tets, fraction: float = 0.002):
    """The tets of connected parts (tets sharing a vertex) holding at least ``fraction`` of
    them: a speck of a few cubes would be a body of its own."""
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csgraph

    n = len(vertices)
    rows = np.repeat(np.arange(len(tets)), 4)
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, tets.reshape(-1))), shape=(len(tets), n)).tocsr()
    count, label = csgraph.connected_components(sp.bmat([[None, graph], [graph.T, None]]), directed=False)
    label = label[:len(tets)]
    sizes = np.bincount(label, minlength=count)
    return tets[sizes[label] >= fraction * len(tets)]


def _snap(vertices, tets, contour: trimesh.Trimesh, cube: float, lattice=None):
    """Boundary vertices moved onto ``contour`` (at most one cube from their ``lattice``
    places), no tet flattened."""
    import igl

    from .topology import boundary_faces

    faces = boundary_faces(tets)[0]
    boundary = np.unique(faces)
    _, _, nearest = igl.point_mesh_squared_distance(np.ascontiguousarray(vertices[boundary]),
                                                    np.ascontiguousarray(contour.vertices, dtype=np.float64),
                                                    np.ascontiguousarray(contour.faces, dtype=np.int64))
    move = np.asarray(nearest) - vertices[boundary]
    if lattice is not None:
        reach = np.asarray(nearest) - lattice[boundary]
        length = np.linalg.norm(reach, axis=1, keepdims=True)
        move = reach * np.minimum(1.0, cube / np.maximum(length, 1e-300)) + lattice[boundary] - vertices[boundary]
    return _move_guarded(vertices, tets, boundary, move, MIN_VOLUME_FRACTION * cube**3 / 6.0)


#: Rounds of boundary moves and interior smoothing: the interior vertices make room, so the
#: next round's moves flatten fewer tets and go further.
SETTLE_ROUNDS = 4


def _settle(vertices, tets, contour, cube):
    """Boundary vertices onto ``contour`` (:func:`_snap`), interior vertices halfway to their
    neighbours' mean (a move that would flatten a tet undone), :data:`SETTLE_ROUNDS` times."""
    import scipy.sparse as sp

    from .topology import boundary_faces

    boundary = np.zeros(len(vertices), dtype=bool)
    boundary[np.unique(boundary_faces(tets)[0])] = True
    pairs = np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(4) if a != b])
    adjacency = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(vertices),) * 2)
    adjacency.data[:] = 1.0
    degree = np.maximum(np.asarray(adjacency.sum(axis=1)).ravel(), 1.0)[:, None]
    floor = MIN_VOLUME_FRACTION * cube**3 / 6.0
    lattice = vertices
    for _ in range(SETTLE_ROUNDS):
        vertices = _snap(vertices, tets, contour, cube, lattice)
        smoothed = vertices.copy()
        inner = ~boundary
        smoothed[inner] = 0.5 * (vertices[inner] + (adjacency @ vertices)[inner] / degree[inner])
        flat = signed_volumes(smoothed, tets) < floor
        if flat.any():
            undo = np.unique(tets[flat])
            smoothed[undo] = vertices[undo]
        vertices = smoothed
    return vertices


def _build(values, origin, cell, contour, cube):
    """(vertices, tets) of one cube size: kept cubes, Kuhn tets, moved onto the contour, the
    tets the moves flattened dropped."""
    from .topology import compact_vertices, orient_tets

    lo, hi = contour.bounds
    kept, start = _kept_cubes(values, origin, cell, lo, hi, cube, np.asarray(contour.vertices, dtype=np.float64))
    vertices, tets = _tets_of(kept, start, cube)
    tets = _largest_parts(vertices, tets)
    vertices, tets, _ = compact_vertices(vertices, tets)
    tets = orient_tets(vertices, tets)
    vertices = _settle(vertices, tets, contour, cube)
    # A cube mostly outside the solid has its outer vertices pulled onto the contour: its
    # tets there are flat and hold no volume, so they go.
    tets = tets[signed_volumes(vertices, tets) >= FLAT_FRACTION * cube**3 / 6.0]
    vertices, tets, _ = compact_vertices(vertices, tets)
    return vertices, np.asarray(tets, dtype=np.int64)


def _move_guarded(vertices, tets, at, move, floor):
    """``vertices`` with the vertices ``at`` moved by ``move`` (len(at),3), each move halved
    (:data:`MOVE_HALVINGS` times, then undone) while a tet it touches would fall under
    ``floor`` [m^3] of volume."""
    position = np.full(len(vertices), -1, dtype=np.int64)
    position[at] = np.arange(len(at))
    scale = np.ones(len(at))
    moved = vertices.copy()
    for halving in range(MOVE_HALVINGS + 1):
        moved[at] = vertices[at] + scale[:, None] * move
        flat = signed_volumes(moved, tets) < floor
        if not flat.any():
            return moved
        hit = position[np.unique(tets[flat])]
        hit = hit[hit >= 0]
        scale[hit] = 0.0 if halving == MOVE_HALVINGS - 1 else 0.5 * scale[hit]
    moved[at] = vertices[at] + scale[:, None] * move
    return moved


#: Rounds of the least-squares fit of the tets' boundary to the contour (:func:`_fit_boundary`).
FIT_ROUNDS = 4


def _fit_boundary(vertices, tets, contour: trimesh.Trimesh, cube: float, bounds):
    """The boundary vertices moved to the least-squares fit of ``contour`` (the pull of
    ``simplify.fit_to_surface``: vertices on the contour cut convex parts short by their
    chords), given the contour's volume back by a small uniform offset, held inside
    ``bounds`` ((2,3) [m], the input's box) and, on each side of it, the boundary vertex
    nearest the contour's outermost point (within a cube) moved onto it, so the extents are
    the contour's; no tet is flattened (:func:`_move_guarded`)."""
    from .simplify import FIT_SAMPLES_PER_FACE, _pull, surface_samples
    from .topology import boundary_faces

    faces = boundary_faces(tets)[0]
    at = np.unique(faces)
    lo, hi = np.asarray(bounds, dtype=np.float64)
    floor = MIN_VOLUME_FRACTION * cube**3 / 6.0
    samples = surface_samples(contour, max(20_000, FIT_SAMPLES_PER_FACE * len(faces)))
    for _ in range(FIT_ROUNDS):
        move, _, _ = _pull(vertices, faces, samples, 2.0 * cube)
        target = np.clip(vertices[at] + move[at], lo, hi)
        vertices = _move_guarded(vertices, tets, at, target - vertices[at], floor)
    surface = trimesh.Trimesh(vertices, faces, process=False)
    offset = (float(contour.volume) - float(signed_volumes(vertices, tets).sum())) / max(float(surface.area), 1e-300)
    target = np.clip(vertices[at] + offset * surface.vertex_normals[at], lo, hi)
    vertices = _move_guarded(vertices, tets, at, target - vertices[at], floor)
    ends = np.asarray(contour.vertices, dtype=np.float64)
    ends = np.clip(ends[np.concatenate([ends.argmin(axis=0), ends.argmax(axis=0)])], lo, hi)
    for end in ends:
        nearest = at[np.argmin(np.linalg.norm(vertices[at] - end, axis=1))]
        if np.linalg.norm(vertices[nearest] - end) <= cube:
            vertices = _move_guarded(vertices, tets, np.array([nearest]), (end - vertices[nearest])[None], floor)
    return vertices


def lattice_tets(values: np.ndarray, origin: np.ndarray, cell: float, contour: trimesh.Trimesh, target: int,
                 bounds=None):
    """Tets of the solid {``values`` > 0} (a field on the grid of ``cell`` [m] from
    ``origin`` (3,) [m]) whose boundary is ``contour``, about ``target`` of them, their
    boundary fitted to the contour inside ``bounds`` ((2,3) [m]: the input's box; default the
    contour's).

    Returns (vertices (V,3) [m], tets (T,4) int64, positively oriented, cube [m])."""
    cube = (6.0 * float(contour.volume) / target) ** (1.0 / 3.0)
    best = None
    for _ in range(CALIBRATION_TRIES):
        vertices, tets = _build(values, origin, cell, contour, cube)
        count = len(tets)
        if count and (best is None or abs(count / target - 1) < abs(len(best[1]) / target - 1)):
            best = (vertices, tets, cube)
        if count and abs(count / target - 1) < 0.03:
            break
        cube *= (max(count, 1) / target) ** (1.0 / 3.0)
    if best is None:
        return None
    vertices, tets, cube = best
    return _fit_boundary(vertices, tets, contour, cube, contour.bounds if bounds is None else bounds), tets, cube
