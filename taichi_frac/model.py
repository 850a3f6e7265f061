"""The static two-scale particle model of one rigid solid (BRIEF.md steps 1-3).

A :class:`BodyModel` is built once (for a scene object, or for a fragment when a body
breaks) and is read-only afterwards. Everything is in the **body frame**: origin at the
body's centre of mass, axes parallel to the source mesh's axes, metres.

Layers:
- physics particles: one per tet, at its centroid (stress analysis, fracture);
- surface particles: the physics particles whose tet has a boundary face;
- boundary particles: about ``boundary_group_size`` adjacent surface particles merged into
  one coarser sphere (collision detection and response).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .geometry import rows
from .geometry.mass import MassProperties, tet_mass_properties
from .geometry.rays import face_bounds, first_hits
from .geometry.topology import (
    bonds_from_neighbors,
    boundary_faces,
    compact_vertices,
    orient_tets,
    signed_volumes,
    subset_neighbors,
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
    particle_spacing: float | None = None
    root: BodyModel | None = None

    @property
    def collision_position(self) -> np.ndarray:
        """(N,3) [m] centres of the boundary spheres used for collision."""
        return self.boundary_position if self.boundary_contact_position is None else self.boundary_contact_position

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


def group_surface_particles(
    positions: np.ndarray,
    surface: np.ndarray,
    face_tet: np.ndarray,
    faces: np.ndarray,
    group_size: int,
    keep_leftovers: bool = True,
):
    """Merge adjacent surface particles into groups of about ``group_size``.

    Two surface particles are adjacent when their tets share a boundary vertex. Seeds are
    taken in breadth-first order over that graph (so groups tile the surface without gaps);
    each seed takes its nearest still-free neighbours, widening to neighbours of the group
    when the seed's own ring runs out, until the group has ``group_size`` members. A group
    that ends with one member is a leftover: kept as its own boundary particle or dropped.

    Returns (groups: list of int arrays of tet indices, dropped: int array).
    """
    if group_size == 1:
        return [np.array([s]) for s in surface], np.zeros(0, dtype=np.int32)
    s_count = len(surface)
    local = np.full(int(surface.max()) + 1 if s_count else 1, -1, dtype=np.int64)
    local[surface] = np.arange(s_count)
    adjacent = _surface_adjacency(local[face_tet], faces, s_count)
    # The greedy walk below is sequential; on a fragment's few hundred particles plain
    # Python lists beat numpy's per-call overhead (~4x on a ring's 2,562).
    pos = positions[surface].tolist()
    free = [True] * s_count
    visited = [False] * s_count
    groups, dropped = [], []
    for start in range(s_count):
        if visited[start]:
            continue
        queue = [start]
        visited[start] = True
        head = 0
        while head < len(queue):
            seed = queue[head]
            head += 1
            nbrs = adjacent[seed]
            for m in nbrs:
                if not visited[m]:
                    visited[m] = True
                    queue.append(m)
            if not free[seed]:
                continue
            members = [seed]
            free[seed] = False
            frontier = nbrs
            seed_pos = pos[seed]
            for _ in range(3):  # widen at most twice beyond the seed's own ring
                cand = sorted({m for m in frontier if free[m]})
                if cand:
                    cand.sort(key=lambda m: math.dist(pos[m], seed_pos))  # stable: ties by index
                    take = cand[: group_size - len(members)]
                    for m in take:
                        free[m] = False
                    members.extend(take)
                if len(members) >= group_size:
                    break
                frontier = [m for member in members for m in adjacent[member]]
            if len(members) == 1 and not keep_leftovers:
                dropped.append(seed)
            else:
                groups.append(surface[np.array(members)])
    return groups, surface[np.array(dropped, dtype=np.int64)].astype(np.int32)


def _surface_adjacency(owner: np.ndarray, faces: np.ndarray, count: int) -> list:
    """rows[k]: the particles (ascending, k included) that share a boundary vertex with
    particle k, where ``owner`` (F,) is the particle of each boundary face (F,3). Python
    sets for a few hundred particles (the crack side of a fragment: scipy's sparse
    product cost ~0.6 ms of overhead there), the incidence matrix squared above that."""
    if count <= 400:
        by_vertex: dict[int, set] = {}
        for p, face in zip(owner.tolist(), faces.tolist()):
            for v in face:
                by_vertex.setdefault(v, set()).add(p)
        near = [set() for _ in range(count)]
        for sharing in by_vertex.values():
            for p in sharing:
                near[p] |= sharing
        return [sorted(n) for n in near]
    # Incidence particle x boundary vertex, then particle adjacency.
    cols = faces.reshape(-1)
    inc = sp.csr_matrix((np.ones(len(cols)), (np.repeat(owner, 3), cols)), shape=(count, int(cols.max()) + 1))
    adj = (inc @ inc.T).tocsr()
    adj.sort_indices()
    flat, ptr = adj.indices.tolist(), adj.indptr.tolist()
    return [flat[ptr[k]:ptr[k + 1]] for k in range(count)]  # (one tolist, not one per row)


def build_body_model(
    vertices: np.ndarray,
    tets: np.ndarray,
    density: float,
    *,
    boundary_group_size: int = 4,
    keep_leftovers: bool = True,
    source_tet: np.ndarray | None = None,
) -> BodyModel:
    """Build the two-scale particle model of a tet set given in its source frame.

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
    return _assemble(vertices, tets, vol, tet_neighbors(tets), density, boundary_group_size, keep_leftovers,
                     np.arange(len(tets)) if source_tet is None else np.asarray(source_tet),
                     spacing=float(np.mean(np.cbrt(vol))), root=None)


