"""Shading attributes of the input surface carried onto the tet mesh's boundary faces.

The mesher splits input triangles (tetgen refines the surface), so a boundary face of the
tet mesh lies inside one input triangle rather than being one. Each boundary face is
matched to the input triangle nearest its centroid, and its corners get that triangle's
corner normals and UVs interpolated barycentrically. Corner normals are area-weighted
face normals around the vertex over the faces within ``crease_angle_deg`` (60 degrees) of the face
itself, so curved surfaces shade smoothly (coarse primitives have 45 degrees between
neighbouring facets) and sharp edges (a box, a wall: 90 degrees) stay sharp.
UVs come from the input mesh's texture coordinates where it has any (None otherwise): its
exact per-corner UVs (``metadata["corner_uvs"]``, which keep both sides of a UV seam) when
given, else its per-vertex UVs.
"""

from __future__ import annotations

import numpy as np
import trimesh


def input_corner_normals(surface: trimesh.Trimesh, crease_angle_deg: float = 60.0) -> np.ndarray:
    """(Fi,3,3) unit normal at each corner of each input triangle (see module docstring)."""
    face_normals = np.asarray(surface.face_normals)
    area = np.asarray(surface.area_faces)
    incident = np.asarray(surface.vertex_faces)[np.asarray(surface.faces)]  # (Fi,3,D), -1 padded
    valid = incident >= 0
    neighbour_normals = face_normals[np.where(valid, incident, 0)]  # (Fi,3,D,3)
    cos_to_face = np.einsum("fcdk,fk->fcd", neighbour_normals, face_normals)
    weight = area[np.where(valid, incident, 0)] * valid * (cos_to_face >= np.cos(np.radians(crease_angle_deg)))
    normals = np.einsum("fcd,fcdk->fck", weight, neighbour_normals)
    length = np.linalg.norm(normals, axis=2, keepdims=True)
    return np.where(length > 0, normals / np.maximum(length, 1e-300), face_normals[:, None, :])


def boundary_corner_attributes(surface: trimesh.Trimesh, corners: np.ndarray,
                               crease_angle_deg: float = 60.0):
    """Normals and UVs for boundary triangles lying on ``surface``.

    Args:
        surface: the input surface, in the same frame and units as ``corners``.
        corners: (F,3,3) [m] corner positions of the boundary triangles.

    Returns (normals (F,3,3) unit, uvs (F,3,2) or None).
    """
    corners = np.asarray(corners, dtype=np.float64)
    count = len(corners)
    if count == 0:
        return np.zeros((0, 3, 3)), None
    # The mesher merges coplanar input triangles into one facet and re-triangulates it, so a
    # boundary face may span several input triangles: each corner is located on its own,
    # nudged a little into its face so that a corner on an input edge picks the triangle
    # on this face's side (the right one at a crease or a UV seam).
    centroid = corners.mean(axis=1, keepdims=True)
    probe = (corners + 1e-3 * (centroid - corners)).reshape(-1, 3)
    _, _, triangle = trimesh.proximity.closest_point(surface, probe)  # (3F,)
    tri_points = np.asarray(surface.triangles)[triangle]  # (3F,3,3)
    bary = trimesh.triangles.points_to_barycentric(tri_points, corners.reshape(-1, 3))
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    corner_normals = input_corner_normals(surface, crease_angle_deg)[triangle]  # (3F,3,3)
    normals = np.einsum("ik,ikd->id", bary, corner_normals).reshape(count, 3, 3)
    normals /= np.maximum(np.linalg.norm(normals, axis=2, keepdims=True), 1e-300)
    uv = getattr(surface.visual, "uv", None)
    corner_uvs = surface.metadata.get("corner_uvs")
    uvs = None
    if corner_uvs is not None and len(corner_uvs) == len(surface.faces):
        tri_uv = np.asarray(corner_uvs, dtype=np.float64)[triangle]  # (3F,3,2)
        uvs = np.einsum("ik,ikd->id", bary, tri_uv).reshape(count, 3, 2)
    elif uv is not None and len(uv) == len(surface.vertices):
        tri_uv = np.asarray(uv, dtype=np.float64)[np.asarray(surface.faces)[triangle]]  # (3F,3,2)
        uvs = np.einsum("ik,ikd->id", bary, tri_uv).reshape(count, 3, 2)
    return normals, uvs
