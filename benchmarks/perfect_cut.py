"""What a flat crack face can reach at best on a body's tets: the render solid cut exactly by a
plane and the tets split by that same plane (each tet to the side its centroid lies on), so
the cut and the pieces agree as well as any flat face can. The gap left between a piece's
render solid and its tets is the tets' staircase alone, the floor under the piece-geometry
page's distance and volume columns.

Per body: halves (one plane through a random particle) and wedges (a second plane at 30-90°
to it, placed so the wedge holds a set number of tets), each measured with
surfaces/checks.py as the live pieces are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import spread

#: Tets in a wedge piece: the sizes of the pieces made where two cracks meet.
WEDGE_TETS = (30, 100)
#: Random planes per body.
PLANES = 12


@dataclass(frozen=True)
class Cut:
    """One piece of a perfect cut: ``tets`` in it, its render solid's ``volume_error``
    against its tets' (fraction), and ``to_tets`` / ``from_tets`` [particle spacings]: the
    largest distance from its render surface to its tets' union and back (0 inside)."""

    tets: int
    volume_error: float
    to_tets: float
    from_tets: float


def perfect_cut(model, solid, planes) -> Cut | None:
    """The piece on the positive side of every plane (``normal``, ``offset``): n.x >= d) of
    ``planes``: the render ``solid`` (a manifold3d Manifold in the body frame) trimmed by
    them, against the tets whose centroids lie there. Render parts holding none of those
    centroids (a sliver where a plane grazes the surface) are left out. None when no tet or
    no render lies there."""
    from taichi_frac.surfaces.checks import inside, outside_distance, signed_volume
    from taichi_frac.surfaces.solid import solid_arrays
    from taichi_frac.geometry.topology import boundary_faces

    centroids = model.particle_position
    mask = np.all([centroids @ np.asarray(n) >= d for n, d in planes], axis=0)
    if not mask.any():
        return None
    tets = np.nonzero(mask)[0]
    for normal, offset in planes:
        solid = solid.trim_by_plane(np.asarray(normal, dtype=np.float64), float(offset))
    parts = []
    for part in solid.decompose():
        props, faces = solid_arrays(part)
        vertices = props[:, :3]
        if len(faces) and inside(centroids[tets], vertices[faces]).any():
            parts.append((vertices, faces))
    if not parts:
        return None
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    vertices = np.concatenate([v for v, _ in parts])
    faces = np.concatenate([f + o for (_, f), o in zip(parts, offsets)])
    boundary = boundary_faces(model.tets[tets])[0]
    to_tets = outside_distance(vertices, model.vertices, boundary)
    from_tets = outside_distance(model.vertices[np.unique(boundary)], vertices, faces)
    return Cut(tets=len(tets),
               volume_error=signed_volume(vertices, faces) / float(model.tet_volume[tets].sum()) - 1.0,
               to_tets=float(to_tets.max()) / model.spacing, from_tets=float(from_tets.max()) / model.spacing)


def perfect_cuts(model, solid, seed: int = 0, planes: int = PLANES) -> dict:
    """{kind: [Cut]} over ``planes`` random planes through ``model``'s particles: 'halves'
    (both sides of each plane) and 'wedges of about N tets' per ``WEDGE_TETS``."""
    rng = np.random.default_rng(seed)
    centroids = model.particle_position
    cuts = {"halves": []} | {f"wedges of about {n} tets": [] for n in WEDGE_TETS}
    for _ in range(planes):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        offset = float(normal @ centroids[rng.integers(len(centroids))])
        for sign in (1.0, -1.0):
            cuts["halves"].append(perfect_cut(model, solid, [(sign * normal, sign * offset)]))
        side = rng.normal(size=3)
        side -= (side @ normal) * normal
        side /= np.linalg.norm(side)
        angle = np.deg2rad(rng.uniform(30.0, 90.0))
        second = np.cos(angle) * normal + np.sin(angle) * side
        heights = np.sort(centroids[centroids @ normal >= offset] @ second)[::-1]
        for n in WEDGE_TETS:
            if len(heights) > n:
                planes_ = [(normal, offset), (second, 0.5 * float(heights[n - 1] + heights[n]))]
                cuts[f"wedges of about {n} tets"].append(perfect_cut(model, solid, planes_))
    return {kind: [c for c in found if c is not None] for kind, found in cuts.items()}


#: The floor table's header (``floor_rows``' columns).
FLOOR_HEADER = ["body", "pieces", "tets, median", "volume error [%]: median / 95th pct / max",
                "off by more than 2 %", "render-to-tets [spacings]: median / 95th pct / max",
                "tets-to-render [spacings]: median / 95th pct / max", "within 1 spacing both ways"]


def floor_rows(label: str, cuts: dict) -> list:
    """The floor table's rows of one body's ``perfect_cuts``, one per kind of piece."""
    rows = []
    for kind, found in cuts.items():
        if not found:
            continue
        error = np.abs([c.volume_error for c in found])
        to_tets = np.array([c.to_tets for c in found])
        from_tets = np.array([c.from_tets for c in found])
        rows.append([f"{label}: {kind}", len(found), f"{np.median([c.tets for c in found]):.0f}",
                     spread(100 * error), int(np.sum(error > 0.02)), spread(to_tets), spread(from_tets),
                     int(np.sum((to_tets <= 1.0) & (from_tets <= 1.0)))])
    return rows
