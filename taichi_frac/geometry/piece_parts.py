"""Which piece each part of a cut render solid goes to (geometry/piece_surface.py cuts it):
a vote of its faces for the nearest tets' piece, carving a piece no part went to out of the
part holding its tets, and the checks that send a piece the cut failed back to its tets'
boundary. Plain numpy and scipy on the parts' meshes; ``manifold3d`` for their volumes.
"""

from __future__ import annotations

import manifold3d as m3
import numpy as np

#: A part's vote reads at most about this many of its faces (evenly spread over its list).
MAX_VOTING_FACES = 256
#: A vote whose winner has less than this share of the area is settled by the tets inside.
DECISIVE_VOTE = 0.8
#: How many tets in a part's box that check reads at most.
MAX_PROBED_TETS = 64
#: A piece whose parts hold less than this share of its tets' volume lost its material to a
#: neighbour (the slabs left a gap in the wall between them): it gets its tets' boundary.
LOST_VOLUME_SHARE = 0.5
#: The piece whose part holds a lost piece's tets gets its tets' boundary too when the lost
#: volume is more than this share of its own tets' volume (else it would carry it along).
SWALLOWED_VOLUME_SHARE = 0.05
#: A piece whose render solid reaches farther than this [particle spacings] from its nearest
#: tet centroid holds another piece's material (the slabs ran past a crack's end or left a
#: gap): it and the pieces whose tets lie there get their tets' boundary. A flat crack face
#: through the tets' staircase reaches up to about one tet (edges ~2.2 spacings) past them.
OVERREACH_FACTOR = 5.0
#: A piece whose parts hold more than (1 + this) times its tets' volume, and more than
#: GAINED_VOLUME_FACTOR spacings cubed beyond it, holds a neighbour's material within that
#: reach: it gets its tets' boundary (the flat faces of a piece of a few tets differ from
#: its staircase by a few tets' volume, under that bound).
GAINED_VOLUME_SHARE = 0.25
GAINED_VOLUME_FACTOR = 10.0


def _winding_inside(points: np.ndarray, solid: m3.Manifold) -> np.ndarray:
    """(N,) bool: ``points`` (N,3) inside the closed ``solid``."""
    from .piece_checks import inside

    mesh = solid.to_mesh64()
    return inside(points, np.asarray(mesh.vert_properties)[:, :3][np.asarray(mesh.tri_verts, dtype=np.int64)])


def _part_holding(points: np.ndarray, parts) -> int | None:
    """The index of the part holding most of ``points`` (N,3) [m], None when none holds any."""
    best, best_count = None, 0
    for j, part in enumerate(parts):
        box = part.bounding_box()
        near = np.all((points >= np.asarray(box[:3])) & (points <= np.asarray(box[3:])), axis=1)
        if not near.any():
            continue
        count = int(_winding_inside(points[near], part).sum())
        if count > best_count:
            best, best_count = j, count
    return best


