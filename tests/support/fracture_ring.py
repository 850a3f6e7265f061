"""The fracture set-ups the benchmark report measures and the tests check, defined once so
both describe the same bodies: the ring (torus major radius 0.1 m, minor 0.025 m, about
5,000 tets, meshed by tetgen directly so it does not depend on the geometry pipeline), its
documented impact, the jittered block of the stress-error table and the crack discs that
isolate one tet."""

from functools import lru_cache

import numpy as np

from taichi_frac.fracture.cracks import CrackPlane
from taichi_frac.geometry.topology import TET_FACES
from taichi_frac.model import build_body_model

# The documented controllability settings (docs/guide/fracture-controls.md): impact on the outer
# equator, pushing toward the ring's centre.
RING_CONTACT = np.array([0.125, 0.0, 0.0])
RING_NORMAL = np.array([-1.0, 0.0, 0.0])
RING_FORCE = 1.0e4 * RING_NORMAL  # [N]


@lru_cache(maxsize=1)
def struck_ring_model(density: float = 2400.0):
    """The ring's BodyModel (density [kg/m^3]); built once per process."""
    import tetgen
    import trimesh

    surface = trimesh.creation.torus(major_radius=0.1, minor_radius=0.025, major_sections=48, minor_sections=16)
    mesher = tetgen.TetGen(surface.vertices, surface.faces)
    nodes, tets = mesher.tetrahedralize(switches="pq1.8a4.5e-7Q")[:2]
    return build_body_model(nodes, tets, density)


def jittered_block(per_side, jitter=0.2, seed=0):
    """Particles of a unit cube z in [0, 1], x, y in [-1/2, 1/2] (top face z = 1): a
    lattice of per_side^3 points jittered by ``jitter`` x spacing. Returns (points (N,3)
    [m], volumes (N,) [m^3]). The stress test and ``taichi-frac bench sph`` both use it,
    so the test's tolerance and the report's error table describe the same block."""
    rng = np.random.default_rng(seed)
    s = 1.0 / per_side
    g = (np.arange(per_side) + 0.5) * s - 0.5
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = pts + rng.uniform(-jitter, jitter, pts.shape) * s
    pts[:, 2] += 0.5
    return pts, np.full(len(pts), s**3)


def corner_cracks(model, tet):
    """Crack discs on the faces of ``tet`` shared with neighbours: isolates it (and maybe a
    few tets beside it)."""
    cracks = []
    p = model.vertices[model.tets[tet]]
    for k in range(4):
        if model.tet_neighbor[tet, k] < 0:
            continue
        face = p[TET_FACES[k]]
        n = np.cross(face[1] - face[0], face[2] - face[0])
        centre = face.mean(axis=0)
        reach = np.linalg.norm(face - centre, axis=1).max()
        cracks.append(CrackPlane(point=centre, normal=n / np.linalg.norm(n), extent=0.5 * reach, peak_stress=2e6))
    return cracks
