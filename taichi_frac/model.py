"""The static two-scale particle model of one rigid solid (BRIEF.md steps 1-3).

A :class:`BodyModel` is built once (for a scene object, or for a fragment when a body
breaks) and is read-only afterwards. Everything is in the **body frame**: origin at the
body's centre of mass, axes parallel to the source mesh's axes, metres.

Layers:
- physics particles: one per tet, at its centroid (stress analysis, fracture);
- surface particles: the physics particles whose tet has a boundary face;
- boundary particles: about ``boundary_group_size`` adjacent surface particles merged into
  one coarser sphere (collision detection and response); with surface contacts a large
  body may take a coarser n (``coarse_group_size``), since its spheres only find which
  patches may touch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import rows
from .geometry.mass import MassProperties, tet_mass_properties
from .geometry.collision_centres import CENTRE_REACH, contact_sphere_centres
from .geometry.contact_patches import ContactPatches, patches_of
from .geometry.rays import near_faces
from .geometry.surface_groups import group_surface_particles
from .geometry.topology import (
    bonds_from_neighbors,
    boundary_faces,
    compact_vertices,
    orient_tets,
    signed_volumes,
    tet_neighbors,
)


@dataclass(frozen=True, eq=False)
class BodyModel:
    """Static data of one rigid body. Shapes: T tets, V vertices, B bonds, F boundary faces,
    S surface particles, N boundary particles. Float arrays are float64, index arrays int32.

    Attributes:
        vertices: (V,3) [m] tet-mesh vertices, body frame.
        tets: (T,4) vertex indices, positively oriented.
        tet_volume: (T,) [m^3].
        tet_neighbor: (T,4) tet across face k (opposite vertex k) or -1 on the boundary.
        bonds: (B,2) face-sharing tet pairs i < j: the links a crack cuts.
        particle_position: (T,3) [m] physics particles (tet centroids).
        particle_mass: (T,) [kg] = density x tet volume.
        particle_radius: (T,) [m] = (3V / 4 pi)^(1/3).
        is_surface: (T,) bool, tet has a boundary face.
        surface_particles: (S,) tet indices of the surface particles.
        surface_faces: (F,3) boundary triangles (vertex indices, outward winding).
        surface_face_tet: (F,) tet owning each boundary triangle.
        surface_face_local: (F,) int8 local face index k within its tet.
        boundary_position: (N,3) [m] centroid of each boundary particle's members.
        boundary_mass: (N,) [kg] sum of its members' masses.
        boundary_radius: (N,) [m] smallest radius about boundary_position enclosing every
            member's sphere.
        boundary_member_offsets: (N+1,) CSR offsets into boundary_members.
        boundary_members: (M,) tet indices (surface particles) of each boundary particle.
        dropped_surface_particles: (D,) surface particles in no boundary particle
            (leftovers when keep_leftovers is False).
        density: [kg/m^3].
        mass: [kg], exact from the tets.
        inertia: (3,3) [kg m^2] about the centre of mass, body axes, exact from the tets.
        com_in_source: (3,) [m] where the body-frame origin lies in the source frame (the
            input mesh's frame for a scene object, the parent's body frame for a fragment).
        source_tet: (T,) index of each tet in the root solid's tet mesh (identity for a
            root body): lets a fragment tell crack faces from original surface.
        boundary_group_size: the n used to build the boundary layer.
        coarse_group_size: the n a body (or piece) of at least ``COARSE_MIN_SPHERES`` x n
            surface particles is grouped by instead (bodies that collide through their true
            surface, ``DynamicsOptions.surface_contact``: their spheres only find which
            patches may touch); smaller ones keep the finer n they were asked for. 0: none.
            Its pieces inherit it.
        particle_spacing: [m] mean V^(1/3) of the root solid's tets: the discretisation's
            particle spacing, which sets the SPH smoothing length (fracture). A fragment
            inherits its root's, so a particle keeps its neighbours when its body breaks.
        root: the root solid's model for a fragment (``source_tet`` indexes its tets),
            None for a root; derived data keyed by the root (the SPH neighbour lists) is
            restricted to a fragment instead of rebuilt.
        boundary_contact_position: (N,3) [m] where each boundary particle's sphere (radius
            boundary_radius) sits for collisions: moved inward along the group's outward
            normal until its outermost point lies on the true surface (so the coarse layer
            does not stand proud of the body), no further than keeps it inside the body
            behind it. None: collide at boundary_position. Use ``collision_position``.
    """

    vertices: np.ndarray
    tets: np.ndarray
    tet_volume: np.ndarray
    tet_neighbor: np.ndarray
    bonds: np.ndarray
    particle_position: np.ndarray
    particle_mass: np.ndarray
    particle_radius: np.ndarray
    is_surface: np.ndarray
    surface_particles: np.ndarray
    surface_faces: np.ndarray
    surface_face_tet: np.ndarray
    surface_face_local: np.ndarray
    boundary_position: np.ndarray
    boundary_mass: np.ndarray
    boundary_radius: np.ndarray
    boundary_member_offsets: np.ndarray
    boundary_members: np.ndarray
    dropped_surface_particles: np.ndarray
    density: float
    mass: float
    inertia: np.ndarray
    com_in_source: np.ndarray
    source_tet: np.ndarray
    boundary_group_size: int
    boundary_contact_position: np.ndarray | None = None
    coarse_group_size: int = 0
    particle_spacing: float | None = None
    root: BodyModel | None = None

    @property
    def collision_position(self) -> np.ndarray:
        """(N,3) [m] centres of the boundary spheres used for collision."""
        return self.boundary_position if self.boundary_contact_position is None else self.boundary_contact_position

    @property
    def boundary_patches(self) -> "ContactPatches":
        """The true surface under each boundary sphere (``contact_patches``), computed on
        first use and kept beside the model while it lives."""
        return patches_of([self], single=False)[0]

    @property
    def surface_particle_patches(self) -> "ContactPatches":
        """The same for the single-scale layer: one patch per surface particle."""
        return patches_of([self], single=True)[0]

    @property
    def spacing(self) -> float:
        """[m] ``particle_spacing``, or this model's own mean V^(1/3) when it is None."""
        if self.particle_spacing is not None:
            return float(self.particle_spacing)
        return float(np.mean(np.cbrt(self.tet_volume)))

    @property
    def tet_count(self) -> int:
        return len(self.tets)

    @property
    def surface_particle_count(self) -> int:
        return len(self.surface_particles)

    @property
    def boundary_particle_count(self) -> int:
        return len(self.boundary_mass)

    @property
    def volume(self) -> float:
        return float(self.tet_volume.sum())


