"""Checks a surface mesh must pass before any meshing work.

Each failure raises :class:`MeshError` whose message names the file, the problem, the
numbers and what to do, e.g. ``'teapot.obj' is not closed: 4 boundary loops, 52 open
edges``. Checks run cheapest first; the first failing one is reported.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import trimesh

#: The fix a MeshError offers, worded for ``prepare_body`` and ``taichi-frac info``; a scene
#: swaps it for its own (``scene_setup.prepare_objects``).
REPAIR_HINT = "pass repair=True (CLI: --repair) to try an automatic fix, or fix it in a modelling tool"


class MeshError(ValueError):
    """A mesh that cannot be simulated as it is. The message says which file, what is wrong
    (with counts) and what to do."""


class _HalfEdges:
    """The 3F half-edges of a face set grouped by undirected edge with one 1-D sort (no
    Python loop, no row-wise ``np.unique``): the undirected key (lo * base + hi) and the
    half-edge index are packed into one int64 where they fit, so a plain ``np.sort``
    replaces an argsort. ``order``: half-edge indices (face = index // 3) by edge;
    ``start``/``counts``: each undirected edge's first position in ``order`` and its uses."""

    def __init__(self, faces: np.ndarray):
        faces = np.asarray(faces, dtype=np.int64)
        self.directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        lo = np.minimum(self.directed[:, 0], self.directed[:, 1])
        hi = np.maximum(self.directed[:, 0], self.directed[:, 1])
        n = len(lo)
        self.base = int(hi.max()) + 1 if n else 1
        key = lo * self.base + hi
        shift = max(int(n - 1).bit_length(), 1)
        if n and int(key.max()) < (1 << (62 - shift)):
            packed = np.sort((key << shift) | np.arange(n, dtype=np.int64))
            self.order = packed & ((1 << shift) - 1)
            skey = packed >> shift
        else:
            self.order = np.argsort(key, kind="stable")
            skey = key[self.order]
        boundary = np.empty(n, dtype=bool)
        boundary[:1] = True
        np.not_equal(skey[1:], skey[:-1], out=boundary[1:])
        self.start = np.flatnonzero(boundary)
        self.counts = np.diff(np.append(self.start, n))
        self.keys = skey[self.start]

    def edges(self, which=None) -> np.ndarray:
        keys = self.keys if which is None else self.keys[which]
        return np.stack([keys // self.base, keys % self.base], axis=1)

    def face_pairs(self) -> np.ndarray:
        """(M,2) the two faces of each edge that exactly two faces use."""
        first = self.start[self.counts == 2]
        return np.stack([self.order[first] // 3, self.order[first + 1] // 3], axis=1)

    def same_direction(self) -> int:
        """Edges of two uses that both faces run the same way (inconsistent winding)."""
        first = self.start[self.counts == 2]
        forward = self.directed[:, 0] < self.directed[:, 1]
        return int(np.sum(forward[self.order[first]] == forward[self.order[first + 1]]))


def _edges(faces: np.ndarray):
    """Unique undirected edges (E,2) and how many faces use each (E,)."""
    half = _HalfEdges(faces)
    return half.edges(), half.counts


def count_loops(edges: np.ndarray) -> int:
    """Connected components of a set of edges (E,2): the number of boundary loops."""
    if len(edges) == 0:
        return 0
    verts, inv = np.unique(edges, return_inverse=True)
    inv = inv.reshape(-1, 2)
    g = sp.coo_matrix((np.ones(len(inv)), (inv[:, 0], inv[:, 1])), shape=(len(verts), len(verts)))
    return int(csgraph.connected_components(g, directed=False)[0])


def degenerate_faces(mesh: trimesh.Trimesh) -> np.ndarray:
    """Indices of faces with (near) zero area: below 1e-12 of the bounding-box diagonal squared,
    or with a repeated vertex index."""
    return _degenerate_and_volume(mesh)[0]


def _degenerate_and_volume(mesh: trimesh.Trimesh):
    """(degenerate face indices, enclosed volume) from one pass over the corners: twice a
    face's area is |(b - a) x (c - a)| and its signed volume a . ((b - a) x (c - a)) / 6."""
    f = np.asarray(mesh.faces, dtype=np.int64)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    scale = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) if len(v) else 1.0
    a = v[f[:, 0]]
    e1 = v[f[:, 1]] - a
    e2 = v[f[:, 2]] - a
    n = np.empty_like(a)
    n[:, 0] = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    n[:, 1] = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    n[:, 2] = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    area = 0.5 * np.sqrt(np.einsum("ij,ij->i", n, n))
    volume = float(np.einsum("ij,ij->", a, n)) / 6.0
    return np.nonzero(repeated | (area <= 1e-12 * scale**2))[0], volume


def shell_labels(faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Shells of a face set: faces joined across edges that exactly two faces share. A
    non-manifold edge (a fin on a box, parts glued along an edge) separates shells, so
    each can be closed on its own. Returns (count, label (F,) int)."""
    return _shell_labels(len(faces), _HalfEdges(faces) if len(faces) else None)


def _shell_labels(count: int, half) -> tuple[int, np.ndarray]:
    if count == 0:
        return 0, np.zeros(0, dtype=np.int64)
    pairs = half.face_pairs()  # the two faces of each manifold edge
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    n, label = csgraph.connected_components(graph, directed=False)
    return int(n), label


def self_intersections(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Pairs (K,2) of faces that cross each other (an edge of one passes through the other),
    i < j. Faces sharing a vertex are skipped and coplanar overlaps are not detected; any
    size is checked, in linear time (``intersections.crossing_face_pairs``: a hierarchical
    grid broad phase and float64 segment-triangle tests in one Taichi kernel)."""
    from .intersections import crossing_face_pairs

    return crossing_face_pairs(vertices, faces)


def volume_free(mesh: trimesh.Trimesh) -> bool:
    """Whether ``mesh`` is flat (one plane) or its generalized winding number reaches 1/2
    nowhere on a coarse grid: a sheet that encloses nothing."""
    from .winding_solid import estimate_volume, is_flat, usable_faces

    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = usable_faces(vertices, mesh.faces)
    return is_flat(vertices, faces) or estimate_volume(vertices, faces) <= 0


def validate_surface(mesh: trimesh.Trimesh, name: str = "mesh", *, allow_multiple_shells: bool = False,
                     check_self_intersection: bool = True) -> None:
    """Raise :class:`MeshError` unless ``mesh`` is a closed, consistently wound, outward
    oriented, non-self-intersecting single solid without degenerate faces.

    ``name`` is what the messages call the mesh (usually the file name).
    """
    label = repr(name)
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise MeshError(f"{label} is empty: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces; "
                        "check the file exports geometry (not only a camera, light or point cloud)")
    bad, volume = _degenerate_and_volume(mesh)
    if len(bad):
        raise MeshError(f"{label} has {len(bad)} degenerate faces (zero area or a repeated vertex) out of "
                        f"{len(mesh.faces)}, e.g. face {int(bad[0])}; {REPAIR_HINT}")
    half = _HalfEdges(mesh.faces)
    counts = half.counts
    open_edges = half.edges(counts == 1)
    nonmanifold = int(np.sum(counts > 2))
    if len(open_edges):
        loops = count_loops(open_edges)
        if volume_free(mesh):
            raise MeshError(f"{label} has no volume: it is an open sheet ({loops} boundary loop{'' if loops == 1 else 's'}, "
                            f"flat or enclosing nothing); give the object a thickness in metres (thickness = 0.005 "
                            "makes a 5 mm shell about it), or model it as a closed solid")
        raise MeshError(f"{label} is not closed: {loops} boundary loop{'' if loops == 1 else 's'}, {len(open_edges)} "
                        f"open edges; a breakable solid needs a watertight surface: {REPAIR_HINT}; a sheet "
                        "(a pane, a sign, a leaf) needs a thickness in metres instead")
    if nonmanifold:
        raise MeshError(f"{label} is not manifold: {nonmanifold} edges are shared by more than two faces; "
                        f"{REPAIR_HINT}")
    # Closed and manifold: consistent winding means every directed edge is used once (a
    # flipped face traverses an edge in the same direction as its neighbour).
    flipped = half.same_direction()
    if flipped:
        raise MeshError(f"{label} has inconsistent winding: {flipped} edges are traversed in "
                        "the same direction by both of their faces (some faces are flipped); "
                        f"{REPAIR_HINT} (trimesh.repair.fix_winding also fixes this)")
    if check_self_intersection:
        hits = self_intersections(mesh.vertices, mesh.faces)
        if len(hits):
            n_faces = len(np.unique(hits))
            raise MeshError(f"{label} self-intersects: {len(hits)} crossing face pairs ({n_faces} faces), e.g. "
                            f"faces {int(hits[0, 0])} and {int(hits[0, 1])}; {REPAIR_HINT}")
    shells, shell_of_face = _shell_labels(len(mesh.faces), half)
    if shells > 1 and not allow_multiple_shells:
        parts = sorted(np.bincount(shell_of_face).tolist(), reverse=True)
        raise MeshError(f"{label} has {shells} disconnected shells (faces per shell: "
                        f"{', '.join(map(str, parts[:8]))}{', ...' if len(parts) > 8 else ''}); "
                        "make one scene object per shell, or pass repair=True to unite overlapping shells")
    if volume <= 0:
        raise MeshError(f"{label} is inverted: enclosed volume {volume:.6g} m^3 is negative (normals point "
                        "inward); flip the faces (trimesh: mesh.invert()) or pass repair=True")
