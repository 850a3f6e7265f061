"""Output: the USD fracture cache (``CacheWriter``) and the recorder that keeps it in step with a run."""

from .cache import CacheWriter

__all__ = ["CacheWriter"]