def build_body_model(
    vertices: np.ndarray,
    tets: np.ndarray,
    density: float,
    *,
    boundary_group_size: int = 4,
    keep_leftovers: bool = True,
    source_tet: np.ndarray | None = None,
    coarse_group_size: int = 0,
) -> BodyModel:
    """Build the two-scale particle model of a tet set given in its source frame.
    ``coarse_group_size``: see :class:`BodyModel` (the body is grouped by it when it has
    enough surface particles and its patches keep their facets, ``COARSE_MIN_FACETED``;
    else by ``boundary_group_size``, and the model's ``coarse_group_size`` is 0).

    ``vertices`` (V,3) [m] and ``tets`` (T,4) may contain unused vertices and negatively
    oriented tets; both are cleaned. The result is recentred on the exact centre of mass.
    ``source_tet`` maps each tet to the root solid's tet mesh (for fragments).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise ValueError(f"need at least one tet as a (T, 4) index array, got shape {tets.shape}")
    vertices, tets, _ = compact_vertices(vertices, tets)
    tets = orient_tets(vertices, tets)
    vol = signed_volumes(vertices, tets)
    if np.any(vol <= 0):
        raise ValueError(f"{int(np.sum(vol <= 0))} degenerate (zero-volume) tets")
    neighbor = tet_neighbors(tets)
    piece_n = group_sizes([np.any(neighbor < 0, axis=1).sum()], boundary_group_size, coarse_group_size)
    source = np.arange(len(tets)) if source_tet is None else np.asarray(source_tet)

    def build(n):
        return _assemble(vertices, tets, vol, neighbor, np.array([0, len(tets)]), np.array([0, len(vertices)]),
                         density, n, keep_leftovers, source, spacing=float(np.mean(np.cbrt(vol))), root=None,
                         props=[None], coarse_group_size=coarse_group_size)[0]

    model = build(piece_n)
    if piece_n[0] != boundary_group_size and not keeps_facets([model])[0]:
        coarse_group_size = 0  # (nor for its pieces)
        model = build(np.array([boundary_group_size]))
    return model


#: A body grouped by its ``coarse_group_size`` keeps at least this many spheres: one of
#: fewer surface particles keeps the finer n, since a few large spheres over a small block
#: fold their patches round its edges and corners, where the patches lose their facets.
COARSE_MIN_SPHERES = 32


#: A body (``build_body_model``) keeps the coarse n only where at least this fraction of
#: its patches lie in a few planes (``ContactPatches.facets``), as the finer grouping's
#: all do; else it and its pieces keep the finer n: patches without facets fall back to
#: sphere contacts, which rest coarse bodies too high. Pieces are not tested: the patches
#: along their cracks (tet faces in steps) fold at any n.
COARSE_MIN_FACETED = 0.9


def keeps_facets(models) -> list[bool]:
    """Whether each of ``models`` has facets on at least ``COARSE_MIN_FACETED`` of its
    boundary patches (computed in one pass and kept with the models, ``patches_of``)."""
    return [bool(np.mean(np.any(np.linalg.norm(p.facets, axis=2) > 0.5, axis=1)) >= COARSE_MIN_FACETED)
            if len(p.facets) else True for p in patches_of(models, single=False)]


def group_sizes(surface_counts: np.ndarray, fine: int, coarse: int) -> np.ndarray:
    """The boundary grouping n of bodies of ``surface_counts`` (P,) surface particles:
    ``coarse`` for those with at least ``COARSE_MIN_SPHERES`` x ``coarse``, ``fine`` for the
    rest (and for all when ``coarse`` is 0 or ``fine`` is 1, single-scale). (P,) int64."""
    counts = np.asarray(surface_counts, dtype=np.int64)
    if coarse <= 0 or fine <= 1:
        return np.full(len(counts), fine, dtype=np.int64)
    return np.where(counts >= COARSE_MIN_SPHERES * coarse, coarse, fine).astype(np.int64)


def build_fragment_model(
    parent: BodyModel,
    tets: np.ndarray,
    *,
    boundary_group_size: int = 4,
    keep_leftovers: bool = True,
    coarse_group_size: int | None = None,
) -> BodyModel:
    """The model of the piece of ``parent`` made of its tets ``tets`` (ascending indices):
    ``build_fragment_models`` for one piece."""
    return build_fragment_models(parent, [tets], boundary_group_size=boundary_group_size,
                                 keep_leftovers=keep_leftovers, coarse_group_size=coarse_group_size)[0]


def build_fragment_models(
    parent: BodyModel,
    pieces,
    *,
    boundary_group_size: int = 4,
    keep_leftovers: bool = True,
    coarse_group_size: int | None = None,
) -> list[BodyModel]:
    """The models of the pieces of ``parent`` made of its tets ``pieces`` (a sequence of
    disjoint, ascending index arrays), each in the parent's body frame as source frame:
    the tets, mass properties and physics particles ``build_body_model`` would build from
    ``parent.vertices`` and ``parent.tets[piece]``, with the topology restricted from the
    parent's instead of rebuilt and the SPH discretisation (``particle_spacing``,
    ``root``) inherited.

    The boundary layer is inherited where the surface is the parent's: a parent group
    whose members are all in the piece and touch no crack face is kept as it was (the
    same sphere, and the same collision centre unless a crack face lies within reach of
    its inward ray), and only the surface particles along the cracks are grouped afresh.
    So a piece collides where its parent did the instant it is born, and the build costs
    in proportion to the crack, not to the piece's surface. ``coarse_group_size`` (default
    the parent's) chooses each piece's n from its own surface (``group_sizes``); a piece
    grouped by another n than its parent's is grouped afresh.

    The pieces of one split are built together: each step is one numpy pass over the
    rows of all of them (a piece's rows are contiguous, in the order its own build would
    have them), so a split pays numpy's per-call cost once rather than once a piece (most
    of a small chip's build cost). Every piece's model is
    the one it gets built alone, to the bit (tests/test_fracture_fragments.py)."""
    pieces = [np.asarray(p, dtype=np.int64) for p in pieces]
    for p in pieces:
        if p.ndim != 1 or len(p) == 0 or np.any(np.diff(p) <= 0):
            raise ValueError("each piece must be a non-empty ascending array of the parent's tet indices")
    if not pieces:
        return []
    piece_count = len(pieces)
    tet_start = np.zeros(piece_count + 1, dtype=np.int64)
    np.cumsum([len(p) for p in pieces], out=tet_start[1:])
    all_tets = np.concatenate(pieces)
    piece_of_tet = np.repeat(np.arange(piece_count), np.diff(tet_start))
    t_parent = parent.tet_count
    if all_tets.max() >= t_parent:
        raise ValueError(f"tet index {int(all_tets.max())} is out of range: the parent has {t_parent} tets")
    label = np.full(t_parent + 1, -1, dtype=np.int64)  # last slot: a boundary face's -1
    label[all_tets] = piece_of_tet
    if np.any(label[all_tets] != piece_of_tet):
        raise ValueError("the pieces overlap: a tet is in more than one")
    index = np.full(t_parent + 1, -1, dtype=np.int64)  # parent tet -> row of the batch
    index[all_tets] = np.arange(len(all_tets))

    # Each piece's own vertices, ascending (what compact_vertices keeps of each alone).
    v_parent = len(parent.vertices)
    key = piece_of_tet[:, None] * v_parent + parent.tets[all_tets]
    if piece_count * v_parent <= 8 * key.size + 1_000_000:
        used = np.zeros(piece_count * v_parent, dtype=bool)
        used[key.reshape(-1)] = True
        vertex_key = np.nonzero(used)[0]
        tets = (np.cumsum(used) - 1)[key]
    else:  # (many pieces of a large parent: a sort instead of a piece x vertex table)
        vertex_key, inverse = np.unique(key, return_inverse=True)
        tets = inverse.reshape(key.shape)
    vertex_piece = vertex_key // v_parent
    vertex_start = np.zeros(piece_count + 1, dtype=np.int64)
    np.cumsum(np.bincount(vertex_piece, minlength=piece_count), out=vertex_start[1:])

    # Face neighbours within the piece (rows of the batch), -1 across a crack or outside.
    parent_neighbor = parent.tet_neighbor[all_tets].astype(np.int64)
    across = np.where(parent_neighbor < 0, t_parent, parent_neighbor)
    same = label[across] == piece_of_tet[:, None]
    neighbor = np.where(same, index[across], -1)
    crack_face = (parent_neighbor >= 0) & ~same  # (T,4) faces the cut opened

    coarse = parent.coarse_group_size if coarse_group_size is None else coarse_group_size
    surface_counts = np.bincount(piece_of_tet, weights=np.any(neighbor < 0, axis=1), minlength=piece_count)
    piece_n = group_sizes(surface_counts, boundary_group_size, coarse)
    inherited = None
    same_n = piece_n == parent.boundary_group_size
    if parent.boundary_group_size > 1 and np.any(same_n):
        off, members = parent.boundary_member_offsets, parent.boundary_members
        sizes = np.diff(off)
        owner = np.repeat(np.arange(len(sizes)), sizes)
        mapped = index[members]
        member_piece = label[members]
        group_piece = member_piece[off[:-1]]
        # spoilt: a member outside the pieces, on a crack, or in another piece than the first
        # (or in a piece grouped by another n than the parent's)
        bad = (mapped < 0) | crack_face[np.maximum(mapped, 0)].any(axis=1) | (member_piece != group_piece[owner]) \
            | ~same_n[np.maximum(member_piece, 0)]
        spoilt = np.bincount(owner, weights=bad, minlength=len(sizes)) > 0
        keep = np.nonzero(~spoilt)[0]
        inherited = (mapped[~spoilt[owner]], sizes[keep], group_piece[keep], parent.collision_position[keep],
                     crack_face)
    return _assemble(parent.vertices[vertex_key - vertex_piece * v_parent], tets, parent.tet_volume[all_tets],
                     neighbor, tet_start, vertex_start, parent.density, piece_n, keep_leftovers,
                     parent.source_tet[all_tets], spacing=parent.spacing,
                     root=parent.root if parent.root is not None else parent, inherited=inherited,
                     props=[_mass_by_subtraction(parent, p) for p in pieces], coarse_group_size=coarse)


def _mass_by_subtraction(parent: BodyModel, tets: np.ndarray) -> MassProperties | None:
    """The mass properties of the piece ``tets`` of ``parent`` as the parent's less those
    of the rest, when the piece holds most of the parent (the big piece left when a chip
    breaks off: the rest is the small one), else None (integrate the piece). The parent's
    body frame has its centre of mass at the origin, so with the rest's mass m_r, centre
    c_r and inertia I_r (about c_r), the piece has m = M - m_r, c = -m_r c_r / m and

        I = I_parent - (I_r + m_r (|c_r|^2 E - c_r c_r^T)) - m (|c|^2 E - c c^T)

    (parallel-axis rule, both about the origin, then to c). Exact in arithmetic; in f64
    it agrees with integrating the piece to ~1e-15 of the inertia, because the piece's
    terms are the large ones; it skips integrating the big piece's tets."""
    if 2 * len(tets) <= parent.tet_count:
        return None
    rest = np.ones(parent.tet_count, dtype=bool)
    rest[tets] = False
    rest = np.nonzero(rest)[0]
    if len(rest) == 0:  # the whole parent (a split that cut nothing off)
        return MassProperties(mass=float(parent.mass), center_of_mass=np.zeros(3), inertia=parent.inertia.copy(),
                              volume=parent.volume)
    removed = tet_mass_properties(parent.vertices, parent.tets[rest], parent.density, parent.tet_volume[rest])
    mass = parent.mass - removed.mass
    c_r = removed.center_of_mass
    com = -removed.mass * c_r / mass
    eye = np.eye(3)
    inertia = (parent.inertia - removed.inertia - removed.mass * (c_r @ c_r * eye - np.outer(c_r, c_r))
               - mass * (com @ com * eye - np.outer(com, com)))
    return MassProperties(mass=float(mass), center_of_mass=com, inertia=0.5 * (inertia + inertia.T),
                          volume=float(parent.volume - removed.volume))


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The indices start, start+1, ..., start+length-1 of every (start, length), in order."""
    ends = np.cumsum(lengths)
    return np.repeat(starts - (ends - lengths), lengths) + np.arange(ends[-1] if len(ends) else 0)


def _starts(piece_of_row: np.ndarray, piece_count: int) -> np.ndarray:
    """(P+1,) where each piece's rows begin in an array whose rows are piece-major, given
    each row's piece (non-decreasing)."""
    return np.searchsorted(piece_of_row, np.arange(piece_count + 1), side="left")


