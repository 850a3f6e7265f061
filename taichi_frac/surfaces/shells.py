"""A piece's shells: crumbs dropped, stray bits joined. A bit of a piece apart from its main
shell (material a divided part's cells gave it beyond a crack's slab, a carved corner) would
fly beside it as a separate solid. Crumbs (``without_crumbs``) are dropped; where a bit lies
against its own piece's main shell (across a crack slab's hairline gap or on a shared cell
face) a thin bridge over that contact joins the two; where it lies against another piece's
main shell only, it goes to that piece, bridged the same way.
Plain numpy for the contacts; ``manifold3d`` for the bridges.
"""

from __future__ import annotations

from typing import NamedTuple

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
#: A bit goes to another piece only where its volume is under this share of that piece's main shell's (a larger
#: bit is its own piece's material: moved, it would change the other's volume by more).
MOVED_VOLUME_SHARE = 0.1


class StrayPlan(NamedTuple):
    """Where each piece's stray shells go (``plan_stray_shells``): ``mains`` piece -> its main
    shell, ``apart`` piece -> its bits that touch no main shell (they stay its own, apart),
    ``joined`` piece -> (bit, its trimesh, the indices of its faces touching the main shell)
    of each bit joined to that piece's main shell, ``moved`` how many of those came from
    another piece."""

    mains: dict
    apart: dict
    joined: dict
    moved: int


def plan_stray_shells(shells: dict, spacing: float) -> StrayPlan:
    """Where the shells other than each piece's largest go (``shells``: piece -> closed
    Manifolds of one shell each, none empty, the body's frame [m]): to the largest shell they
    touch over CONTACT_AREA_FACTOR, their own piece's where they touch it so, else the other
    piece's they touch most (MOVED_VOLUME_SHARE); bits that touch no main shell stay apart."""
    volume = {id(shell): shell.volume() for mine in shells.values() for shell in mine}  # [m^3]
    shells = {k: sorted(mine, key=lambda shell: -volume[id(shell)]) for k, mine in shells.items()}
    strays = [(k, bit) for k, mine in shells.items() for bit in mine[1:]]
    mains = {k: mine[0] for k, mine in shells.items()}
    main_triangles = {}  # piece -> its main shell's triangles (F,3,3) [m], once asked for
    gap, least = CONTACT_GAP_FACTOR * spacing, CONTACT_AREA_FACTOR * spacing**2
    joined = {k: [] for k in shells}
    apart = {k: [] for k in shells}
    moved = 0

    def contact(mesh, j):
        """The faces of ``mesh`` touching piece j's main shell and their area [m^2]."""
        box = np.asarray(mains[j].bounding_box()).reshape(2, 3)
        if not (np.all(mesh.bounds[0] <= box[1] + gap) and np.all(box[0] <= mesh.bounds[1] + gap)):
            return np.zeros(0, dtype=np.int64), 0.0
        if j not in main_triangles:
            main_triangles[j] = _trimesh(mains[j]).triangles
        faces = _touching(mesh, main_triangles[j], gap)
        return faces, float(mesh.area_faces[faces].sum())

    for k, bit in strays:
        mesh = _trimesh(bit)
        faces, area = contact(mesh, k)
        target = k
        if area < least:  # (its own piece first: its tets say the bit is that piece's)
            others = [(j, *contact(mesh, j)) for j in mains
                      if j != k and volume[id(bit)] <= MOVED_VOLUME_SHARE * volume[id(mains[j])]]
            target, faces, area = max(others, key=lambda item: item[2], default=(k, faces, area))
        if area < least:
            apart[k].append(bit)
            continue
        joined[target].append((bit, mesh, faces))
        moved += target != k
    return StrayPlan(mains, apart, joined, moved)


def planned_solids(plan: StrayPlan) -> dict:
    """Piece -> its shells as ``plan`` gives them out (main, joined bits, bits apart), as one
    Manifold without the bridges: each piece's volume but for theirs (prisms CONTACT_GAP_FACTOR
    spacings deep)."""
    result = {}
    for k, main in plan.mains.items():
        shells = [main, *(bit for bit, _, _ in plan.joined[k]), *plan.apart[k]]
        result[k] = shells[0] if len(shells) == 1 else m3.Manifold.compose(shells)
    return result


def join_planned_shells(plan: StrayPlan, spacing: float) -> dict:
    """Piece -> its solid: ``plan``'s joined bits bridged to its main shell, its bits apart
    beside it. The bridge: prisms over the bit's faces that touch the main shell
    (CONTACT_GAP_FACTOR), reaching through the gap into both."""
    from .solid import without_dust

    gap = CONTACT_GAP_FACTOR * spacing
    result = {}
    for k, main in plan.mains.items():
        parts = [main, *plan.apart[k]]
        if plan.joined[k]:
            joining = [solid for bit, mesh, faces in plan.joined[k] for solid in (bit, _bridge(mesh, faces, gap))]
            parts[:1] = without_dust(m3.Manifold.batch_boolean([main, *joining], m3.OpType.Add), spacing)
        result[k] = parts[0] if len(parts) == 1 else m3.Manifold.compose(parts)
    return result


def without_crumbs(mine, spacing: float) -> list:
    """A piece's parts less those under CRUMB_VOLUME_FACTOR spacings cubed or CRUMB_VOLUME_SHARE
    of the largest beside it: wedges where two cracks' slabs cross near the surface, chips
    where a divided part's cell faces do, each a separate shell that would travel with the
    piece."""
    largest = max((part.volume() for part in mine), default=0.0)
    least = max(CRUMB_VOLUME_FACTOR * spacing**3, CRUMB_VOLUME_SHARE * largest)
    return [part for part in mine if part.volume() >= least or part.volume() == largest]


