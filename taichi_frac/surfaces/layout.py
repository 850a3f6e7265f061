"""The vertex layout of a render solid: the per-vertex property columns of its manifold3d
solid (``Manifold.to_mesh().vert_properties``), which every cut carries through.

Columns: x, y, z [m] body frame; the corner normal (3, unit); the UV (2); the index of the
crack the vertex lies on (``ARTIST_SURFACE`` on the artist's surface, ``HULL_FACE`` on a
carved piece's hull). ``PROPERTY_COUNT`` columns in all.
"""

POSITION = slice(0, 3)
NORMAL = slice(3, 6)
UV = slice(6, 8)
CRACK = 8
PROPERTY_COUNT = 9

#: The crack index of the artist's own surface.
ARTIST_SURFACE = -1
#: The crack index of a carved piece's hull faces (inner faces on no crack).
HULL_FACE = -2