def build_fragment_model(
    parent: BodyModel,
    tets: np.ndarray,
    *,
    boundary_group_size: int = 4,
    keep_leftovers: bool = True,
) -> BodyModel:
    """The model of the piece of ``parent`` made of its tets ``tets`` (ascending indices),
    in the parent's body frame as source frame: the tets, mass properties and physics
    particles ``build_body_model`` would build from ``parent.vertices`` and
    ``parent.tets[tets]``, with the topology restricted from the parent's instead of
    rebuilt and the SPH discretisation (``particle_spacing``, ``root``) inherited.

    The boundary layer is inherited where the surface is the parent's: a parent group
    whose members are all in the piece and touch no crack face is kept as it was (the
    same sphere, and the same collision centre unless a crack face lies within reach of
    its inward ray), and only the surface particles along the cracks are grouped afresh.
    So a piece collides where its parent did the instant it is born, and the build costs
    in proportion to the crack, not to the piece's surface."""
    tets = np.asarray(tets, dtype=np.int64)
    if tets.ndim != 1 or len(tets) == 0 or np.any(np.diff(tets) <= 0):
        raise ValueError("tets must be a non-empty ascending array of the parent's tet indices")
    vertices, sub, _ = compact_vertices(parent.vertices, parent.tets[tets])
    neighbor = subset_neighbors(parent.tet_neighbor, tets)
    crack_face = (parent.tet_neighbor[tets] >= 0) & (neighbor < 0)  # (T,4) faces the cut opened
    inherited = None
    if boundary_group_size == parent.boundary_group_size and boundary_group_size > 1:
        local = np.full(parent.tet_count, -1, dtype=np.int64)
        local[tets] = np.arange(len(tets))
        off, members = parent.boundary_member_offsets, parent.boundary_members
        owner = np.repeat(np.arange(len(off) - 1), np.diff(off))
        mapped = local[members]
        spoilt = np.zeros(len(off) - 1, dtype=bool)  # a member outside the piece or on a crack
        np.logical_or.at(spoilt, owner, (mapped < 0) | crack_face[np.maximum(mapped, 0)].any(axis=1))
        keep = np.nonzero(~spoilt)[0]
        groups = [mapped[off[g]:off[g + 1]] for g in keep]
        inherited = (groups, parent.collision_position[keep], crack_face)
    return _assemble(vertices, sub, parent.tet_volume[tets], neighbor, parent.density, boundary_group_size,
                     keep_leftovers, parent.source_tet[tets], spacing=parent.spacing,
                     root=parent.root if parent.root is not None else parent, inherited=inherited,
                     props=_mass_by_subtraction(parent, tets))


def _mass_by_subtraction(parent: BodyModel, tets: np.ndarray) -> MassProperties | None:
    """The mass properties of the piece ``tets`` of ``parent`` as the parent's less those
    of the rest, when the piece holds most of the parent (the big piece left when a chip
    breaks off: the rest is the small one), else None (integrate the piece). The parent's
    body frame has its centre of mass at the origin, so with the rest's mass m_r, centre
    c_r and inertia I_r (about c_r), the piece has m = M - m_r, c = -m_r c_r / m and

        I = I_parent - (I_r + m_r (|c_r|^2 E - c_r c_r^T)) - m (|c|^2 E - c c^T)

    (parallel-axis rule, both about the origin, then to c). Exact in arithmetic; in f64
    it agrees with integrating the piece to ~1e-15 of the inertia, because the piece's
    terms are the large ones. A ring's big piece: 1.2 -> 0.2 ms."""
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


