"""A piece's shells: crumbs dropped, stray bits joined. A bit of a piece apart from its main
shell (material a divided part's cells gave it beyond a crack's slab, a carved corner) would
fly beside it as a separate solid. Crumbs (``without_crumbs``) are dropped; where a bit lies
against its own piece's main shell (across a crack slab's hairline gap or on a shared cell
face) a thin bridge over that contact joins the two; where it lies against another piece's
main shell only, it goes to that piece, bridged the same way.
Plain numpy and trimesh for the contacts; ``manifold3d`` for the bridges.
"""

from __future__ import annotations

import manifold3d as m3
import numpy as np

#: A piece's parts smaller than this [particle spacings cubed] beside a larger one are
#: dropped: crumbs where cracks meet, under a mean tet's volume.
CRUMB_VOLUME_FACTOR = 1.0
#: So are those under this share of its largest part: chips where cracks or the faces of a
#: divided part's cells cross the surface, which would travel beside the piece as separate
#: shells (they hold under this share of its volume each).
CRUMB_VOLUME_SHARE = 0.01

#: Two faces touch when they lie within this [particle spacings] of each other: five crack
#: slabs' thickness (the hairline gap a slab leaves between two parts), so a bit facing its
#: piece across that gap touches it.
CONTACT_GAP_FACTOR = 1e-3
#: A bit joins a shell it touches over at least this area [particle spacings squared]: less
#: is an edge or a corner, where a bridge would be a visible neck.
CONTACT_AREA_FACTOR = 0.1
#: A bit goes to another piece only where its contact with its own piece's main shell is
#: under this share of its contact with that piece's.
OWN_CONTACT_SHARE = 0.25
#: ... and only where its volume is under this share of that piece's main shell's (a larger
#: bit is its own piece's material: moved, it would change the other's volume by more).
MOVED_VOLUME_SHARE = 0.1


def join_stray_shells(solids: dict, render_solid: m3.Manifold, spacing: float) -> tuple[dict, int]:
    """Each piece's solid (``solids``: piece -> closed Manifold, the body's frame [m]) with its
    shells other than the largest joined to the largest shell they touch (CONTACT_AREA_FACTOR),
    preferring their own piece's (OWN_CONTACT_SHARE): by a bridge, the ``render_solid`` within
    a prism over the bit's faces that touch that shell (CONTACT_GAP_FACTOR), reaching through
    the gap into both. Bits that touch no main shell stay. Returns (solids, how many bits
    moved to another piece)."""
    shells = {k: sorted(solid.decompose(), key=lambda shell: -shell.volume()) for k, solid in solids.items()}
    strays = [(k, bit) for k, mine in shells.items() for bit in mine[1:]]
    if not strays:
        return solids, 0
    mains = {k: mine[0] for k, mine in shells.items() if mine}  # each piece's main shell, joined bits and all
    main_triangles = {}  # piece -> its main shell's triangles (F,3,3) [m], once asked for
    gap = CONTACT_GAP_FACTOR * spacing
    kept = {k: [] for k in shells}
    moved = 0
    for k, bit in sorted(strays, key=lambda item: -item[1].volume()):
        mesh = _trimesh(bit)
        contact = {}
        for j, main in mains.items():
            box = np.asarray(main.bounding_box()).reshape(2, 3)
            if np.all(mesh.bounds[0] <= box[1] + gap) and np.all(box[0] <= mesh.bounds[1] + gap):
                if j not in main_triangles:
                    main_triangles[j] = _trimesh(shells[j][0]).triangles
                contact[j] = _touching(mesh, main_triangles[j], gap)
        area = {j: float(mesh.area_faces[faces].sum()) for j, faces in contact.items()}
        least = CONTACT_AREA_FACTOR * spacing**2
        best = max((j for j in area if j != k and bit.volume() <= MOVED_VOLUME_SHARE * mains[j].volume()),
                   key=area.get, default=None)
        if area.get(k, 0.0) >= least and (best is None or area[k] >= OWN_CONTACT_SHARE * area[best]):
            target = k
        elif best is not None and area[best] >= least:
            target = best
        else:
            kept[k].append(bit)
            continue
        joined = _joined(mains[target], bit, _bridge(mesh, contact[target], render_solid, gap), spacing)
        if joined is None:  # (the gap is no part of the render solid: a stray of the piece that broke)
            joined = _joined(mains[target], bit, _bridge(mesh, contact[target], None, gap), spacing)
        if joined is None:
            kept[k].append(bit)
            continue
        mains[target] = joined
        moved += target != k
    result = {}
    for k, solid in solids.items():
        parts = [mains[k], *kept[k]] if k in mains else [solid]
        result[k] = parts[0] if len(parts) == 1 else m3.Manifold.compose(parts)
    return result, moved


