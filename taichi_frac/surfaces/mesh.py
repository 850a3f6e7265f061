"""The render surface of a fragment: its boundary triangles, split into the original surface
(outer) and crack faces (inner), from its tets (``fragment_surface``) or its render solid
(``piece_mesh``)."""

from __future__ import annotations

import numpy as np

from ..model import BodyModel
from .layout import CRACK, HULL_FACE, NORMAL, UV
from .solid import SPHERE_SAGITTA_FACTOR, PieceMesh, RenderSolid, tangent_frame


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

    mesh = piece_mesh(render)
    face_peak = None
    if tet_peak_stress is not None:
        _, nearest = cKDTree(model.particle_position).query(mesh.vertices[mesh.faces].mean(axis=1))
        face_peak = np.asarray(tet_peak_stress, dtype=np.float64)[nearest]
    return mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.normals, mesh.uvs, face_peak


def _face_cracks(corner_crack: np.ndarray, triangles: np.ndarray, cracks, spacing: float) -> np.ndarray:
    """(F,) each face's crack index from its corners' (F,3): the one they share, else (a face
    the booleans gave corners of two origins) the crack whose surface all three corners lie on
    (within SPHERE_SAGITTA_FACTOR spacings), else the artist's surface (-1), or a hull's."""
    crack = corner_crack[:, 0].copy()
    mixed = np.nonzero((corner_crack != corner_crack[:, :1]).any(axis=1))[0]
    for f in mixed:
        crack[f] = HULL_FACE if (corner_crack[f] == HULL_FACE).any() else -1
        for index in np.unique(corner_crack[f][corner_crack[f] >= 0]):
            if np.all(np.abs(cracks[index].distance(triangles[f])) <= SPHERE_SAGITTA_FACTOR * spacing):
                crack[f] = index
                break
    return crack


def _outer_uvs(uvs: np.ndarray, triangles: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """``uvs`` (F,3,2) with each NaN corner of an ``outer`` face given the UV of the nearest
    outer corner that has one (``triangles`` (F,3,3) [m] the corners): the booleans
    interpolate a sliver's properties over its zero area as NaN (slivers of 1e-15 m^2
    where a slab grazes the surface)."""
    uvs = uvs.copy()
    lost = outer[:, None] & np.isnan(uvs).any(axis=2)
    known = outer[:, None] & ~np.isnan(uvs).any(axis=2)
    if lost.any() and known.any():
        from scipy.spatial import cKDTree

        nearest = cKDTree(triangles[known]).query(triangles[lost])[1]
        uvs[lost] = uvs[known][nearest]
    return uvs


def piece_mesh(render: RenderSolid) -> PieceMesh:
    """The render solid as a triangle mesh with per-corner shading (see PieceMesh)."""
    mesh = render.solid.to_mesh64()
    props = np.asarray(mesh.vert_properties, dtype=np.float64)
    tri_verts = np.asarray(mesh.tri_verts, dtype=np.int64)
    # One vertex per topological vertex: property vertices repeat one across UV and normal
    # seams (the merge vectors say which), while two vertices the solid pinches together at
    # one position stay two, so the mesh stays manifold.
    topological = np.arange(len(props))
    topological[np.asarray(mesh.merge_from_vert, dtype=np.int64)] = np.asarray(mesh.merge_to_vert, dtype=np.int64)
    used, vertex_of = np.unique(topological, return_inverse=True)
    positions = props[used, :3]
    faces = vertex_of.reshape(-1)[tri_verts]
    corner = props[tri_verts]  # (F,3,P)
    tri = positions[faces]
    corner_crack = np.rint(np.nan_to_num(corner[:, :, CRACK], nan=-1.0)).astype(np.int64)
    crack = _face_cracks(corner_crack, tri, render.cracks, render.spacing)
    inner = crack != -1
    flat = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flat /= np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300)
    normals = corner[:, :, NORMAL].copy()
    normals[inner] = flat[inner][:, None, :]
    length = np.linalg.norm(normals, axis=2, keepdims=True)
    normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-300), flat[:, None, :])
    uvs = _outer_uvs(corner[:, :, UV], tri, crack == -1)
    uvs[crack == HULL_FACE] = np.nan  # (the cache writer projects them on a box)
    for index in np.unique(crack[crack >= 0]):
        rows = np.nonzero(crack == index)[0]
        surface = render.cracks[index]
        rel = tri[rows] - surface.point
        if surface.radius is None:
            e1, e2 = tangent_frame(surface.normal)
            uvs[rows] = np.stack([rel @ e1, rel @ e2], axis=2)
        else:  # a sphere: longitude and latitude scaled to metres on the sphere
            r = np.linalg.norm(rel, axis=2)
            uvs[rows] = np.stack([np.arctan2(rel[..., 1], rel[..., 0]) * surface.radius,
                                  np.arcsin(np.clip(rel[..., 2] / np.maximum(r, 1e-300), -1, 1)) * surface.radius],
                                 axis=2)
    return PieceMesh(positions, faces, inner, normals, uvs, crack, render.cracks)
