"""Which piece each part of a cut render solid goes to (surfaces/cut.py cuts it):
a vote of its faces for the nearest tets' piece, dividing a part that holds two pieces'
material by their tets' nearest-centroid cells, carving a piece no part went to out of the
part holding its tets, and the checks that send a piece the cut failed back to its tets'
boundary. Plain numpy and scipy on the parts' meshes; ``manifold3d`` for their volumes.
"""

from __future__ import annotations

import manifold3d as m3
import numpy as np

from .solid import difference, solid_arrays, with_crack_index
from .tet_cells import LOCAL_DIAGRAM_FACTOR, own_cells, voronoi_cells
from .trees import centroid_tree

#: A part's vote reads at most about this many of its faces (evenly spread over its list).
MAX_VOTING_FACES = 256
#: A vote whose winner has less than this share of the area is settled by the tets inside.
DECISIVE_VOTE = 0.8
#: How many tets in a part's box that check reads at most.
MAX_PROBED_TETS = 64
#: A piece whose parts hold less than this share of its tets' volume lost its material to a
#: neighbour (the slabs left a gap in the wall between them): it gets its tets' boundary.
LOST_VOLUME_SHARE = 0.5
#: A piece of PARTLY_LOST_TETS tets or more whose parts hold less than PARTLY_LOST_SHARE of
#: its tets' volume, and leave out a tet centroid farther than PARTLY_LOST_DEPTH [particle
#: spacings] (plus the crack faces' noise amplitude) from those they hold, has the rest
#: carved out of the other piece's part holding it (rough cracks meeting at a point gave a
#: third of a 170-tet piece to its neighbour so). A crack face moved past a layer of its
#: centroids leaves out only centroids beside held ones.
PARTLY_LOST_SHARE = 0.9
PARTLY_LOST_TETS = 100
PARTLY_LOST_DEPTH = 1.5
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
#: Rough crack faces move a piece's volume by their noise's mean over its faces: at most
#: this share of the amplitude times its surface area is not counted as gained, so a small
#: piece where rough cracks meet does not read as overfull and fail its neighbours.
NOISE_VOLUME_SHARE = 0.25


