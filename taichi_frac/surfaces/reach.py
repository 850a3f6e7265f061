"""Keep a piece's render solid within reach of its own tets.

Where two cracks meet at a sharp angle, the flat crack faces of the piece between them run on
as a thin wedge past its last tet, into tets the physics gave its neighbours: measured on the
paper's scenes, such wedge tips reached up to four particle spacings past their piece's tets.
A flat face crossing the tets' staircase lies up to about three quarters of a tet's height
(some 1.4 spacings) from them anyway, so only what lies farther than ``REACH_FACTOR``
spacings from the piece's tets, and within that of another piece's (or a dropped tet's), is
cut away; the artist's detail that no tet reaches (thin features the mesher left out) stays.
The faces the trim leaves lie on no crack (``HULL_FACE``): the surface of the piece's tets
grown by that reach, a blunt tip where the wedge was.

Plain numpy and scipy for the distances; ``manifold3d`` for the grown tets and the trim.
"""

from __future__ import annotations

import functools

import manifold3d as m3
import numpy as np

from .layout import HULL_FACE
from .solid import difference, solid_arrays, with_crack_index

#: A piece's render solid keeps what lies within this [particle spacings] of its tets: past the
#: 1.4 spacings a flat crack face can lie from the staircase of tets it crosses.
REACH_FACTOR = 1.5
#: A trim is kept only where the piece keeps at least this share of its volume: a solid
#: mostly past its tets is not a wedge but a failed cut, which the cut's own checks judge.
KEPT_SHARE = 0.5
#: The grown tets' hull lies within this factor of the reach from them: an icosahedron's
#: circumradius over its inradius.
BALL_BOUND = float(np.sqrt(10.0 + 2.0 * np.sqrt(5.0)) / 4.0 / ((3.0 + np.sqrt(5.0)) * np.sqrt(3.0) / 12.0))
#: How many of the piece's tets (nearest by centroid) a point's distance is measured to.
NEAREST_TETS = 16


@functools.lru_cache(maxsize=1)
def _ball() -> np.ndarray:
    """(12,3) directions whose convex hull holds the unit ball: a unit icosahedron's vertices
    scaled by BALL_BOUND to inradius 1. A tet's corners moved by r along them span the tet
    grown by r (and lie within BALL_BOUND r of it)."""
    import trimesh

    return BALL_BOUND * np.asarray(trimesh.creation.icosphere(subdivisions=0).vertices)


def distance_to_tets(points: np.ndarray, corners: np.ndarray, centroids: np.ndarray, tree=None) -> np.ndarray:
    """(N,) [m] each of ``points`` (N,3) [m]'s distance to the union of the tets ``corners``
    (T,4,3) [m] (0 inside one), measured to the NEAREST_TETS tets whose ``centroids`` (T,3)
    are nearest it (a far tet with a nearer face would be nearer still: the distance is an
    upper bound, exact wherever the tets are of like size). ``tree``: a KD-tree of
    ``centroids`` where one is at hand."""
    import trimesh
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    if not len(points) or not len(corners):
        return np.full(len(points), np.inf)
    k = min(NEAREST_TETS, len(corners))
    tree = cKDTree(centroids) if tree is None else tree
    candidates = tree.query(points, k=k)[1].reshape(len(points), k)  # (N,K)
    tet = corners[candidates]  # (N,K,4,3)
    p = np.broadcast_to(points[:, None, :], (len(points), k, 3))
    # Inside a tet: every barycentric coordinate of the point non-negative.
    edges = np.stack([tet[:, :, i] - tet[:, :, 0] for i in (1, 2, 3)], axis=-1)  # (N,K,3,3)
    flat = np.abs(np.linalg.det(edges)) <= 1e-300  # (a tet of no volume holds no point)
    bary = np.linalg.solve(np.where(flat[..., None, None], np.eye(3), edges), (p - tet[:, :, 0])[..., None])[..., 0]
    inside = ~flat & np.all(bary >= 0.0, axis=-1) & (bary.sum(axis=-1) <= 1.0)
    faces = tet[:, :, [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]]  # (N,K,4,3,3)
    q = np.broadcast_to(p[:, :, None, :], faces.shape[:3] + (3,)).reshape(-1, 3)
    nearest = trimesh.triangles.closest_point(faces.reshape(-1, 3, 3), q)
    distance = np.linalg.norm(nearest - q, axis=1).reshape(faces.shape[:3]).min(axis=2)
    return np.where(inside, 0.0, distance).min(axis=1)


def _grown(corners: np.ndarray, reach: float) -> list:
    """The tets ``corners`` (T,4,3) [m], each grown by ``reach`` [m]: (T,) convex manifolds."""
    offsets = reach * _ball()
    return [m3.Manifold.hull_points(np.ascontiguousarray((tet[:, None, :] + offsets[None]).reshape(-1, 3)))
            for tet in corners]


def trim_overreach(solid: m3.Manifold, model, labels: np.ndarray, k: int, spacing: float) -> tuple[m3.Manifold, float]:
    """Piece ``k``'s render ``solid`` (the body's frame [m]) less what lies farther than
    REACH_FACTOR spacings from its tets (``labels == k`` of ``model``'s) and within that of
    the other tets (another piece's, or dropped), near the vertices that far. Returns the
    solid (``solid`` itself where nothing is that far) and the volume cut away [m^3]."""
    from .trees import centroid_tree

    mine = np.nonzero(labels == k)[0]
    if solid.is_empty() or not len(mine):
        return solid, 0.0
    reach = REACH_FACTOR * spacing
    props, _ = solid_arrays(solid)
    vertices = props[:, :3]
    # Vertices beyond reach of the piece's tets and within it of another's (a vertex within
    # reach of a tet centroid is within reach of its tet).
    centroids = model.particle_position
    own_tree = centroid_tree(model, labels, k)
    candidates = np.nonzero(own_tree.query(vertices)[0] > reach)[0]
    if not len(candidates):
        return solid, 0.0
    own_corners = model.vertices[model.tets[mine]]  # (T,4,3)
    distance = distance_to_tets(vertices[candidates], own_corners, centroids[mine], own_tree)
    candidates, distance = candidates[distance > reach], distance[distance > reach]
    others = np.nonzero(labels != k)[0]
    if len(candidates) and len(others):
        held = distance_to_tets(vertices[candidates], model.vertices[model.tets[others]], centroids[others],
                                centroid_tree(model, labels, k, others=True)) <= reach
        candidates, distance = candidates[held], distance[held]
    if not len(candidates):
        return solid, 0.0
    far = vertices[candidates]
    # (the wedge runs back from its tip to where it comes within reach)
    margin = float(distance.max()) - reach + spacing
    low, high = far.min(axis=0) - margin, far.max(axis=0) + margin
    own = np.all((own_corners.max(axis=1) >= low - reach) & (own_corners.min(axis=1) <= high + reach), axis=1)
    removed = m3.Manifold.cube(tuple(high - low)).translate(tuple(low))
    if own.any():
        removed = difference(removed, _grown(own_corners[own], reach))
    if removed.is_empty():
        return solid, 0.0
    trimmed = solid - with_crack_index(removed, HULL_FACE)
    return trimmed, solid.volume() - trimmed.volume()
