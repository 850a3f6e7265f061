"""The box the piece-geometry tests cut (a 0.2 x 0.1 x 0.06 m block with UVs linear in
position, so a clipped triangle's UVs have a closed form), meshed once per test process, and
the split-and-cut and closedness helpers they share."""

import functools

import numpy as np
import trimesh

from taichi_frac.fracture.fragments import make_fragments, split_body
from taichi_frac.surfaces.checks import edge_counts, signed_volume
from taichi_frac.surfaces.cut import cut_render_solid
from taichi_frac.geometry.prepare import prepare_body
from taichi_frac.options import FractureOptions, ParticleOptions

SIZE = np.array([0.2, 0.1, 0.06])
PARTICLES = ParticleOptions(target_particles=1500)


def uv_of(points):
    """The box's texture coordinates: a linear function of position, so a clipped
    triangle's interpolated UVs have a closed form."""
    return np.stack([points[:, 0] / SIZE[0] + 0.3 * points[:, 2], points[:, 1] / SIZE[1] - points[:, 2]], axis=1)


@functools.lru_cache(maxsize=1)
def box_body():
    """(BodyModel, PrepareReport, trimesh surface) of the box (meshed once per test process)."""
    surface = trimesh.creation.box(extents=SIZE)
    surface.visual = trimesh.visual.TextureVisuals(uv=uv_of(surface.vertices))
    model, report = prepare_body(surface, particles=PARTICLES)
    return model, report, surface


def split_and_cut(model, render, cracks, options=FractureOptions(), **kwargs):
    """Split ``model`` by ``cracks`` and cut ``render`` for its pieces: (pieces, renders,
    counts); ``kwargs`` go to ``cut_render_solid``."""
    split = split_body(model, cracks, options)
    pieces = make_fragments(model, split, np.zeros(3), [1.0, 0.0, 0.0, 0.0], np.zeros(3), np.zeros(3), None,
                            PARTICLES, options=options)
    renders, counts = cut_render_solid(render, model, split.fragment_tets, cracks,
                                       [p.model.com_in_source for p in pieces], **kwargs)
    return pieces, renders, counts


def assert_closed(mesh):
    """``mesh`` (a PieceMesh) is closed, manifold, consistently and outward wound."""
    counts = edge_counts(mesh.faces)
    assert counts["open_edges"] == counts["nonmanifold_edges"] == counts["misoriented_edges"] == 0, counts
    assert signed_volume(mesh.vertices, mesh.faces) > 0