def _assemble(vertices, tets, vol, neighbor, density, boundary_group_size, keep_leftovers, source_tet, *,
              spacing, root, inherited=None, props=None) -> BodyModel:
    """The model of clean, positively oriented ``tets`` (T,4) over ``vertices`` (V,3) [m,
    source frame] with volumes ``vol`` (T,) [m^3] and face neighbours ``neighbor`` (T,4).
    ``inherited``: (kept groups (lists of tet indices), their collision centres (K,3) [m,
    source frame], crack faces (T,4) bool) from ``build_fragment_model``; ``props``: the
    tets' mass properties when the caller has them (source frame), else integrated."""
    if props is None:
        props = tet_mass_properties(vertices, tets, density, vol)
    com = props.center_of_mass
    vertices = vertices - com
    faces, face_tet, face_local = boundary_faces(tets, neighbor)
    centroids = rows.corner_mean(vertices[tets])
    mass = density * vol
    radius = np.cbrt(3.0 * vol / (4.0 * np.pi))
    is_surface = np.zeros(len(tets), dtype=bool)
    is_surface[face_tet] = True
    surface = np.nonzero(is_surface)[0].astype(np.int32)

    if inherited is None:
        groups, dropped = group_surface_particles(
            centroids, surface, face_tet, faces, boundary_group_size, keep_leftovers
        )
        kept = 0
    else:
        groups, kept_centres, crack_face = inherited
        kept = len(groups)
        covered = np.zeros(len(tets), dtype=bool)
        if kept:
            covered[np.concatenate(groups)] = True
        rest = surface[~covered[surface]]
        dropped = np.zeros(0, dtype=np.int32)
        if len(rest):
            on_rest = ~covered[face_tet]
            fresh, dropped = group_surface_particles(
                centroids, rest, face_tet[on_rest], faces[on_rest], boundary_group_size, keep_leftovers
            )
            groups = list(groups) + fresh
    sizes = np.array([len(g) for g in groups], dtype=np.int64)
    offsets = np.zeros(len(groups) + 1, dtype=np.int64)
    np.cumsum(sizes, out=offsets[1:])
    members = np.concatenate(groups).astype(np.int32) if groups else np.zeros(0, np.int32)
    owner = np.repeat(np.arange(len(groups)), sizes)
    b_mass = np.bincount(owner, weights=mass[members], minlength=len(groups))
    b_pos = np.stack(
        [np.bincount(owner, weights=centroids[members, k], minlength=len(groups)) for k in range(3)], axis=1
    ) / np.maximum(sizes, 1)[:, None]
    reach = rows.norm(centroids[members] - b_pos[owner]) + radius[members]
    b_radius = np.zeros(len(groups))
    np.maximum.at(b_radius, owner, reach)
    if inherited is None:
        contact_pos = contact_sphere_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius)
    else:
        contact_pos = np.empty_like(b_pos)
        contact_pos[:kept] = kept_centres - com
        redo = np.ones(len(groups), dtype=bool)
        redo[:kept] = _near_faces(vertices, faces[crack_face[face_tet, face_local]], b_pos[:kept],
                                  CENTRE_REACH * b_radius[:kept])
        which = np.nonzero(redo)[0]
        if len(which):
            sub = np.isin(owner, which)
            renumber = np.cumsum(redo) - 1
            contact_pos[which] = contact_sphere_centres(vertices, faces, face_tet, centroids, members[sub],
                                                        renumber[owner[sub]], b_pos[which], b_radius[which])

    return BodyModel(
        vertices=vertices,
        tets=tets.astype(np.int32),
        tet_volume=vol,
        tet_neighbor=neighbor,
        bonds=bonds_from_neighbors(neighbor),
        particle_position=centroids,
        particle_mass=mass,
        particle_radius=radius,
        is_surface=is_surface,
        surface_particles=surface,
        surface_faces=faces,
        surface_face_tet=face_tet,
        surface_face_local=face_local,
        boundary_position=b_pos,
        boundary_mass=b_mass,
        boundary_radius=b_radius,
        boundary_member_offsets=offsets.astype(np.int32),
        boundary_members=members,
        dropped_surface_particles=dropped.astype(np.int32),
        density=float(density),
        mass=props.mass,
        inertia=props.inertia,
        com_in_source=com,
        source_tet=np.asarray(source_tet).astype(np.int32),
        boundary_group_size=int(boundary_group_size),
        boundary_contact_position=contact_pos,
        particle_spacing=float(spacing),
        root=root,
    )