def _group_by_size(centroids, rest, face_tet, faces, piece_of_tet, piece_n, keep_leftovers):
    """``group_surface_particles`` over the surface particles ``rest`` of pieces grouped by
    different n: one walk per n over its pieces' particles, the results in piece order
    (each piece's groups as its own walk makes them). Returns (members, sizes, dropped)."""
    values = np.unique(piece_n)
    if len(values) == 1:
        return group_surface_particles(centroids, rest, face_tet, faces, int(values[0]), keep_leftovers)
    parts = []
    for n in values:
        rows_n = piece_n[piece_of_tet[rest]] == n
        faces_n = piece_n[piece_of_tet[face_tet]] == n
        parts.append(group_surface_particles(centroids, rest[rows_n], face_tet[faces_n], faces[faces_n], int(n),
                                             keep_leftovers))
    members = np.concatenate([p[0] for p in parts])
    sizes = np.concatenate([p[1] for p in parts])
    first = members[np.cumsum(sizes) - sizes]
    order = np.argsort(piece_of_tet[first], kind="stable")
    members = members[_ranges((np.cumsum(sizes) - sizes)[order], sizes[order])]
    dropped = np.sort(np.concatenate([p[2] for p in parts]))
    return members, sizes[order], dropped


def _assemble(vertices, tets, vol, neighbor, tet_start, vertex_start, density, piece_n, keep_leftovers,
              source_tet, *, spacing, root, props, inherited=None, coarse_group_size=0) -> list[BodyModel]:
    """The models of P pieces given as one batch: the rows of piece k are ``tet_start[k]``
    to ``tet_start[k+1]`` of ``tets`` (T,4) (clean, positively oriented, indexing
    ``vertices`` (V,3) [m, source frame], whose piece k rows are ``vertex_start[k]`` to
    ``vertex_start[k+1]``), ``vol`` (T,) [m^3] and face neighbours ``neighbor`` (T,4)
    (rows of the batch, within the piece; -1 on its boundary). ``piece_n`` (P,): each
    piece's boundary grouping n (``group_sizes``). ``props``: each piece's
    mass properties (source frame), or None to integrate them. ``inherited``: (the kept
    parent groups' members (rows, group after group), their sizes (K,), pieces (K,) and
    collision centres (K,3) [m, source frame], crack faces (T,4) bool) from
    ``build_fragment_models``. Every step treats a piece's rows as its own build would:
    the same rows in the same order, so each model is the one built alone."""
    piece_count = len(tet_start) - 1
    piece_of_tet = np.repeat(np.arange(piece_count), np.diff(tet_start))
    piece_of_vertex = np.repeat(np.arange(piece_count), np.diff(vertex_start))
    props = [p if p is not None else tet_mass_properties(
        vertices[vertex_start[k]:vertex_start[k + 1]], tets[tet_start[k]:tet_start[k + 1]] - vertex_start[k],
        density, vol[tet_start[k]:tet_start[k + 1]]) for k, p in enumerate(props)]
    com = np.array([p.center_of_mass for p in props])  # (P,3)
    vertices = vertices - com[piece_of_vertex]
    faces, face_tet, face_local = boundary_faces(tets, neighbor)  # piece-major rows
    face_piece = piece_of_tet[face_tet]
    centroids = rows.corner_mean(vertices[tets])
    mass = density * vol
    radius = np.cbrt(3.0 * vol / (4.0 * np.pi))
    is_surface = np.zeros(len(tets), dtype=bool)
    is_surface[face_tet] = True
    surface = np.nonzero(is_surface)[0]

    # Boundary groups: the kept parent groups, then the surface particles they leave grouped
    # afresh. One greedy walk over all pieces: no two pieces share a vertex row, so a piece's
    # walk meets only its own particles, in its own order.
    if inherited is None:
        kept_members, kept_sizes, kept_piece = (np.zeros(0, dtype=np.int64),) * 3
        kept_centres, crack_face = np.zeros((0, 3)), None
    else:
        kept_members, kept_sizes, kept_piece, kept_centres, crack_face = inherited
    covered = np.zeros(len(tets), dtype=bool)
    covered[kept_members] = True
    rest = surface[~covered[surface]]
    on_rest = ~covered[face_tet]
    fresh_members, fresh_sizes, dropped = _group_by_size(centroids, rest, face_tet[on_rest], faces[on_rest],
                                                         piece_of_tet, np.asarray(piece_n), keep_leftovers)
    fresh_piece = piece_of_tet[fresh_members[np.cumsum(fresh_sizes) - fresh_sizes]]
    # Each piece's groups: its kept ones (in the parent's order), then its fresh ones.
    kept = len(kept_sizes)
    order = np.argsort(np.concatenate([2 * kept_piece, 2 * fresh_piece + 1]), kind="stable")
    all_sizes = np.concatenate([kept_sizes, fresh_sizes])
    sizes = all_sizes[order]
    members = np.concatenate([kept_members, fresh_members])[_ranges((np.cumsum(all_sizes) - all_sizes)[order], sizes)]
    group_piece = np.concatenate([kept_piece, fresh_piece])[order]
    group_count = len(sizes)
    offsets = np.zeros(group_count + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    owner = np.repeat(np.arange(group_count), sizes)
    b_mass = np.bincount(owner, weights=mass[members], minlength=group_count)
    b_pos = np.stack(
        [np.bincount(owner, weights=centroids[members, k], minlength=group_count) for k in range(3)], axis=1
    ) / np.maximum(sizes, 1)[:, None]
    reach = rows.norm(centroids[members] - b_pos[owner]) + radius[members]
    b_radius = np.zeros(group_count)
    np.maximum.at(b_radius, owner, reach)

    # Collision centres: a kept group's is its parent's unless a crack face comes near it.
    contact_pos = np.empty_like(b_pos)
    redo = order >= kept
    slots = np.nonzero(~redo)[0]
    contact_pos[slots] = kept_centres[order[slots]] - com[group_piece[slots]]
    if len(slots):
        crack = crack_face[face_tet, face_local]
        for k in np.unique(group_piece[slots]):
            mine = slots[group_piece[slots] == k]
            redo[mine] = near_faces(vertices, faces[crack & (face_piece == k)], b_pos[mine],
                                     CENTRE_REACH * b_radius[mine])
    which = np.nonzero(redo)[0]
    if len(which):
        sub = redo[owner]
        renumber = np.cumsum(redo) - 1
        contact_pos[which] = contact_sphere_centres(vertices, faces, face_tet, centroids, members[sub],
                                                    renumber[owner[sub]], b_pos[which], b_radius[which],
                                                    group_piece=group_piece[which], face_piece=face_piece)

    batch = dict(vertices=vertices, tets=tets, vol=vol, neighbor=neighbor, centroids=centroids, mass=mass,
                 radius=radius, is_surface=is_surface, surface=surface, faces=faces, face_tet=face_tet,
                 face_local=face_local, face_piece=face_piece, b_pos=b_pos, b_mass=b_mass, b_radius=b_radius,
                 offsets=offsets, members=members, group_piece=group_piece, dropped=dropped, contact_pos=contact_pos,
                 com=com, props=props, source_tet=source_tet)
    return _piece_models(batch, tet_start, vertex_start, piece_of_tet, piece_n, density=density, spacing=spacing,
                         root=root, coarse_group_size=coarse_group_size)


def _piece_models(batch: dict, tet_start, vertex_start, piece_of_tet, piece_n, *, density, spacing, root,
                  coarse_group_size) -> list[BodyModel]:
    """Each piece's BodyModel cut out of ``_assemble``'s batch arrays (``batch``: its rows,
    piece-major), indices renumbered to the piece's own rows."""
    vertices, tets, neighbor, surface = batch["vertices"], batch["tets"], batch["neighbor"], batch["surface"]
    faces, face_tet, members, offsets = batch["faces"], batch["face_tet"], batch["members"], batch["offsets"]
    dropped, props, com = batch["dropped"], batch["props"], batch["com"]
    piece_count = len(tet_start) - 1
    bonds = bonds_from_neighbors(neighbor)  # rows of the batch, piece-major
    face_start = _starts(batch["face_piece"], piece_count)
    group_start = _starts(batch["group_piece"], piece_count)
    surface_start = np.searchsorted(surface, tet_start)
    bond_start = np.searchsorted(bonds[:, 0], tet_start)
    dropped_start = _starts(piece_of_tet[dropped], piece_count)
    models = []
    for k in range(piece_count):
        t0, t1 = tet_start[k], tet_start[k + 1]
        v0, v1 = vertex_start[k], vertex_start[k + 1]
        g0, g1 = group_start[k], group_start[k + 1]
        f0, f1 = face_start[k], face_start[k + 1]
        own_neighbor = neighbor[t0:t1]
        models.append(BodyModel(
            vertices=vertices[v0:v1],
            tets=(tets[t0:t1] - v0).astype(np.int32),
            tet_volume=batch["vol"][t0:t1],
            tet_neighbor=np.where(own_neighbor >= 0, own_neighbor - t0, -1).astype(np.int32),
            bonds=(bonds[bond_start[k]:bond_start[k + 1]] - t0).astype(np.int32),
            particle_position=batch["centroids"][t0:t1],
            particle_mass=batch["mass"][t0:t1],
            particle_radius=batch["radius"][t0:t1],
            is_surface=batch["is_surface"][t0:t1],
            surface_particles=(surface[surface_start[k]:surface_start[k + 1]] - t0).astype(np.int32),
            surface_faces=(faces[f0:f1] - v0).astype(np.int32),
            surface_face_tet=(face_tet[f0:f1] - t0).astype(np.int32),
            surface_face_local=batch["face_local"][f0:f1],
            boundary_position=batch["b_pos"][g0:g1],
            boundary_mass=batch["b_mass"][g0:g1],
            boundary_radius=batch["b_radius"][g0:g1],
            boundary_member_offsets=(offsets[g0:g1 + 1] - offsets[g0]).astype(np.int32),
            boundary_members=(members[offsets[g0]:offsets[g1]] - t0).astype(np.int32),
            dropped_surface_particles=(dropped[dropped_start[k]:dropped_start[k + 1]] - t0).astype(np.int32),
            density=float(density),
            mass=props[k].mass,
            inertia=props[k].inertia,
            com_in_source=com[k],
            source_tet=np.asarray(batch["source_tet"][t0:t1]).astype(np.int32),
            boundary_group_size=int(piece_n[k]),
            coarse_group_size=int(coarse_group_size),
            boundary_contact_position=batch["contact_pos"][g0:g1],
            particle_spacing=float(spacing),
            root=root,
        ))
    return models
