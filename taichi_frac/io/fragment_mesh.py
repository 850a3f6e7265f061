"""The render surface of a fragment: its boundary triangles, split into the original surface
(outer) and crack faces (inner)."""

from __future__ import annotations

import numpy as np

from ..model import BodyModel


def fragment_surface(model: BodyModel, root: BodyModel):
    """Surface of a fragment ``model`` cut from the solid ``root``.

    Returns (vertices (V,3) [m] = model.vertices, body frame; faces (F,3) = model.surface_faces,
    outward winding; face_is_inner (F,) bool). Vertices are the model's own (indices stay valid
    for per-vertex data the caller computes); the cache writer drops the unused interior ones.

    A boundary face of the fragment is a crack (inner) face iff the same face of the same root
    tet had a neighbour in the root solid: root.tet_neighbor[rt, k_root] != -1, with rt =
    model.source_tet[tet]. The local face index k is matched through the geometry rather than
    assumed equal: a fragment's tets are a translated copy of its root tets (body axes stay
    parallel to the source's), so the vertex opposite the face is found by comparing vertex
    offsets from the tet centroid. That keeps it right if a tet's vertices were reordered
    (e.g. re-oriented) when the fragment was built.
    """
    faces = np.asarray(model.surface_faces)
    face_tet = np.asarray(model.surface_face_tet, dtype=np.int64)
    local = np.asarray(model.surface_face_local, dtype=np.int64)
    root_tet = np.asarray(model.source_tet, dtype=np.int64)[face_tet]
    if len(face_tet) and (root_tet.min() < 0 or root_tet.max() >= root.tet_count):
        raise ValueError("model.source_tet indexes tets outside the root model")

    mine = model.vertices[model.tets[face_tet]]            # (F,4,3)
    theirs = root.vertices[root.tets[root_tet]]            # (F,4,3)
    mine = mine - mine.mean(axis=1, keepdims=True)
    theirs = theirs - theirs.mean(axis=1, keepdims=True)
    # Face k is the one opposite vertex k (geometry/topology.py TET_FACES).
    opposite = mine[np.arange(len(face_tet)), local]       # (F,3)
    distance = np.linalg.norm(theirs - opposite[:, None, :], axis=2)  # (F,4)
    root_local = np.argmin(distance, axis=1)
    size = np.linalg.norm(theirs, axis=2).max(axis=1)
    if np.any(distance[np.arange(len(face_tet)), root_local] > 1e-6 * np.maximum(size, 1e-300)):
        raise ValueError("fragment tets do not match their source tets in the root model")
    inner = root.tet_neighbor[root_tet, root_local] != -1
    return model.vertices, faces, inner
