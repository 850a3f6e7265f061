"""Tetrahedral mesh topology: faces, face adjacency (bonds), boundary faces.

Convention: face k of tet (v0, v1, v2, v3) is the face opposite vertex k, wound so its
normal points out of a positively oriented tet (det[v1-v0, v2-v0, v3-v0] > 0).
"""

from __future__ import annotations

import numpy as np

# Local vertex indices of face k (opposite vertex k), outward winding.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


def signed_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed tet volumes (T,) [m^3]; positive for the outward-face convention above."""
    p = vertices[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


def orient_tets(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Return tets with vertices 1 and 2 swapped where the volume is negative."""
    tets = np.array(tets, dtype=np.int32, copy=True)
    neg = signed_volumes(vertices, tets) < 0
    tets[neg, 1], tets[neg, 2] = tets[neg, 2].copy(), tets[neg, 1].copy()
    return tets


def tet_neighbors(tets: np.ndarray) -> np.ndarray:
    """Tet across each face: (T, 4) int32, -1 where face k lies on the boundary.

    Raises ValueError if a face is shared by more than two tets (a non-manifold tet mesh).
    """
    tets = np.asarray(tets)
    t_count = len(tets)
    faces = np.sort(tets[:, TET_FACES].reshape(-1, 3), axis=1)  # (4T, 3), row = 4*t + k
    order = np.lexsort((faces[:, 2], faces[:, 1], faces[:, 0]))
    sorted_faces = faces[order]
    same = np.all(sorted_faces[1:] == sorted_faces[:-1], axis=1)
    if np.any(same[1:] & same[:-1]):
        raise ValueError("tet mesh is not manifold: a face is shared by more than two tets")
    neighbor = np.full(4 * t_count, -1, dtype=np.int64)
    a = order[:-1][same]
    b = order[1:][same]
    neighbor[a] = b // 4
    neighbor[b] = a // 4
    return neighbor.reshape(t_count, 4).astype(np.int32)


def bonds_from_neighbors(neighbor: np.ndarray) -> np.ndarray:
    """Unique face-sharing tet pairs (B, 2) int32 with i < j, sorted."""
    t_index = np.repeat(np.arange(len(neighbor)), 4)
    j = neighbor.reshape(-1)
    keep = j > t_index
    return np.stack([t_index[keep], j[keep]], axis=1).astype(np.int32)


def boundary_faces(tets: np.ndarray, neighbor: np.ndarray | None = None):
    """Boundary triangles of a tet set.

    Returns (faces (F,3) int32 vertex indices, outward winding; owner (F,) int32 tet index;
    local (F,) int8 local face index k). A face is on the boundary when no tet of this set
    lies across it: for a fragment, its crack faces are boundary faces too.
    """
    if neighbor is None:
        neighbor = tet_neighbors(tets)
    owner, local = np.nonzero(neighbor < 0)
    faces = np.asarray(tets)[owner[:, None], TET_FACES[local]]
    return faces.astype(np.int32), owner.astype(np.int32), local.astype(np.int8)


def compact_vertices(vertices: np.ndarray, tets: np.ndarray):
    """Drop unused vertices. Returns (vertices (V',3), tets re-indexed, used vertex ids (V',))."""
    used = np.unique(tets)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[tets].astype(np.int32), used.astype(np.int32)


def dihedral_angles_deg(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles of each tet (T, 6) in degrees."""
    p = vertices[tets]
    # Outward face normals, face k opposite vertex k.
    n = np.empty((len(tets), 4, 3))
    for k, (a, b, c) in enumerate(TET_FACES):
        n[:, k] = np.cross(p[:, b] - p[:, a], p[:, c] - p[:, a])
    n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-300)
    out = np.empty((len(tets), 6))
    for e, (i, j) in enumerate([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]):
        # Interior dihedral angle between faces i and j = pi - angle between outward normals.
        cosang = np.clip(-np.einsum("ij,ij->i", n[:, i], n[:, j]), -1.0, 1.0)
        out[:, e] = np.degrees(np.arccos(cosang))
    return out
