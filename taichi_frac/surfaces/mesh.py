"""The render surface of a fragment: its boundary triangles, split into the original surface
(outer) and crack faces (inner)."""

from __future__ import annotations

import numpy as np

from ..model import BodyModel


def fragment_surface(model: BodyModel, root: BodyModel, root_faces=None):
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
    (e.g. re-oriented) when the fragment was built. ``root_faces``: ``root_faces_of(model,
    root)`` when the caller has it already.
    """
    root_tet, root_local = root_faces_of(model, root) if root_faces is None else root_faces
    inner = root.tet_neighbor[root_tet, root_local] != -1
    return model.vertices, np.asarray(model.surface_faces), inner


def root_faces_of(model: BodyModel, root: BodyModel):
    """For each boundary face of ``model``: (root tet (F,), local face index in that root
    tet (F,)), matched through the geometry (see fragment_surface)."""
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
    return root_tet, root_local


def surface_corner_attributes(model: BodyModel, root: BodyModel, root_normals, root_uvs=None, root_faces=None):
    """Per-corner normals (F,3,3) and UVs (F,3,2) or None for ``model``'s boundary faces,
    taken from the root's boundary faces (``root_normals`` (Fr,3,3), ``root_uvs``
    (Fr,3,2) aligned with ``root.surface_faces``). Crack faces have no root counterpart
    and get NaN (the cache writer then uses their flat face normal). ``root_faces``: as in
    ``fragment_surface``."""
    root_tet, root_local = root_faces_of(model, root) if root_faces is None else root_faces
    lookup = np.full(root.tet_count * 4, -1, dtype=np.int64)
    lookup[np.asarray(root.surface_face_tet, np.int64) * 4 + np.asarray(root.surface_face_local, np.int64)] = \
        np.arange(len(root.surface_faces))
    root_face = lookup[root_tet * 4 + root_local]
    outer = root_face >= 0
    # Match corners by position relative to the face centroid (the frames differ by a shift).
    mine = model.vertices[np.asarray(model.surface_faces)[outer]]
    theirs = root.vertices[np.asarray(root.surface_faces)[root_face[outer]]]
    mine = mine - mine.mean(axis=1, keepdims=True)
    theirs = theirs - theirs.mean(axis=1, keepdims=True)
    order = np.argmin(np.linalg.norm(mine[:, :, None, :] - theirs[:, None, :, :], axis=3), axis=2)  # (Fo,3)
    rows = root_face[outer][:, None]
    normals = np.full((len(root_face), 3, 3), np.nan)
    normals[outer] = np.asarray(root_normals)[rows, order]
    uvs = None
    if root_uvs is not None:
        uvs = np.full((len(root_face), 3, 2), np.nan)
        uvs[outer] = np.asarray(root_uvs)[rows, order]
    return normals, uvs


def render_surface(render, model: BodyModel, tet_peak_stress=None):
    """A piece's cut render solid (surfaces/cut.py) as the cache writer takes it.

    Returns (vertices (V,3) [m] body frame, faces (F,3) outward, face_is_inner (F,) bool,
    normals (F,3,3), uvs (F,3,2), face_peak_stress (F,) [Pa] or None). A face's peak stress
    is that of the piece's tet nearest its centroid (``tet_peak_stress`` (T,) [Pa]), as the
    tets' own boundary faces carry their tet's.
    """
    from scipy.spatial import cKDTree

    from .cut import piece_mesh

    mesh = piece_mesh(render)
    face_peak = None
    if tet_peak_stress is not None:
        _, nearest = cKDTree(model.particle_position).query(mesh.vertices[mesh.faces].mean(axis=1))
        face_peak = np.asarray(tet_peak_stress, dtype=np.float64)[nearest]
    return mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.normals, mesh.uvs, face_peak