def without_crumbs(mine, spacing: float) -> list:
    """A piece's parts less those under CRUMB_VOLUME_FACTOR spacings cubed or CRUMB_VOLUME_SHARE
    of the largest beside it: wedges where two cracks' slabs cross near the surface, chips
    where a divided part's cell faces do, each a separate shell that would travel with the
    piece."""
    largest = max((part.volume() for part in mine), default=0.0)
    least = max(CRUMB_VOLUME_FACTOR * spacing**3, CRUMB_VOLUME_SHARE * largest)
    return [part for part in mine if part.volume() >= least or part.volume() == largest]


def _joined(main: m3.Manifold, bit: m3.Manifold, bridge: m3.Manifold, spacing: float) -> m3.Manifold | None:
    """The union of ``main``, ``bit`` and ``bridge`` less its dust (where the bridge meets the
    artist's surface its faces lie on the parts' own: flat slivers of no volume), or None
    where it is not one shell."""
    from .piece_surface import DUST_VOLUME_FACTOR

    shells = [shell for shell in m3.Manifold.batch_boolean([main, bit, bridge], m3.OpType.Add).decompose()
              if shell.volume() >= DUST_VOLUME_FACTOR * spacing**3]
    return shells[0] if len(shells) == 1 else None


def _trimesh(solid: m3.Manifold):
    import trimesh

    mesh = solid.to_mesh64()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64),
                           process=False)


def _touching(mesh, triangles: np.ndarray, gap: float) -> np.ndarray:
    """Indices of ``mesh``'s faces whose centres lie within ``gap`` [m] of the surface of
    ``triangles`` (F,3,3) [m]: each centre measured to the triangles whose boxes it is in."""
    from trimesh.triangles import closest_point

    centres = mesh.triangles_center
    low, high = triangles.min(axis=1) - gap, triangles.max(axis=1) + gap
    near = np.all((low <= mesh.bounds[1]) & (high >= mesh.bounds[0]), axis=1)
    triangles, low, high = triangles[near], low[near], high[near]
    point, triangle = np.nonzero(np.all((centres[:, None] >= low[None]) & (centres[:, None] <= high[None]), axis=2))
    if not len(point):
        return np.zeros(0, dtype=np.int64)
    distance = np.linalg.norm(closest_point(triangles[triangle], centres[point]) - centres[point], axis=1)
    return np.unique(point[distance <= gap])


def _bridge(mesh, faces: np.ndarray, render_solid: m3.Manifold | None, gap: float) -> m3.Manifold:
    """The ``render_solid`` (None: all) within prisms over ``mesh``'s ``faces``: from ``gap``
    [m] inside the bit to twice it outside, across the gap into the shell it touches."""
    from .piece_surface import HULL_FACE, _with_crack_index

    normal = mesh.face_normals[faces][:, None, :]
    corners = mesh.triangles[faces]
    prisms = [m3.Manifold.hull_points(np.ascontiguousarray(points.reshape(-1, 3)))
              for points in np.concatenate([corners - gap * normal, corners + 2.0 * gap * normal], axis=1)]
    # (its faces in the gap lie on no crack: HULL_FACE, like a carved piece's)
    bridge = _with_crack_index(m3.Manifold.batch_boolean(prisms, m3.OpType.Add), HULL_FACE)
    return bridge if render_solid is None else render_solid ^ bridge
