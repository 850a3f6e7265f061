"""Checks a surface mesh must pass before any meshing work (the issue's bad-input list).

Each failure raises :class:`MeshError` whose message names the file, the problem, the
numbers and what to do, e.g. ``'teapot.obj' is not closed: 4 boundary loops, 52 open
edges``. Checks run cheapest first; the first failing one is reported.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import trimesh

REPAIR_HINT = "pass repair=True (CLI: --repair) to try an automatic fix, or fix it in a modelling tool"


class MeshError(ValueError):
    """A mesh that cannot be simulated as it is. The message says which file, what is wrong
    (with counts) and what to do."""


def _edges(faces: np.ndarray):
    """Unique undirected edges (E,2) and how many faces use each (E,). Edges are packed into
    one int64 each, so that a million faces take a 1-D sort instead of a row sort."""
    e = np.sort(np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    base = int(e.max()) + 1 if len(e) else 1
    unique, counts = np.unique(e[:, 0] * base + e[:, 1], return_counts=True)
    return np.stack([unique // base, unique % base], axis=1), counts


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
    f = mesh.faces
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    scale = float(np.linalg.norm(mesh.extents)) if len(mesh.vertices) else 1.0
    tiny = mesh.area_faces <= 1e-12 * scale**2
    return np.nonzero(repeated | tiny)[0]


def shell_labels(faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Shells of a face set: faces joined across edges that exactly two faces share. A
    non-manifold edge (a fin on a box, parts glued along an edge) separates shells, so
    each can be closed on its own. Returns (count, label (F,) int)."""
    faces = np.asarray(faces, dtype=np.int64)
    count = len(faces)
    if count == 0:
        return 0, np.zeros(0, dtype=np.int64)
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    base = int(e.max()) + 1
    _, edge_id, uses = np.unique(e[:, 0] * base + e[:, 1], return_inverse=True, return_counts=True)
    owner = np.repeat(np.arange(count), 3)
    manifold = uses[edge_id] == 2
    order = np.argsort(edge_id[manifold], kind="stable")
    pairs = owner[manifold][order].reshape(-1, 2)  # the two faces of each manifold edge
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
    bad = degenerate_faces(mesh)
    if len(bad):
        raise MeshError(f"{label} has {len(bad)} degenerate faces (zero area or a repeated vertex) out of "
                        f"{len(mesh.faces)}, e.g. face {int(bad[0])}; {REPAIR_HINT}")
    edges, counts = _edges(mesh.faces)
    open_edges = edges[counts == 1]
    nonmanifold = int(np.sum(counts > 2))
    if len(open_edges):
        loops = count_loops(open_edges)
        raise MeshError(f"{label} is not closed: {loops} boundary loop{'' if loops == 1 else 's'}, {len(open_edges)} "
                        f"open edges; a breakable solid needs a watertight surface: {REPAIR_HINT}")
    if nonmanifold:
        raise MeshError(f"{label} is not manifold: {nonmanifold} edges are shared by more than two faces; "
                        f"{REPAIR_HINT}")
    # Closed and manifold: consistent winding means every directed edge is used once (a
    # flipped face traverses an edge in the same direction as its neighbour).
    directed = np.asarray(mesh.faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, dcounts = np.unique(directed[:, 0] * (int(directed.max()) + 1) + directed[:, 1], return_counts=True)
    if np.any(dcounts > 1):
        raise MeshError(f"{label} has inconsistent winding: {int(np.sum(dcounts > 1))} edges are traversed in "
                        "the same direction by both of their faces (some faces are flipped); "
                        f"{REPAIR_HINT} (trimesh.repair.fix_winding also fixes this)")
    if check_self_intersection:
        hits = self_intersections(mesh.vertices, mesh.faces)
        if len(hits):
            n_faces = len(np.unique(hits))
            raise MeshError(f"{label} self-intersects: {len(hits)} crossing face pairs ({n_faces} faces), e.g. "
                            f"faces {int(hits[0, 0])} and {int(hits[0, 1])}; {REPAIR_HINT}")
    shells, shell_of_face = shell_labels(mesh.faces)
    if shells > 1 and not allow_multiple_shells:
        parts = sorted(np.bincount(shell_of_face).tolist(), reverse=True)
        raise MeshError(f"{label} has {shells} disconnected shells (faces per shell: "
                        f"{', '.join(map(str, parts[:8]))}{', ...' if len(parts) > 8 else ''}); "
                        "make one scene object per shell, or pass repair=True to unite overlapping shells")
    volume = float(mesh.volume)
    if volume <= 0:
        raise MeshError(f"{label} is inverted: enclosed volume {volume:.6g} m^3 is negative (normals point "
                        "inward); flip the faces (trimesh: mesh.invert()) or pass repair=True")
