"""The Voronoi cells of tet centroids, as closed solids: the material nearest a piece's
tets, which ``piece_parts`` hands out where the crack slabs cannot part two pieces (a part
holding two pieces' material, a piece carved out of its neighbour, a piece the cut failed).
``scipy.spatial.Voronoi`` for the diagram, ``manifold3d`` for the solids.
"""

from __future__ import annotations

import manifold3d as m3
import numpy as np

from ..memo import made_for

#: How far [particle spacings] about the centroids whose cells may go to another piece the
#: Voronoi diagram that divides a part reads the centroids (a cell depends only on its
#: neighbours, within twice its reach); half of it bounds how far from the part such a
#: centroid can lie and still reach it.
LOCAL_DIAGRAM_FACTOR = 4.0


def voronoi_cells(points: np.ndarray, spacing: float):
    """The Voronoi diagram of ``points`` (N,3) [m] (bounded by a box 20 spacings beyond
    them, so every point's cell is closed): ``.radius(indices)`` each cell's reach from its
    point [m]; ``.union(indices)`` the union of those points' cells as one closed manifold
    (its faces HULL_FACE), or None where qhull's diagram is degenerate there."""
    from scipy.spatial import Voronoi

    from .layout import CRACK, HULL_FACE, PROPERTY_COUNT

    low, high = points.min(axis=0) - 20 * spacing, points.max(axis=0) + 20 * spacing
    fence = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
    diagram = Voronoi(np.concatenate([points, fence]))
    regions = [diagram.regions[r] for r in diagram.point_region[:len(points)]]
    owner_of = np.repeat(np.arange(len(points)), [len(region) for region in regions])
    reach = np.zeros(len(points))  # (N,) [m] each point's farthest cell corner
    np.maximum.at(reach, owner_of, np.linalg.norm(diagram.vertices[np.concatenate(regions)] - points[owner_of], axis=1))
    ridge_points = np.asarray(diagram.ridge_points, dtype=np.int64)

    class Cells:
        @staticmethod
        def joined(indices, seeds):
            """The ``indices`` whose cells connect, through cells of ``indices``, to one of
            the ``seeds``' cells."""
            from scipy.sparse import coo_matrix
            from scipy.sparse.csgraph import connected_components

            chosen = np.zeros(len(diagram.points), dtype=bool)
            chosen[indices] = True
            both = ridge_points[chosen[ridge_points[:, 0]] & chosen[ridge_points[:, 1]]]
            graph = coo_matrix((np.ones(len(both)), (both[:, 0], both[:, 1])), shape=(len(chosen),) * 2)
            component = connected_components(graph, directed=False)[1]
            seeded = np.unique(component[np.asarray(seeds, dtype=np.int64)[chosen[seeds]]])
            return np.asarray(indices)[np.isin(component[indices], seeded)]

        @staticmethod
        def radius(indices):
            return reach[indices]

        @staticmethod
        def union(indices):
            mesh = Cells.union_mesh(indices)
            return None if mesh is None else solid_of(mesh)

        @staticmethod
        def union_mesh(indices):
            """The arrays ``union`` builds its manifold from (``m3.Mesh64``), or None."""
            # The union's boundary is every ridge between a chosen point and one not chosen:
            # a convex polygon, its corners sorted by angle about its centre and fanned into
            # triangles facing away from the chosen point; neighbouring ridges share the
            # diagram's vertices, so the surface is closed.
            chosen = np.zeros(len(diagram.points), dtype=bool)
            chosen[np.asarray(indices, dtype=np.int64)] = True
            rows = np.nonzero(chosen[ridge_points[:, 0]] != chosen[ridge_points[:, 1]])[0]
            if not len(rows):
                return None
            rings = [diagram.ridge_vertices[r] for r in rows]
            sizes = np.array([len(ring) for ring in rings])
            corner = np.concatenate(rings).astype(np.int64)
            if (sizes < 3).any() or (corner < 0).any():
                return None
            ridge = np.repeat(np.arange(len(rows)), sizes)
            a, b = ridge_points[rows, 0], ridge_points[rows, 1]
            inner = np.where(chosen[a], a, b)
            normal = diagram.points[np.where(chosen[a], b, a)] - diagram.points[inner]  # out of the union
            position = diagram.vertices[corner]
            centre = np.stack([np.bincount(ridge, weights=position[:, k]) for k in range(3)], axis=1) / sizes[:, None]
            start = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            e1 = position[start] - centre
            e2 = np.cross(normal, e1)
            rel = position - centre[ridge]
            angle = np.arctan2(np.einsum("ij,ij->i", rel, e2[ridge]), np.einsum("ij,ij->i", rel, e1[ridge]))
            corner = corner[np.lexsort((angle, ridge))]  # each ring counter-clockwise about its normal
            fans = sizes - 2  # triangles of each ring: (first, t, t + 1) for t in 1 .. size - 2
            step = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1
            first = np.repeat(start, fans)
            fan = np.stack([first, first + step, first + step + 1], axis=1)
            triangles = corner[fan]
            used, faces = np.unique(triangles, return_inverse=True)
            props = np.zeros((len(used), PROPERTY_COUNT))
            props[:, :3] = diagram.vertices[used]
            props[:, CRACK] = HULL_FACE
            return m3.Mesh64(vert_properties=props, tri_verts=np.ascontiguousarray(faces.reshape(-1, 3),
                                                                                   dtype=np.uint64))

    return Cells()


def solid_of(mesh: m3.Mesh64):
    """The closed manifold of a cells' union's arrays (``union_mesh``), or None where qhull's
    diagram was degenerate."""
    solid = m3.Manifold(mesh)
    return solid if solid.status() == m3.Error.NoError and not solid.is_empty() else None


#: The last few ``own_cells`` diagrams: each pass of a split's crack fit asks again for the
#: cells of the same pieces among the same tets (13 of the 13 rings' 34 asks).
OWN_CELLS_KEPT = 32
_OWN_CELLS: dict = {}  # (memo.made_for) -> ((positions, labels), the union's Mesh64 or None)


def own_cells(model, labels, k: int, spacing: float, pool: np.ndarray):
    """The union of piece ``k``'s tet centroids' cells in the Voronoi diagram of the centroids
    ``pool`` (indices, sorted, k's among them) about them (HULL_FACE faces), or None where it
    is degenerate or k has no tets. The diagram is kept for the same arrays (``model``'s
    centroids and ``labels``, the same objects) and pool; the manifold is built anew from it
    each time, as the boolean library numbers each solid it builds and a cut's bytes follow
    those numbers."""
    from scipy.spatial import cKDTree

    pool = np.asarray(pool, dtype=np.int64)
    positions = model.particle_position

    def diagram():
        mine = np.nonzero(labels == k)[0]
        if not len(mine):
            return None
        # (the diagram about k's centroids only: their cells depend on their neighbours alone)
        near = pool[cKDTree(positions[mine]).query(positions[pool])[0] <= LOCAL_DIAGRAM_FACTOR * spacing]
        return voronoi_cells(positions[near], spacing).union_mesh(np.searchsorted(near, mine))

    mesh = made_for(_OWN_CELLS, (positions, labels), (int(k), float(spacing), pool.tobytes()), diagram,
                    OWN_CELLS_KEPT)
    return None if mesh is None else solid_of(mesh)