#: A kept boundary group's collision centre is computed again when a crack face lies
#: within this many of its radii of its centre: the centre moves inward by less than
#: 2 radii (``contact_sphere_centres``: at most R - h, h > -R for a surface group's own
#: faces) and the thickness ray looks a radius beyond that.
CENTRE_REACH = 3.0


def _near_faces(vertices, faces, points, reach) -> np.ndarray:
    """(P,) bool: does any of ``faces`` (F,3) come within ``reach`` (P,) [m] of ``points``
    (P,3) [m] (the nearest face centre's distance less the largest face's own radius; a
    conservative test)."""
    from scipy.spatial import cKDTree

    if len(faces) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    centre, radius = face_bounds(vertices[faces])
    distance, _ = cKDTree(centre).query(points)
    return distance < reach + float(radius.max())


def contact_sphere_centres(vertices, faces, face_tet, centroids, members, owner, b_pos, b_radius):
    """Collision centres of the boundary spheres (see ``BodyModel.boundary_contact_position``).

    For each group: its outward normal n (area-weighted normals of its members' boundary
    faces), the height h of the true surface above its centre along n (largest over those
    faces' vertices), the radius rho its members' centroids span about the normal axis,
    and the body's thickness t behind the centre along -n (``ray_exit_distance`` against
    the boundary faces, looked at only as far as the limit can bind, s + R).
    The centre moves inward by

        s = min(R - h, sqrt(R^2 - rho^2) - h, t - R), at least 0:

    toward putting the sphere's outermost point on the surface (R - h), but never so far
    that its cross-section at the surface stops covering its members (so neighbouring
    spheres leave no hole a small body could fall through, even on a coarse mesh), and
    never so far that it pokes out behind (t - R).
    """
    n_groups = len(b_pos)
    if n_groups == 0 or len(faces) == 0:
        return b_pos.copy()
    group_of_tet = np.full(len(centroids), -1, dtype=np.int64)
    group_of_tet[members] = owner
    group = group_of_tet[face_tet]
    mine = np.nonzero(group >= 0)[0]  # the faces of these groups' members (all, or a few)
    group = group[mine]
    corners = vertices[faces[mine]]  # (Fm,3,3)
    normal = rows.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    outward = np.sign(rows.dot(rows.corner_mean(corners) - centroids[face_tet[mine]], normal))
    normal *= outward[:, None]  # away from the owning tet, whatever the winding
    n_sum = np.zeros((n_groups, 3))
    np.add.at(n_sum, group, normal)
    length = rows.norm(n_sum)
    has_normal = length > 1e-12 * max(float(length.max()), 1e-300)
    n_unit = np.where(has_normal[:, None], n_sum / np.maximum(length, 1e-300)[:, None], 0.0)
    rel = corners - b_pos[group][:, None, :]  # (Fm,3,3) face vertices from the centre
    heights = (rel * n_unit[group][:, None, :]).sum(axis=2)
    h = np.full(n_groups, np.inf)
    np.minimum.at(h, group, -heights.max(axis=1))
    h = -h  # largest height of the group's faces above its centre
    member_rel = centroids[members] - b_pos[owner]
    along = rows.dot(member_rel, n_unit[owner])
    rho = np.zeros(n_groups)
    np.maximum.at(rho, owner, np.sqrt(np.maximum(rows.dot(member_rel, member_rel) - along ** 2, 0.0)))
    cover = np.sqrt(np.maximum(b_radius ** 2 - rho ** 2, 0.0))
    shift = np.where(has_normal & np.isfinite(h), np.minimum(b_radius, cover) - h, 0.0)
    todo = np.nonzero(shift > 0)[0]
    if len(todo):
        thickness = np.full(n_groups, np.inf)
        thickness[todo] = ray_exit_distance(vertices, faces, b_pos[todo], -n_unit[todo],
                                            shift[todo] + b_radius[todo])
        shift = np.minimum(shift, thickness - b_radius)
    shift = np.maximum(shift, 0.0)
    return b_pos - shift[:, None] * n_unit


def ray_exit_distance(vertices, faces, origin, direction, reach):
    """Distance [m] along each ray (origin (P,3) [m], unit direction (P,3)) to the first
    boundary face (F,3) it crosses within ``reach`` (P,) [m]; inf when none does.

    ``geometry.rays.first_hits``: one kernel, each ray testing only the faces whose
    bounding sphere comes within its reach (Moller-Trumbore). The model build asks only
    as far as the result can matter (a few particle radii), so this costs a fraction of
    a general ray cast (trimesh's rtree cast took ~21 ms per fragment model, 60 % of its
    build; a KD-tree query in numpy, 2.9 ms for a ring's big piece).
    """
    return first_hits(vertices, faces, origin, direction, reach)
