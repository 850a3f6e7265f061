"""Output: the USD fracture cache (``CacheWriter``) and fragment render surfaces."""

from .cache import CacheWriter
from .fragment_mesh import fragment_surface

__all__ = ["CacheWriter", "fragment_surface"]
