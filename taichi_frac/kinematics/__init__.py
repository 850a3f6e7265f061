"""Rigid-body math shared by ``collision/``, ``dynamics/`` and the host code that places
bodies: quaternions and rotations (``quaternion.py``, in Taichi and numpy) and the
per-body motion bounds (``bounds.py``), tangent frames (``frames.py``). Imports nothing else of the package."""
