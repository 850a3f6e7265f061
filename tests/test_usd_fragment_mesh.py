"""fragment_surface: crack faces are exactly the faces on the cut, checked geometrically."""

from __future__ import annotations

import numpy as np
import pytest

from taichi_frac.surfaces.mesh import fragment_surface
from taichi_frac.model import build_body_model

# Kuhn split of a cube into 6 tets sharing the diagonal 0-6 (conforming across cubes).
CUBE_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]])


def grid_tets(n):
    """A [0,n]^3 block of unit cubes, 6 tets each. Corner order of a cube: 0..3 bottom, 4..7 top."""
    index = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    vertices = np.stack(np.meshgrid(*[np.arange(n + 1.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [index[i, j, k], index[i + 1, j, k], index[i + 1, j + 1, k], index[i, j + 1, k],
                     index[i, j, k + 1], index[i + 1, j, k + 1], index[i + 1, j + 1, k + 1], index[i, j + 1, k + 1]]
                tets += [[c[v] for v in t] for t in CUBE_TETS]
    return vertices, np.array(tets)


@pytest.mark.parametrize("corner_order", [[0, 1, 2, 3], [1, 2, 0, 3]])
def test_inner_faces_are_the_cut_plane(corner_order):
    """Also with the fragment's tet corners in another (same-orientation) order than the root's:
    its local face k is then not the root's."""
    vertices, tets = grid_tets(3)
    root = build_body_model(vertices, tets, density=1000.0)
    centroid_x = (root.vertices[root.tets].mean(axis=1) + root.com_in_source)[:, 0]
    cut_x = 1.0  # a plane between cube layers: no tet straddles it
    for side in (centroid_x < cut_x, centroid_x > cut_x):
        subset = np.nonzero(side)[0]
        part = build_body_model(root.vertices, root.tets[subset][:, corner_order], density=1000.0, source_tet=subset)
        verts, faces, inner = fragment_surface(part, root)
        assert len(faces) == len(part.surface_faces)
        # Fragment body frame -> root body frame -> source frame: add both centres of mass.
        corner_x = (verts[faces] + part.com_in_source + root.com_in_source)[..., 0]
        on_cut = np.all(np.isclose(corner_x, cut_x), axis=1)
        np.testing.assert_array_equal(inner, on_cut)
        assert inner.sum() == 2 * 3 * 3  # the cut plane: 3x3 unit squares, 2 triangles each


def test_root_body_has_no_inner_faces():
    vertices, tets = grid_tets(2)
    root = build_body_model(vertices, tets, density=1000.0)
    _, faces, inner = fragment_surface(root, root)
    assert len(faces) == 6 * 2 * 2 * 2 and not inner.any()
