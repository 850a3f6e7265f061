"""The pieces' render surfaces: the artist's surface of each body, cut along the cracks at
every split so that each piece is closed and holds its tets' volume.

Entry points: ``pool.SurfaceWorkers(count)`` and ``pool.InProcessSurfaces()`` (both
``front.SurfaceFront``): ``add_body`` for a scene object, ``cut(fracture)`` after a split,
futures of a :class:`BodySurface` per body (the vertex layout the cache writer takes) and of
the split's :class:`PieceSurfaces`; :class:`SurfaceStage` (``stage.py``) does the work in
whichever process takes it, a scene object's render solid sent as the arrays it is built
from (``solid.PortableSolid``).
Modules: ``solid.py`` (a render solid and its per-vertex property columns, ``layout``), ``cut.py``
(the cut along the cracks), ``slabs.py`` (the solids a crack removes), ``crack_fit.py``
(cracks moved so the pieces hold their volumes), ``parts.py``, ``shells.py``, ``reach.py``,
``tet_cells.py`` (the pieces' parts given to their tets), ``checks.py`` (measures of a
piece against its tets), ``mesh.py`` (a piece's mesh for the writer).
"""

from .stage import BodySurface, PieceSurfaces, SurfaceStage

__all__ = ["BodySurface", "PieceSurfaces", "SurfaceStage"]
