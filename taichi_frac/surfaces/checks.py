"""Measures of a piece's render surface: is it a closed, manifold, outward-wound solid, how
far do its crack faces lie from their cracks, and how well does it match its tets.

Used by the tests and by ``taichi-frac bench``'s piece-geometry table; plain numpy on
triangle meshes, independent of the boolean library that built them.
"""

from __future__ import annotations

import numpy as np
import trimesh


def edge_counts(faces: np.ndarray) -> dict:
    """Counts over the undirected edges of a triangle mesh ``faces`` (F,3):
    ``open_edges`` (used by one face), ``nonmanifold_edges`` (by more than two),
    ``misoriented_edges`` (two faces that run it the same way: inconsistent winding)."""
    faces = np.asarray(faces, dtype=np.int64)
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    _, inverse, uses = np.unique(undirected, axis=0, return_inverse=True, return_counts=True)
    forward = (directed[:, 0] < directed[:, 1]).astype(np.int64)
    forward_count = np.bincount(inverse.reshape(-1), weights=forward, minlength=len(uses))
    two = uses == 2
    return dict(edges=int(len(uses)), open_edges=int(np.sum(uses == 1)), nonmanifold_edges=int(np.sum(uses > 2)),
                misoriented_edges=int(np.sum(two & (forward_count != 1))))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """[m^3] the divergence-theorem volume of a closed mesh (positive when outward wound)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def crack_deviation(vertices, faces, face_is_inner, face_crack, cracks) -> float:
    """[m] RMS distance of the crack faces' corners from their crack surfaces
    (``CrackSurface``), each corner weighted by a third of its face's area; NaN without
    crack faces. Inner faces on no crack (``face_crack`` < 0) are not counted."""
    faces = np.asarray(faces, dtype=np.int64)
    inner = np.nonzero(np.asarray(face_is_inner, dtype=bool) & (np.asarray(face_crack) >= 0))[0]
    if not len(inner):
        return float("nan")
    tri = np.asarray(vertices, dtype=np.float64)[faces[inner]]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    squares = np.zeros(len(inner))
    for index in np.unique(np.asarray(face_crack)[inner]):
        rows = np.nonzero(np.asarray(face_crack)[inner] == index)[0]
        d = cracks[index].distance(tri[rows].reshape(-1, 3)).reshape(-1, 3)
        squares[rows] = np.mean(d * d, axis=1)
    return float(np.sqrt(np.sum(area * squares) / max(np.sum(area), 1e-300)))


def inside(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N,) bool: ``points`` (N,3) inside the closed surface ``triangles`` (F,3,3): the
    generalized winding number above 1/2 (Jacobson et al. 2013), the exact sum of the
    triangles' solid angles (libigl's ``winding_number``, some fifty times numpy's speed)."""
    import igl

    points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    corners = np.ascontiguousarray(np.asarray(triangles, dtype=np.float64).reshape(-1, 3))
    if not len(points) or not len(corners):
        return np.zeros(len(points), dtype=bool)
    faces = np.arange(len(corners), dtype=np.int64).reshape(-1, 3)
    return np.asarray(igl.winding_number(corners, faces, points)) > 0.5


def outside_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N,) [m] each of ``points`` (N,3)'s distance to the closed surface (``vertices``,
    ``faces``), 0 for a point inside it: how far it lies outside that solid."""
    points = np.asarray(points, dtype=np.float64)
    if not len(points):
        return np.zeros(0)
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    _, distance, _ = trimesh.proximity.closest_point(trimesh.Trimesh(vertices, faces, process=False), points)
    return distance * ~inside(points, vertices[faces])


def farthest_outside_tets(vertices: np.ndarray, model) -> float:
    """[m] the largest distance from a render-surface vertex to the piece's tets' union (0
    inside it): one side of the Hausdorff distance between the render solid and the tets."""
    distance = outside_distance(vertices, model.vertices, model.surface_faces)
    return float(distance.max()) if len(distance) else 0.0


def farthest_outside_render(vertices: np.ndarray, faces: np.ndarray, model) -> float:
    """[m] the largest distance from a vertex of the piece's tets' boundary to its render
    solid (``vertices``, ``faces``; 0 inside it): the other side of the Hausdorff distance.
    A tet straddling a flat crack face with its centroid on the piece's side reaches past the
    face by up to 3/4 of its extent along the face's normal."""
    corners = model.vertices[np.unique(np.asarray(model.surface_faces))]
    distance = outside_distance(corners, vertices, faces)
    return float(distance.max()) if len(distance) else 0.0


def piece_quality(mesh, model) -> dict:
    """Every measure of one piece (a ``PieceMesh``) against its BodyModel, lengths in
    particle spacings: closed/manifold/winding counts, shells, crack-face RMS deviation,
    volume error against the tets' and the largest distances render-to-tets and back."""
    spacing = model.spacing
    counts = edge_counts(mesh.faces)
    volume = signed_volume(mesh.vertices, mesh.faces)
    shells = len(trimesh.graph.connected_components(trimesh.Trimesh(mesh.vertices, mesh.faces,
                                                                     process=False).face_adjacency,
                                                    nodes=np.arange(len(mesh.faces))))
    return dict(
        counts,
        watertight=counts["open_edges"] == 0 and counts["nonmanifold_edges"] == 0 and counts["misoriented_edges"] == 0,
        outward=volume > 0,
        shells=shells,
        crack_rms_spacings=crack_deviation(mesh.vertices, mesh.faces, mesh.face_is_inner, mesh.face_crack,
                                           mesh.cracks) / spacing,
        volume_error=volume / model.volume - 1.0,
        inner_area_fraction=_area_fraction(mesh.vertices, mesh.faces, mesh.face_is_inner),
        distance_to_tets_spacings=farthest_outside_tets(mesh.vertices, model) / spacing,
        distance_from_tets_spacings=farthest_outside_render(mesh.vertices, mesh.faces, model) / spacing,
    )


def _area_fraction(vertices, faces, mask) -> float:
    tri = np.asarray(vertices)[np.asarray(faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return float(area[np.asarray(mask, dtype=bool)].sum() / max(area.sum(), 1e-300))
