"""A scene object's render solid as the arrays it is built from: what travels between
processes, so that any process can cut a scene object's first split.

The boolean library builds a solid from a mesh the same way in every process, so a process
sent the arrays a scene object's render solid was built from holds the very solid every
other process built: its cut gives the same bytes wherever it is made. A cut piece's solid
is another matter: rebuilt from its own mesh, the library tidies what a cut leaves (slivers
a hairline slab wide), which moved tiny pieces' crack faces by up to a spacing; so a
piece's solid stays in the process that cut it, and so do its own splits (``pool.py``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import manifold3d as m3
import numpy as np

from .solid import RenderSolid


@dataclass(frozen=True, eq=False)
class PortableSolid:
    """The arrays a scene object's render solid (``solid.RenderSolid``) is built from.

    Attributes:
        vert_properties: (V,P) float64, the solid's vertices: x, y, z [m] then the property
            columns (``layout.py``).
        tri_verts: (F,3) uint64 vertex indices, outward.
        merge_from, merge_to: (M,) uint64, the property vertices that share a position.
        spacing: [m] the body's particle spacing.
        digest: a hex digest of all of the above.
    """

    vert_properties: np.ndarray
    tri_verts: np.ndarray
    merge_from: np.ndarray
    merge_to: np.ndarray
    spacing: float
    digest: str

    @classmethod
    def of_arrays(cls, vert_properties, tri_verts, merge_from, merge_to, spacing: float) -> "PortableSolid":
        arrays = (np.ascontiguousarray(vert_properties, dtype=np.float64),
                  np.ascontiguousarray(tri_verts, dtype=np.uint64).reshape(-1, 3),
                  np.ascontiguousarray(merge_from, dtype=np.uint64), np.ascontiguousarray(merge_to, dtype=np.uint64))
        digest = hashlib.sha256()
        for array in arrays:
            digest.update(f"{array.shape}".encode())
            digest.update(array.tobytes())
        digest.update(repr(float(spacing)).encode())
        return cls(*arrays, float(spacing), digest.hexdigest())

    def rebuilt(self) -> RenderSolid:
        """The render solid these arrays are of, as every process builds it."""
        solid = m3.Manifold(m3.Mesh64(vert_properties=self.vert_properties, tri_verts=self.tri_verts,
                                      merge_from_vert=self.merge_from, merge_to_vert=self.merge_to))
        if solid.status() != m3.Error.NoError:
            raise ValueError(f"the render surface is not a closed manifold ({solid.status()})")
        return RenderSolid(solid, (), self.spacing, portable=self)
