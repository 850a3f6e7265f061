"""Rigid-body dynamics of the two-scale bodies in Taichi kernels."""

from .options import CapacityError, DynamicsOptions, WorldCapacity
from .world import World, WorldStats

__all__ = ["World", "WorldCapacity", "DynamicsOptions", "CapacityError", "WorldStats"]
