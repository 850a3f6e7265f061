"""taichi-frac: controllable two-scale particle fracture of brittle solids.

Implements Chen, Wang & Xie (2015), "Controllable Two Scale Particles for Fracture
Animation of Brittle Materials" (see ../shared/paper/BRIEF.md for the corrected equations).
"""

__version__ = "0.1.0"