def _trimesh(solid: m3.Manifold):
    import trimesh

    from .solid import solid_arrays

    props, triangles = solid_arrays(solid)
    return trimesh.Trimesh(props[:, :3], triangles, process=False)


def _touching(mesh, triangles: np.ndarray, gap: float) -> np.ndarray:
    """Indices of ``mesh``'s faces whose centres lie within ``gap`` [m] of the surface of
    ``triangles`` (F,3,3) [m]: each centre measured to the triangles whose boxes (grown by
    ``gap``) it is in. The candidates come from a k-d tree of the centres, each box's cube
    about its middle: testing every pair at once grows as the product of the two face
    counts, and stray shells of thousands of faces meet main shells of thousands."""
    from scipy.spatial import cKDTree
    from trimesh.triangles import closest_point

    none = np.zeros(0, dtype=np.int64)
    centres = mesh.triangles_center
    low, high = triangles.min(axis=1) - gap, triangles.max(axis=1) + gap
    near = np.all((low <= mesh.bounds[1]) & (high >= mesh.bounds[0]), axis=1)
    triangles, low, high = triangles[near], low[near], high[near]
    if not len(triangles):
        return none
    # (a hair wider than each box's half side: the exact test below decides)
    reach = 0.5 * (high - low).max(axis=1) * (1.0 + 1e-9) + 1e-12
    lists = cKDTree(centres).query_ball_point(0.5 * (low + high), r=reach, p=np.inf)
    counts = np.fromiter(map(len, lists), dtype=np.int64, count=len(lists))
    if not counts.sum():
        return none
    point = np.concatenate([np.asarray(found, dtype=np.int64) for found in lists if found])
    triangle = np.repeat(np.arange(len(triangles)), counts)
    inside = np.all((centres[point] >= low[triangle]) & (centres[point] <= high[triangle]), axis=1)
    point, triangle = point[inside], triangle[inside]
    if not len(point):
        return none
    distance = np.linalg.norm(closest_point(triangles[triangle], centres[point]) - centres[point], axis=1)
    return np.unique(point[distance <= gap])


#: A bridge's faces whose normals differ by less than COPLANAR_NORMAL [rad] and whose planes
#: by less than COPLANAR_OFFSET [gap] share one prism: a crack's faces lie in one plane,
#: and a prism over their union is the union of theirs (moved by at most that much).
COPLANAR_NORMAL = 1e-9
COPLANAR_OFFSET = 1e-3


def _bridge(mesh, faces: np.ndarray, gap: float) -> m3.Manifold:
    """Prisms over ``mesh``'s ``faces`` from ``gap`` [m] inside the bit to twice it outside,
    across the gap into the shell it touches. Their faces lie on no crack (HULL_FACE, like a
    carved piece's): in the gap, and where a contact face meets the artist's surface, out of
    it by at most twice ``gap``. The faces in one plane share one prism over their union (a
    2D union, then one extrusion): the same solid as a prism per face, whose side walls on
    side walls are the boolean library's slowest union."""
    from .layout import CRACK, HULL_FACE
    from .solid import with_crack_index

    faces = faces[mesh.area_faces[faces] > 0.0]  # (a face of no area has no normal to extrude along)
    normal = mesh.face_normals[faces]
    corners = mesh.triangles[faces]
    offset = np.einsum("ij,ij->i", normal, corners[:, 0])
    key = np.round(np.c_[normal / COPLANAR_NORMAL, offset / (COPLANAR_OFFSET * gap)]).astype(np.int64)
    _, plane = np.unique(key, axis=0, return_inverse=True)
    plane = plane.ravel()
    prisms = []
    for p in range(plane.max(initial=-1) + 1):
        group = np.nonzero(plane == p)[0]
        n = normal[group[0]]
        e1 = corners[group[0], 1] - corners[group[0], 0]
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        # (counter-clockwise about n in the (e1, e2) frame, as about the outward normal)
        flat = [np.c_[(tri - corners[group[0], 0]) @ e1, (tri - corners[group[0], 0]) @ e2] for tri in corners[group]]
        area = m3.CrossSection(flat, m3.FillRule.Positive)
        if area.is_empty():
            continue
        frame = np.c_[e1, e2, n, corners[group[0], 0] - gap * n]  # (3,4): the prism's frame in the body's
        prisms.append(with_crack_index(m3.Manifold.extrude(area, 3.0 * gap).transform(frame), HULL_FACE))
    bridge = m3.Manifold.batch_boolean(prisms, m3.OpType.Add) if prisms else m3.Manifold()
    # The union of nearly coplanar prisms can leave a vertex without properties (NaN), which
    # would read as the artist's surface without its UVs: it is a hull face's like the rest.
    mesh = bridge.to_mesh64()
    props = np.array(mesh.vert_properties, dtype=np.float64, order="C")
    missing = np.isnan(props[:, 3:]).any(axis=1)
    if not missing.any():
        return bridge
    props[missing, 3:] = 0.0
    props[missing, CRACK] = HULL_FACE
    # (copies: the binding takes no read-only views of the library's own arrays)
    return m3.Manifold(m3.Mesh64(vert_properties=props, tri_verts=np.array(mesh.tri_verts, dtype=np.uint64),
                                 merge_from_vert=np.array(mesh.merge_from_vert, dtype=np.uint64),
                                 merge_to_vert=np.array(mesh.merge_to_vert, dtype=np.uint64)))