def _probe_points(model, tets: np.ndarray) -> np.ndarray:
    """About 16 of ``tets``' centroids [m], evenly spread over the list."""
    return model.particle_position[tets[:: max(1, len(tets) // 16)]]


def overreaching_pieces(parts, owner, model, labels, spacing, corners) -> set[int]:
    """Pieces whose parts have a vertex farther than OVERREACH_FACTOR spacings from their own
    nearest tet centroid, and those of the pieces owning the tets nearest those vertices (the
    material it took) whose tets' volume is less than 1 / SWALLOWED_VOLUME_SHARE times the
    volume the first rendered beyond its own tets' (else its loss is too small to see).
    ``corners``: id(part) -> (part, its vertices), where known."""
    from scipy.spatial import cKDTree

    limit = OVERREACH_FACTOR * spacing
    everyone = None
    failed = set()
    for k in sorted({o for o in owner if o >= 0}):
        mine = np.nonzero(labels == k)[0]
        if not len(mine):
            continue
        vertices = np.concatenate([corners[id(p)][1] if corners.get(id(p), (None,))[0] is p else
                                   np.asarray(p.to_mesh64().vert_properties)[:, :3]
                                   for p, o in zip(parts, owner) if o == k])
        far = vertices[cKDTree(model.particle_position[mine]).query(vertices)[0] > limit]
        if not len(far):
            continue
        everyone = cKDTree(model.particle_position) if everyone is None else everyone
        failed.add(k)
        excess = sum(p.volume() for p, o in zip(parts, owner) if o == k) - float(model.tet_volume[mine].sum())
        for victim in np.unique(labels[everyone.query(far)[1]]):
            if victim >= 0 and excess > SWALLOWED_VOLUME_SHARE * float(model.tet_volume[labels == victim].sum()):
                failed.add(int(victim))
    return failed


def overfull_pieces(parts, owner, model, labels, spacing) -> set[int]:
    """Pieces whose parts hold more than their tets' volume by GAINED_VOLUME_SHARE of it and
    GAINED_VOLUME_FACTOR spacings cubed, and those of the pieces with tets inside those parts
    whose tets' volume is less than 1 / SWALLOWED_VOLUME_SHARE times that excess."""
    failed = set()
    for k in sorted({o for o in owner if o >= 0}):
        mine = [part for part, o in zip(parts, owner) if o == k]
        own = float(model.tet_volume[labels == k].sum())
        excess = sum(part.volume() for part in mine) - own
        if excess <= GAINED_VOLUME_SHARE * own or excess <= GAINED_VOLUME_FACTOR * spacing**3:
            continue
        failed.add(k)
        for part in mine:
            mesh = part.to_mesh64()
            vertices = np.asarray(mesh.vert_properties)[:, :3]
            held = _tets_inside(model, vertices.min(axis=0), vertices.max(axis=0),
                                vertices[np.asarray(mesh.tri_verts, dtype=np.int64)])
            for victim in np.unique(labels[held]):
                if victim >= 0 and victim != k and excess > SWALLOWED_VOLUME_SHARE * float(
                        model.tet_volume[labels == victim].sum()):
                    failed.add(int(victim))
    return failed


def failed_pieces(parts, owner, model, fragment_tets) -> set[int]:
    """Pieces the cut failed, to be given their tets' boundary: those whose parts hold less
    than LOST_VOLUME_SHARE of their tets' volume (where the slabs leave a gap in the wall
    between two pieces, the part on both sides goes to one of them by the vote and the other
    keeps only chips), and the piece that got the part holding a lost piece's tets when the
    volume it gained is more than SWALLOWED_VOLUME_SHARE of its own. A piece with no part at
    all was carved already (``carve_missing_pieces``) or has no render solid."""
    rendered = np.zeros(len(fragment_tets))
    for part, o in zip(parts, owner):
        if o >= 0:
            rendered[o] += part.volume()
    failed = set()
    for k, tets in enumerate(fragment_tets):
        tets = np.asarray(tets, dtype=np.int64)
        own = float(model.tet_volume[tets].sum())
        if k not in owner or rendered[k] >= LOST_VOLUME_SHARE * own:
            continue
        failed.add(k)
        holder = _part_holding(_probe_points(model, tets), parts)
        if holder is None or owner[holder] < 0 or owner[holder] == k:
            continue
        taker = owner[holder]
        if own - rendered[k] > SWALLOWED_VOLUME_SHARE * float(model.tet_volume[np.asarray(fragment_tets[taker])].sum()):
            failed.add(taker)
    return failed


def carve_missing_pieces(parts, owner, model, fragment_tets, labels, spacing):
    """A piece no part went to (a few tets where cracks meet, smaller than the planes can
    resolve) is carved out of the part holding its tets: the part's intersection with the
    convex hull of its tets becomes the piece (owner -(k + 2)), the rest stays. Its faces
    inside the part are then the hull's planes, not a crack's: counted in the stats. The hull
    can cut the rest in two or more: the largest stays with its owner, the others are voted
    for again (a chip beyond the hull belongs to the tets around it)."""
    from .piece_surface import DUST_VOLUME_FACTOR, HULL_FACE, _with_crack_index

    parts, owner = list(parts), list(owner)
    for k, tets in enumerate(fragment_tets):
        if k in owner or -(k + 2) in owner:
            continue
        tets = np.asarray(tets, dtype=np.int64)
        best = _part_holding(_probe_points(model, tets), parts)
        if best is None:
            continue
        hull = _with_crack_index(
            m3.Manifold.hull_points(np.ascontiguousarray(model.vertices[model.tets[tets]].reshape(-1, 3))), HULL_FACE)
        carved = parts[best] ^ hull
        if carved.is_empty():
            continue
        rest = sorted((part for part in (parts[best] - hull).decompose()
                       if part.volume() >= DUST_VOLUME_FACTOR * spacing**3), key=lambda part: -part.volume())
        parts[best] = rest[0] if rest else m3.Manifold()  # (the bulk stays its owner's)
        parts += rest[1:]
        owner += assign_parts(rest[1:], model, labels, spacing)
        parts.append(carved)
        owner.append(-(k + 2))
    keep = [j for j, part in enumerate(parts) if not part.is_empty()]
    return [parts[j] for j in keep], [owner[j] for j in keep]


def assign_parts(parts, model, labels, spacing, corners=None) -> list[int]:
    """The piece (label) each connected part belongs to: an area-weighted vote of its faces,
    each probed a quarter spacing inside the part, for the piece of the nearest tet centroid
    (-1: dropped tets). Each part's vertices go into ``corners`` (by id) when given."""
    from scipy.spatial import cKDTree

    tree = cKDTree(model.particle_position)
    owners = []
    for part in parts:
        mesh = part.to_mesh64()
        vp = np.asarray(mesh.vert_properties)[:, :3]
        if corners is not None:
            corners[id(part)] = (part, vp)  # (the part kept alive: its id is not reused)
        tri_verts = np.asarray(mesh.tri_verts, dtype=np.int64)
        tri = vp[tri_verts[:: max(1, len(tri_verts) // MAX_VOTING_FACES)]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(normal, axis=1)
        normal /= np.maximum(2.0 * area[:, None], 1e-300)
        probe = tri.mean(axis=1) - 0.25 * spacing * normal
        _, nearest = tree.query(probe)
        votes = np.bincount(labels[nearest] + 1, weights=area)
        if votes.max() < DECISIVE_VOTE * votes.sum() and part.volume() >= spacing**3:
            # A thin part (three tets across a glass pane) can sit nearer a neighbour's tets
            # than its own: ask which tets' centroids it holds, by their volume. (Not for
            # chips under a spacing cubed: a refracture through a piece's hairline shells
            # leaves dozens, and which side owns one is invisible.)
            tets = _tets_inside(model, vp.min(axis=0), vp.max(axis=0), vp[tri_verts])
            if len(tets):
                votes = np.bincount(labels[tets] + 1, weights=model.tet_volume[tets])
        owners.append(int(np.argmax(votes)) - 1)
    return owners


def _tets_inside(model, low, high, triangles) -> np.ndarray:
    """Up to MAX_PROBED_TETS tets (evenly spread over those in the box ``low``..``high``
    (3,) [m]) whose centroids lie inside the closed surface ``triangles`` (F,3,3) [m]."""
    from .piece_checks import inside

    in_box = np.nonzero(np.all((model.particle_position >= low) & (model.particle_position <= high), axis=1))[0]
    in_box = in_box[:: max(1, len(in_box) // MAX_PROBED_TETS)]
    return in_box[inside(model.particle_position[in_box], triangles)]
