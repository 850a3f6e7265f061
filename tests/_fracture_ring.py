"""The fracture tests' ring: torus major radius 0.1 m, minor 0.025 m, about 5,000 tets
(tetgen directly, so these tests do not depend on the geometry pipeline)."""

from functools import lru_cache

import numpy as np

from taichi_frac.model import build_body_model

# The documented controllability settings (docs/readme/fracture.md): impact on the outer
# equator, pushing toward the ring's centre.
RING_CONTACT = np.array([0.125, 0.0, 0.0])
RING_NORMAL = np.array([-1.0, 0.0, 0.0])
RING_FORCE = 1.0e4 * RING_NORMAL  # [N]


@lru_cache(maxsize=1)
def ring_model(density: float = 2400.0):
    import tetgen
    import trimesh

    surface = trimesh.creation.torus(major_radius=0.1, minor_radius=0.025, major_sections=48, minor_sections=16)
    mesher = tetgen.TetGen(surface.vertices, surface.faces)
    nodes, tets = mesher.tetrahedralize(switches="pq1.8a4.5e-7Q")[:2]
    return build_body_model(nodes, tets, density)