def _winding_inside(points: np.ndarray, solid: m3.Manifold) -> np.ndarray:
    """(N,) bool: ``points`` (N,3) inside the closed ``solid``."""
    from .checks import inside

    props, triangles = solid_arrays(solid)
    return inside(points, props[:, :3][triangles])


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
    nearest tet centroid and nearer another piece's (a vertex that far from every tet, where
    the surface has detail the tets leave out, is its nearest piece's), and those of the
    pieces owning the tets nearest those vertices (the material it took) whose tets' volume
    is less than 1 / SWALLOWED_VOLUME_SHARE times the volume the first rendered beyond its
    own tets' (else its loss is too small to see). ``corners``: id(part) -> (part, its
    vertices), where known."""
    failed = set()
    for k in sorted({o for o in owner if o >= 0}):
        mine = np.nonzero(labels == k)[0]
        if not len(mine):
            continue
        vertices = np.concatenate([_vertices(p, corners) for p, o in zip(parts, owner) if o == k])
        nearest = _far_owners(vertices, model, labels, k, spacing)
        if np.all(nearest == k):
            continue
        failed.add(k)
        excess = sum(p.volume() for p, o in zip(parts, owner) if o == k) - float(model.tet_volume[mine].sum())
        for victim in np.unique(nearest):
            if victim >= 0 and excess > SWALLOWED_VOLUME_SHARE * float(model.tet_volume[labels == victim].sum()):
                failed.add(int(victim))
    return failed


def _far_owners(vertices: np.ndarray, model, labels, k: int, spacing: float) -> np.ndarray:
    """The pieces (labels) of the tets nearest those of ``vertices`` (N,3) [m] that lie
    farther than OVERREACH_FACTOR spacings from every centroid of piece ``k``'s tets: where
    the piece reaches (a vertex that far from every tet, where the surface has detail the
    tets leave out, is its nearest piece's)."""
    far = vertices[centroid_tree(model, labels, k).query(vertices)[0] > OVERREACH_FACTOR * spacing]
    return labels[centroid_tree(model).query(far)[1]] if len(far) else np.zeros(0, dtype=labels.dtype)


def overfull_pieces(parts, owner, model, labels, spacing, roughness: float = 0.0) -> set[int]:
    """Pieces whose parts hold more than their tets' volume by GAINED_VOLUME_SHARE of it and
    GAINED_VOLUME_FACTOR spacings cubed, beyond what rough crack faces can add
    (NOISE_VOLUME_SHARE x ``roughness`` [m], the noise amplitude, x the parts' surface
    area), and those of the pieces with
    tets inside those parts whose tets' volume is less than 1 / SWALLOWED_VOLUME_SHARE times
    that excess."""
    failed = set()
    for k in sorted({o for o in owner if o >= 0}):
        mine = [part for part, o in zip(parts, owner) if o == k]
        own = float(model.tet_volume[labels == k].sum())
        excess = sum(part.volume() for part in mine) - own
        noise = NOISE_VOLUME_SHARE * roughness * sum(part.surface_area() for part in mine)
        if not _gained(own + excess - noise, own, spacing):
            continue
        failed.add(k)
        for part in mine:
            props, triangles = solid_arrays(part)
            vertices = props[:, :3]
            held = _tets_inside(model, vertices.min(axis=0), vertices.max(axis=0), vertices[triangles])
            for victim in np.unique(labels[held]):
                if victim >= 0 and victim != k and excess > SWALLOWED_VOLUME_SHARE * float(
                        model.tet_volume[labels == victim].sum()):
                    failed.add(int(victim))
    return failed


def _rendered_volumes(parts, owner, count: int) -> np.ndarray:
    """(count,) [m^3] the volume of the ``parts`` each piece owns (``owner``: each part's
    piece, negative: none)."""
    rendered = np.zeros(count)
    for part, o in zip(parts, owner):
        if o >= 0:
            rendered[o] += part.volume()
    return rendered


def failed_pieces(parts, owner, model, fragment_tets) -> set[int]:
    """Pieces the cut failed, to be given their tets' boundary: those whose parts hold less
    than LOST_VOLUME_SHARE of their tets' volume after ``carve_lost_pieces`` (no other
    piece's part held their tets, or carving them out of it left nothing), and the piece
    that got the part holding a lost piece's tets when the volume it gained is more than
    SWALLOWED_VOLUME_SHARE of its own. A piece with no part at all was carved already or
    has no render solid."""
    rendered = _rendered_volumes(parts, owner, len(fragment_tets))
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


def carve_lost_pieces(parts, owner, model, fragment_tets, labels, spacing, roughness: float = 0.0):
    """A piece no part went to (a few tets where cracks meet, smaller than the planes can
    resolve), or whose parts hold less than LOST_VOLUME_SHARE of its tets' volume while
    another piece's part holds its tets (the slabs left a gap in the wall between them and
    the vote gave the material on both sides to the other), is carved out of the part
    holding its tets; so is a piece of PARTLY_LOST_TETS or more under PARTLY_LOST_SHARE
    whose parts leave out a chunk of its tets (deeper than PARTLY_LOST_DEPTH spacings plus
    the crack faces' noise amplitude ``roughness`` [m]), out of the part holding the tets
    its own parts do not: the part's intersection with its tets' nearest-centroid cells
    (``_carved``) becomes the piece (owner -(k + 2)), the rest stays. Its faces inside the part are then the
    cells', not a crack's: counted in the stats. The carving can cut the rest in two or more:
    the largest stays with its owner, the others are voted for again (a chip beyond it
    belongs to the tets around it)."""
    from scipy.spatial import cKDTree

    from .solid import without_dust

    parts, owner = list(parts), list(owner)
    rendered = _rendered_volumes(parts, owner, len(fragment_tets))
    volumes = [float(model.tet_volume[np.asarray(tets)].sum()) for tets in fragment_tets]
    lost = [k for k in range(len(fragment_tets)) if k not in owner or rendered[k] < LOST_VOLUME_SHARE * volumes[k]]
    partly = [k for k, tets in enumerate(fragment_tets) if k not in lost and len(tets) >= PARTLY_LOST_TETS
              and rendered[k] < PARTLY_LOST_SHARE * volumes[k]]
    for k in lost + partly:
        tets = np.asarray(fragment_tets[k], dtype=np.int64)
        if k in partly:  # (the tets its own parts do not hold)
            held = np.zeros(len(tets), dtype=bool)
            for part, o in zip(parts, owner):
                if o == k:
                    held |= _winding_inside(model.particle_position[tets], part)
            # (a face moved past a layer of its centroids leaves them out beside the held ones:
            # not lost)
            if held.all() or not held.any() or cKDTree(model.particle_position[tets[held]]).query(
                    model.particle_position[tets[~held]])[0].max() <= PARTLY_LOST_DEPTH * spacing + roughness:
                continue
            tets = tets[~held]
        best = _part_holding(_probe_points(model, tets), parts)
        if best is None or owner[best] == k:
            continue
        taker = -(owner[best] + 2) if owner[best] < -1 else owner[best]
        carved, rest = _carved(parts[best], model, labels, k, [taker, *lost], spacing)
        if carved.is_empty():
            continue
        rest = sorted(without_dust(rest, spacing), key=lambda part: -part.volume())
        parts[best] = rest[0] if rest else m3.Manifold()  # (the bulk stays its owner's)
        parts += rest[1:]
        owner += assign_parts(rest[1:], model, labels, spacing)
        bits = without_dust(carved, spacing)
        parts += bits
        owner += [-(k + 2)] * len(bits)
    keep = [j for j, part in enumerate(parts) if not part.is_empty()]
    return [parts[j] for j in keep], [owner[j] for j in keep]


def _carved(part: m3.Manifold, model, labels, k: int, holders, spacing: float):
    """(carved, rest): the share of ``part`` in piece ``k``'s tets' nearest-centroid cells,
    and the part less those cells (one boolean makes both: ``Manifold.split``). The cells
    are drawn against the tets of the pieces whose material the
    part may hold, ``holders`` (its owner and the lost pieces): another piece is parted from
    ``k`` by a slab already, and cells drawn against it would cut ``k`` again along the
    staircase, a layer short (a 170-tet piece 7 % short). Where the share so carved reaches
    farther than OVERREACH_FACTOR spacings from ``k``'s tets, or holds well over their
    volume (the part holds another piece's material beyond a gap), the cells are drawn
    against every tet instead. Where the diagram is degenerate, the convex hull of ``k``'s
    tets."""
    from .layout import HULL_FACE

    mine = np.nonzero(labels == k)[0]
    own = float(model.tet_volume[mine].sum())
    carved = rest = cells = None
    pools = [np.nonzero(np.isin(labels, [k, *holders]))[0]]
    if len(pools[0]) < len(labels):  # (when those are every tet, the first carve is the last)
        pools.append(np.arange(len(labels)))
    for pool in pools:
        cells = own_cells(model, labels, k, spacing, pool)
        if cells is None:
            break
        carved, rest = part.split(cells)
        vertices = np.asarray(carved.to_mesh64().vert_properties)[:, :3]
        foreign = np.any(_far_owners(vertices, model, labels, k, spacing) != k)
        if not foreign and not _gained(carved.volume(), own, spacing):
            return carved, rest
    if cells is None:
        cells = with_crack_index(m3.Manifold.hull_points(
            np.ascontiguousarray(model.vertices[model.tets[mine]].reshape(-1, 3))), HULL_FACE)
        carved, rest = part.split(cells)
    return carved, rest


def assign_parts(parts, model, labels, spacing, corners=None) -> list[int]:
    """The piece (label) each connected part belongs to: an area-weighted vote of its faces,
    each probed a quarter spacing inside the part, for the piece of the nearest tet centroid
    (-1: dropped tets). Each part's vertices go into ``corners`` (by id) when given."""
    tree = centroid_tree(model)
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
    from .checks import inside

    in_box = np.nonzero(np.all((model.particle_position >= low) & (model.particle_position <= high), axis=1))[0]
    in_box = in_box[:: max(1, len(in_box) // MAX_PROBED_TETS)]
    return in_box[inside(model.particle_position[in_box], triangles)]


#: Where a piece's part reaches past OVERREACH_FACTOR spacings from its tets, the part is
#: divided by the tets' owners: the cells (nearest-centroid regions) of the other pieces'
#: tets go to those pieces, except those within this [particle spacings] of its own tets and
#: of one of its crack faces (the flat face crosses the tets' staircase there).
FOREIGN_DEPTH_FACTOR = 1.0
#: How far [particle spacings] the solid given to a piece the cut failed reaches into the
#: other pieces' cells (what those pieces hold is then taken away: their crack faces bound it;
#: what they do not hold there, between their crack faces and its cells, is its).
SHARE_REACH_FACTOR = 2.5
#: How many times the parts cut off are checked and divided again (a part cut off and voted
#: to a piece can reach past that piece's tets in turn).
DIVIDE_ROUNDS = 3


def divide_joined_parts(parts, owner, model, labels, spacing, corners):
    """Divide the parts that hold another piece's material (the artist's surface joins two
    pieces across a gap their tets leave open, or a slab stopped short of the surface): of
    each part reaching farther than OVERREACH_FACTOR spacings from its owner's tets, the
    material in the nearest-centroid (Voronoi) cells of other pieces' tets is cut off: the
    cells holding the corners that reach past, and those joined to them of centroids farther
    than FOREIGN_DEPTH_FACTOR spacings from the owner's. Each other piece gets the share in
    its own cells; what is left is voted for again (``assign_parts``). Up to DIVIDE_ROUNDS
    times, every part this made checked again. The cut faces lie on no crack (HULL_FACE).
    Returns (parts, owner, the pieces given material cut off another's part); new parts'
    vertices go into ``corners``."""
    limit = OVERREACH_FACTOR * spacing
    everyone = centroid_tree(model)
    parts, owner = list(parts), list(owner)
    received = set()

    def divide(j, holding, depth):
        """Divide part j (see _divide_part); True when it changed, and what it cut off and
        the rest are then queued in ``cut_off``."""
        k = owner[j]
        result = _divide_part(parts[j], k, holding, depth, model, labels, spacing, corners,
                              centroid_tree(model, labels, k))
        if result is None:
            return False
        for index, (bit, vote) in enumerate(zip(*result)):
            if index == 0:
                parts[j], owner[j] = bit, vote
            else:
                parts.append(bit)
                owner.append(vote)
            cut_off.append(j if index == 0 else len(parts) - 1)  # (the rest too: new corners can reach past)
            if vote != k:
                received.add(vote)
        return True

    fresh = list(range(len(parts)))  # the parts to check this round
    for _ in range(DIVIDE_ROUNDS):
        cut_off = []
        for j in fresh:
            k = owner[j]
            if k < 0:
                continue
            vertices = _vertices(parts[j], corners)
            reach = centroid_tree(model, labels, k).query(vertices)[0]
            if reach.max() <= limit:
                continue
            # The cells of the other pieces' centroids nearest the corners reaching past.
            holding = np.unique(everyone.query(vertices[reach > limit])[1])
            holding = holding[(labels[holding] != k) & (labels[holding] >= 0)]
            if len(holding):
                divide(j, holding, FOREIGN_DEPTH_FACTOR)
        if not cut_off:
            break
        fresh = cut_off
    return parts, owner, received


def _divide_part(part, k, holding, depth, model, labels, spacing, corners, own_tree):
    """Part ``part`` of piece ``k`` less the nearest-centroid cells of other pieces' centroids:
    those ``holding`` (indices, whatever their depth; None: every cell that reaches the part)
    and those joined face to face to them of centroids in the part's box farther than
    ``depth`` spacings from k's (``own_tree``: their KD-tree). Returns (bits, votes): the rest
    (its parts voted for again) then each other piece's share in its own cells, or None when
    nothing changes."""
    from scipy.spatial import cKDTree

    from .layout import CRACK
    from .solid import without_dust

    centroids = model.particle_position
    vertices = _vertices(part, corners)
    low, high = vertices.min(axis=0) - spacing, vertices.max(axis=0) + spacing
    near = np.nonzero(np.all((centroids >= low) & (centroids <= high), axis=1) & (labels != k) & (labels >= 0))[0]
    # A centroid within ``depth`` of k's is left where it is that near one of the part's crack
    # faces (the flat face crosses the tets' staircase there), taken elsewhere (no crack
    # between the two pieces' tets there: their cells' faces are the boundary).
    shallow = np.nonzero(own_tree.query(centroids[near])[0] <= depth * spacing)[0]
    props, tri_verts = solid_arrays(part)
    crack_faces = tri_verts[(props[tri_verts, CRACK] >= 0).all(axis=1)]
    if len(shallow) and len(crack_faces):
        import trimesh

        faces = trimesh.Trimesh(props[:, :3], crack_faces, process=False)
        by_crack = trimesh.proximity.closest_point(faces, centroids[near[shallow]])[1] <= depth * spacing
        near = np.delete(near, shallow[by_crack])
    # Only the cells that can reach the part: of centroids inside it, or nearer its surface
    # than their cell's farthest corner (within LOCAL_DIAGRAM_FACTOR / 2).
    to_surface = cKDTree(vertices).query(centroids[near])[0]
    close = to_surface < 0.5 * LOCAL_DIAGRAM_FACTOR * spacing
    close[~close] = _inside_solid(centroids[near[~close]], part, 0.1 * spacing)
    near, to_surface = near[close], to_surface[close]
    seeds = near if holding is None else np.union1d(near, holding)
    if not len(seeds):
        return None
    # The diagram of the centroids about those only: a cell depends on its neighbours alone,
    # which lie within twice its reach.
    around = np.nonzero(np.all((centroids >= low - LOCAL_DIAGRAM_FACTOR * spacing)
                               & (centroids <= high + LOCAL_DIAGRAM_FACTOR * spacing), axis=1))[0]
    around = np.union1d(around, seeds)
    local = around[cKDTree(centroids[seeds]).query(centroids[around])[0] <= LOCAL_DIAGRAM_FACTOR * spacing]
    cells = voronoi_cells(centroids[local], spacing)
    near_local = np.searchsorted(local, near)  # (local is sorted and holds every one of them)
    touching = to_surface < cells.radius(near_local)
    touching[~touching] = _inside_solid(centroids[near[~touching]], part, 0.1 * spacing)
    near = near_local[touching]
    if holding is not None:
        # Only the cells joined to those holding the corners reaching past: islands of cells
        # about the depth's edge stay with the part.
        holding = np.searchsorted(local, holding)
        near = cells.joined(np.union1d(near, holding), holding)
    foreign = cells.union(near) if len(near) else None
    if foreign is None:
        return None
    bits = without_dust(part - foreign, spacing)
    votes = assign_parts(bits, model, labels, spacing, corners)
    others = np.unique(labels[local[near]])
    shares = [cells.union(near[labels[local[near]] == other]) for other in others]
    if any(share is None for share in shares):  # (a degenerate diagram: the bits are voted for)
        shares, others = [foreign], None
    for index, share in enumerate(shares):
        share = without_dust(part ^ share, spacing)
        bits += share
        votes += (assign_parts(share, model, labels, spacing, corners) if others is None
                  else [int(others[index])] * len(share))
    if not bits or (len(bits) == 1 and votes[0] == k):
        return None
    return bits, votes


def _inside_solid(points: np.ndarray, solid: m3.Manifold, size: float) -> np.ndarray:
    """(N,) bool: ``points`` (N,3) [m], each farther than ``size`` [m] from the surface of the
    closed ``solid``, inside it: a tetrahedron ``size`` across about each point, cut by the
    solid (``_probed_inside``). A point farther from the surface than its tetrahedron reaches
    holds all of it or none, so there the winding number gives the same answer for a
    fraction of the cost; only the points nearer the surface are probed."""
    import igl

    from .checks import inside

    result = np.zeros(len(points), dtype=bool)
    if not len(points):
        return result
    props, triangles = solid_arrays(solid)
    vertices = np.ascontiguousarray(props[:, :3])
    points = np.ascontiguousarray(points, dtype=np.float64)
    squared = np.asarray(igl.point_mesh_squared_distance(points, vertices, triangles)[0])
    # (a tetrahedron of half-width h/2 reaches sqrt(3) h/2 from its centre: under ``size``)
    far = squared > size**2
    result[far] = inside(points[far], vertices[triangles])
    result[~far] = _probed_inside(points[~far], solid, size)
    return result


def _probed_inside(points: np.ndarray, solid: m3.Manifold, size: float) -> np.ndarray:
    """(N,) bool: whether the tetrahedron ``size`` [m] across about each of ``points`` (N,3)
    [m] meets the closed ``solid``, all cut by the solid in one boolean."""
    from scipy.spatial import cKDTree

    result = np.zeros(len(points), dtype=bool)
    if not len(points):
        return result
    tetrahedron = m3.Manifold.tetrahedron().scale((0.5 * size,) * 3)
    probes = m3.Manifold.compose([tetrahedron.translate(tuple(point)) for point in points])
    kept = (solid ^ probes).decompose()
    if kept:
        centres = np.array([np.asarray(bit.bounding_box()).reshape(2, 3).mean(axis=0) for bit in kept])
        result[cKDTree(points).query(centres)[1]] = True
    return result


def _gained(rendered: float, own: float, spacing: float) -> bool:
    """Whether a piece whose parts hold ``rendered`` [m^3] against its tets' ``own`` [m^3]
    holds a neighbour's material (GAINED_VOLUME_SHARE and GAINED_VOLUME_FACTOR)."""
    excess = rendered - own
    return excess > GAINED_VOLUME_SHARE * own and excess > GAINED_VOLUME_FACTOR * spacing**3


def _vertices(part, corners) -> np.ndarray:
    """(N,3) [m] a part's vertices, from ``corners`` where the vote kept them."""
    known = corners.get(id(part))
    return known[1] if known is not None and known[0] is part else np.asarray(part.to_mesh64().vert_properties)[:, :3]


def failed_piece_shells(solid: m3.Manifold, model, labels, k: int, failed, parts, owner, spacing: float) -> list:
    """The shells of the render ``solid`` (the body's, uncut) that piece ``k``, one the cut
    ``failed``, gets: its share nearest its tets (``nearest_cells_share``) less the ``parts``
    of the pieces the cut did not fail (``owner``: each part's piece), so that against them
    its faces are their crack faces; shells under the dust volume, and those with no vertex
    within OVERREACH_FACTOR spacings of its tets (material no piece kept beyond its
    neighbours' parts), left out. Empty where the diagram is degenerate."""
    from .solid import without_dust

    share = nearest_cells_share(solid, model, labels, k, failed, spacing)
    if share is None:
        return []
    box = np.asarray(share.bounding_box())
    kept = [p for p, o in zip(parts, owner) if o >= 0 and o not in failed
            and np.all(np.asarray(p.bounding_box())[:3] <= box[3:]) and np.all(np.asarray(p.bounding_box())[3:] >= box[:3])]
    share = difference(share, kept)
    tree = centroid_tree(model, labels, k)
    return [shell for shell in without_dust(share, spacing)
            if tree.query(_vertices(shell, {}))[0].min() <= OVERREACH_FACTOR * spacing]


def nearest_cells_share(solid: m3.Manifold, model, labels, k: int, among, spacing: float):
    """The part of ``solid`` nearer piece ``k``'s tet centroids than those of any other piece
    of ``among`` (labels, k's included) and than the other tets farther than
    SHARE_REACH_FACTOR spacings from those pieces' (so it reaches at most about that far
    into the others' material, which the caller takes away): the union of k's cells in the
    Voronoi diagram of those centroids (HULL_FACE faces), or None where it is degenerate.
    The surface of a piece the cut failed (``among``: those it failed)."""
    from scipy.spatial import cKDTree

    centroids = model.particle_position
    failed = np.isin(labels, list(among))
    rest = np.nonzero(~failed)[0]
    beyond = rest[cKDTree(centroids[failed]).query(centroids[rest])[0] > SHARE_REACH_FACTOR * spacing]
    region = own_cells(model, labels, k, spacing, np.union1d(np.nonzero(failed)[0], beyond))
    if region is None:
        return None
    share = solid ^ region
    return None if share.is_empty() else share
