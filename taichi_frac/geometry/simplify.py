"""The surface the tets fill: a copy of the artist's surface simplified to the particles' size.

TetGen keeps every input triangle, so a surface finer than the spacing of the wanted particles
forces tiny tets along it and the particle count follows the surface, not the target (a 70k
face scan gave 316,218 particles for a target of 5,000). When the surface has more than
``FINER_FACTOR`` times the triangles a surface at the target spacing needs, a copy is
decimated to that count by quadric error metrics (``fast-simplification``, the maintained
binding of Sven Forstmann's Fast-Quadric-Mesh-Simplification used by PyVista: numpy arrays in
and out; pyfqmr wraps the same code and measured the same faces, 20 % slower). Quadric
decimation leaves long thin triangles (edge ratio 4.8 at the 95th percentile on the rocker
arm) and TetGen's quality refinement fills them with small tets (23,700 for a target of
5,000), so the copy is then relaxed towards equal edges: each vertex moves halfway to its
neighbours' mean within its tangent plane and back onto the finer surface, four times.
Decimation and relaxation shrink convex regions a little and round sharp edges, so the
copy's vertices finally move along their normals by the uniform offset (volume difference /
area) that gives it the input's volume back (to 1e-4). The full-resolution surface stays the
artist's (``PrepareReport.surface``); only the simulation sees the copy.

A thin part (a cow's tail, a handle) can decimate into the body next to it; removing the
crossings then cuts the part away, and its volume is too small for any volume check to see
(the cow's tail: 7 % of its length, 0.01 % of its volume). So every copy is also held to a
distance: no point of the input may lie farther than ``MAX_DEVIATION`` tet edges
(:func:`tet_edge`) from the copy (:func:`surface_deviation`); a copy that strays is replaced by a finer one.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from .validate import self_intersections

#: A surface triangle of the tet mesh is this many times the edge of a regular tet of the
#: target particle volume (the same factor that makes primitives land on the target).
EDGE_FACTOR = 1.3
#: Simplify when the surface has more than this many times the triangles the target needs
#: (thin parts can need fewer than that count: the copies then get coarser, see below).
FINER_FACTOR = 1.0
#: A simplified copy's volume may differ from the input's by this fraction at most.
VOLUME_TOLERANCE = 0.005
#: Fewest triangles a simplified copy keeps (a coarser copy loses the shape, not just detail).
MIN_FACES = 500
#: Largest distance from a point of the input to the copy, in tet edges (:func:`tet_edge`).
#: Decimating to the target's spacing moves the surface by up to 0.6 edges (where shells were
#: united); a lost thin part lies its length away (the cow's tail: 2.4 edges).
MAX_DEVIATION = 1.0
#: Input points the deviation is measured at: every vertex up to this count, else a random
#: subset of this size (a lost part has many vertices; one is enough to see it).
DEVIATION_SAMPLES = 50_000
#: Copies :func:`simplify_to_faces` tries, each with 1.15x the faces of the last (up to 3.5x).
RETRIES = 10


#: A regular tet's edge over the cube root of its volume, (6 sqrt 2)^(1/3).
TET_EDGE_PER_SPACING = (6.0 * math.sqrt(2.0)) ** (1.0 / 3.0)


def tet_edge(volume: float, target_particles: int) -> float:
    """Edge [m] of a regular tet of ``volume`` / ``target_particles`` [m^3]: the length the
    copy's triangles are sized by and its distance check is measured in (about 2.04 particle
    spacings, the particle volume's cube root)."""
    return TET_EDGE_PER_SPACING * (volume / target_particles) ** (1.0 / 3.0)


def deviation_points(mesh: trimesh.Trimesh, samples: int = DEVIATION_SAMPLES, seed: int = 0) -> np.ndarray:
    """(P,3) [m] points of ``mesh`` at which :func:`surface_deviation` measures: its vertices,
    or ``samples`` of them at random plus the six at the ends of its bounding box."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if len(vertices) <= samples:
        return vertices
    pick = np.random.default_rng(seed).choice(len(vertices), samples, replace=False)
    ends = np.concatenate([vertices.argmin(axis=0), vertices.argmax(axis=0)])
    return vertices[np.union1d(pick, ends)]


def surface_deviation(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> float:
    """Largest distance [m] from ``points`` (P,3) to the triangles ``faces`` of ``vertices``
    (libigl's AABB tree): how far the input's surface lies from a copy of it."""
    import igl

    squared, _, _ = igl.point_mesh_squared_distance(np.ascontiguousarray(points, dtype=np.float64),
                                                    np.ascontiguousarray(vertices, dtype=np.float64),
                                                    np.ascontiguousarray(faces, dtype=np.int64))
    return float(np.sqrt(np.max(squared))) if len(squared) else 0.0


def target_face_count(volume: float, area: float, target_particles: int) -> int:
    """Triangles of a surface of ``area`` [m^2] at the spacing of ``target_particles`` tets
    filling ``volume`` [m^3]: area / (an equilateral triangle of EDGE_FACTOR x the regular tet's
    edge)."""
    edge = EDGE_FACTOR * tet_edge(volume, target_particles)
    return max(MIN_FACES, int(round(area / (math.sqrt(3.0) / 4.0 * edge**2))))


def _decimate(vertices: np.ndarray, faces: np.ndarray, face_count: int):
    import fast_simplification

    reduction = 1.0 - face_count / len(faces)
    # The decimator's error thresholds are absolute: work at unit size so that the same shape
    # decimates the same way in millimetres or metres.
    centre = vertices.mean(axis=0)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    unit = np.ascontiguousarray((vertices - centre) / size, dtype=np.float64)
    v, f = fast_simplification.simplify(unit, np.ascontiguousarray(faces, dtype=np.int64), target_reduction=reduction)
    return np.asarray(v, dtype=np.float64) * size + centre, np.asarray(f, dtype=np.int64)


def _closest_points(vertices: np.ndarray, faces: np.ndarray):
    """A function (P,3) -> (P,3) [m]: the closest points on the triangles ``faces`` of
    ``vertices``, through one libigl AABB tree built here (trimesh's R-tree took 8 s to build
    on 1.3M faces; the AABB tree a third of that)."""
    import igl

    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    tree = igl.AABB()
    tree.init(vertices, faces)
    return lambda points: tree.squared_distance(vertices, faces, np.ascontiguousarray(points, dtype=np.float64))[2]


def relax_tangentially(mesh: trimesh.Trimesh, iterations: int = 4, step: float = 0.5,
                       crease_deg: float = 60.0, max_turn_deg: float = 25.0,
                       reference: trimesh.Trimesh | None = None) -> trimesh.Trimesh:
    """Equalise edge lengths without changing the shape: each vertex moves ``step`` of the way
    to its neighbours' mean, in its tangent plane, then onto the ``reference`` surface (the
    finer surface ``mesh`` was decimated from; default ``mesh`` itself).
    Vertices on creases (faces meeting at more than ``crease_deg``) and the outermost vertex on
    each axis stay, so sharp edges stay sharp and the bounding box does not shrink; a move that would turn a face by more than ``max_turn_deg`` is undone, so no face
    folds over."""
    import scipy.sparse as sp

    relaxed = mesh.copy()
    faces = np.asarray(mesh.faces)
    edges = np.asarray(mesh.edges_unique)
    n = len(mesh.vertices)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    degree = np.maximum(np.asarray(adjacency.sum(axis=1)).ravel(), 1.0)[:, None]
    movable = np.ones(n, dtype=bool)
    sharp = mesh.face_adjacency_angles > np.radians(crease_deg)
    movable[np.unique(mesh.face_adjacency_edges[sharp])] = False
    # The copy's outermost vertex on each axis stays too: sliding off a tip (an ear, a horn)
    # would shrink the body's extents.
    movable[np.concatenate([mesh.vertices.argmin(axis=0), mesh.vertices.argmax(axis=0)])] = False
    cos_turn = np.cos(np.radians(max_turn_deg))
    surface = reference or mesh
    onto = _closest_points(surface.vertices, surface.faces)
    for _ in range(iterations):
        before = relaxed.vertices.copy()
        normals_before = relaxed.face_normals.copy()
        move = adjacency @ before / degree - before
        normal = relaxed.vertex_normals
        move -= np.einsum("ij,ij->i", move, normal)[:, None] * normal
        moved = onto(before + step * move)
        relaxed.vertices = np.where(movable[:, None], moved, before)
        for _ in range(5):  # undo the moves around faces that turned too far
            turned = np.einsum("ij,ij->i", relaxed.face_normals, normals_before) < cos_turn
            if not turned.any():
                break
            undo = np.unique(faces[turned])
            vertices = relaxed.vertices.copy()
            vertices[undo] = before[undo]
            relaxed.vertices = vertices
    return relaxed


def restore_volume(mesh: trimesh.Trimesh, volume: float, passes: int = 2) -> trimesh.Trimesh:
    """Move the vertices along their (area-weighted) normals by (volume - mesh volume) / area,
    ``passes`` times: the first-order offset that restores ``volume`` [m^3]."""
    mesh = mesh.copy()
    for _ in range(passes):
        offset = (volume - mesh.volume) / mesh.area
        mesh.vertices = mesh.vertices + offset * mesh.vertex_normals
    return mesh


def _copy_at(mesh: trimesh.Trimesh, count: int, volume: float, near, clock=None, relax: bool = True):
    """One decimation of ``mesh`` to ``count`` faces, relaxed (``relax``) and given ``volume``
    [m^3] back: (copy, how) when it comes out closed, non-crossing, within
    :data:`VOLUME_TOLERANCE` of ``volume`` and ``near`` the input, else None."""
    if clock is not None:
        v, f = clock.run("simplify (fast-simplification)", _decimate, mesh.vertices, mesh.faces, count)
    else:
        v, f = _decimate(mesh.vertices, mesh.faces, count)
    copy = trimesh.Trimesh(v, f, process=True)
    if not (copy.is_watertight and copy.is_winding_consistent and copy.volume > 0
            and abs(copy.volume / volume - 1.0) < 0.2):
        return None
    relaxed = relax_tangentially(copy, reference=mesh) if relax else copy
    # Restoring the volume can push thin walls through each other: then the copy as it is, if
    # its volume is within VOLUME_TOLERANCE; the unrelaxed copy is the last resort (its thin
    # triangles make more tets than asked for).
    candidates = [(restore_volume(copy, volume), "volume restored"), (copy, "as decimated")]
    if relax:
        candidates[:0] = [(restore_volume(relaxed, volume), "relaxed, volume restored"), (relaxed, "relaxed")]
    for candidate, how in candidates:
        if abs(candidate.volume / volume - 1.0) > VOLUME_TOLERANCE:
            continue
        if len(self_intersections(candidate.vertices, candidate.faces)) == 0 and near(candidate):
            return candidate, how
    # Thin parts (legs, ears) decimated into each other: MeshFix removes the crossings (and,
    # when it cuts a thin part away, the distance bound refuses the result).
    cleaned = _meshfix_copy(restore_volume(relaxed, volume), clock)
    if cleaned is not None and abs(cleaned.volume / volume - 1.0) < 0.05:
        cleaned = restore_volume(cleaned, volume)
        if (abs(cleaned.volume / volume - 1.0) <= VOLUME_TOLERANCE
                and len(self_intersections(cleaned.vertices, cleaned.faces)) == 0 and near(cleaned)):
            return cleaned, ("relaxed, " if relax else "") + "crossings removed by pymeshfix, volume restored"
    return None


def simplify_to_faces(mesh: trimesh.Trimesh, face_count: int, clock=None, reference_volume: float | None = None,
                      max_deviation: float | None = None, reference_points: np.ndarray | None = None,
                      finer: trimesh.Trimesh | None = None, relax: bool = True):
    """A closed, non-crossing copy of ``mesh`` [m] decimated to about ``face_count`` faces,
    relaxed, with ``reference_volume`` (default: the mesh's) [m^3], and no point of
    ``reference_points`` (default: :func:`deviation_points` of ``mesh``) farther than
    ``max_deviation`` [m] from it (None: no bound), or None.

    Returns (copy, how) or None. A copy that comes out open, self-crossing, off in volume or
    too far from the input is first made again from ``finer`` (the surface ``mesh`` was itself
    decimated from, if any: a staged copy can have merged what the full surface keeps apart),
    then retried with 1.15x the triangles, up to :data:`RETRIES` times, while that is still
    fewer than the surface has; if all fail, None (the mesher then gets the full surface and
    the count follows the surface, as the report will show).
    """
    volume = float(mesh.volume if reference_volume is None else reference_volume)
    if max_deviation is not None and reference_points is None:
        reference_points = deviation_points(mesh if finer is None else finer)

    def near(candidate) -> bool:
        return max_deviation is None or surface_deviation(reference_points, candidate.vertices,
                                                          candidate.faces) <= max_deviation

    count = max(int(face_count), MIN_FACES)
    for _ in range(RETRIES):
        sources = [source for source in (mesh, finer) if source is not None and count < len(source.faces)]
        if not sources:
            return None
        for source in sources:
            copy = _copy_at(source, count, volume, near, clock, relax)
            if copy is not None:
                return copy
        count = int(count * 1.15)  # (the decimator's output is open at some counts, not at others)
    return None


def _meshfix_copy(copy: trimesh.Trimesh, clock=None):
    """``copy`` through MeshFix, or None if that leaves it open."""
    from .repair import _meshfix

    v, f = clock.run("clean copy (pymeshfix)", _meshfix, copy.vertices, copy.faces) if clock is not None \
        else _meshfix(copy.vertices, copy.faces)
    cleaned = trimesh.Trimesh(v, f, process=True)
    return cleaned if len(cleaned.faces) and cleaned.is_watertight and cleaned.is_winding_consistent else None


def simplified_tet_surfaces(mesh: trimesh.Trimesh, target_particles: int, clock=None):
    """Copies of ``mesh`` for ``target_particles`` tets, coarsest last: a generator the caller
    drives with the tet count each copy gave (``send``), or nothing when ``mesh`` is not finer
    than the target spacing (see the module docstring). Yields (copy, description).

    The first copy has :func:`target_face_count` faces; when its tets overshoot the target
    by more than 15 % (thin parts, many sharp features), the next has fewer faces, by the
    overshoot to the 2/3 (tets ~ faces^(3/2) where the surface sets the count); three at most.
    A large input is first decimated once to 8x the wanted faces, so later copies start small.
    Every copy lies within :data:`MAX_DEVIATION` tet edges of every point of ``mesh``.
    """
    wanted = target_face_count(mesh.volume, mesh.area, target_particles)
    if len(mesh.faces) <= FINER_FACTOR * wanted:
        return
    volume = float(mesh.volume)
    bound = dict(max_deviation=MAX_DEVIATION * tet_edge(volume, target_particles),
                 reference_points=deviation_points(mesh))
    source = mesh
    if len(mesh.faces) > 16 * wanted:
        # Only decimated further: relaxing it (against the full surface) would buy nothing.
        staged = simplify_to_faces(mesh, 8 * wanted, clock, relax=False, **bound)
        if staged is not None:
            source = staged[0]
    count = wanted
    for _ in range(3):
        copy = simplify_to_faces(source, count, clock, reference_volume=volume,
                                 finer=None if source is mesh else mesh, **bound)
        if copy is None:
            return
        tets = yield copy[0], (f"tetrahedralized a copy simplified to the particle spacing: {len(mesh.faces):,} -> "
                               f"{len(copy[0].faces):,} faces (quadric decimation, {copy[1]})")
        if tets is None or tets <= 1.15 * target_particles:
            return
        if len(copy[0].faces) <= MIN_FACES * 1.05:
            return
        count = max(int(len(copy[0].faces) * (target_particles / tets) ** (2 / 3) * 0.95), MIN_FACES)


def simplify_for_target(mesh: trimesh.Trimesh, target_particles: int, clock=None):
    """The first copy of :func:`simplified_tet_surfaces` (copy, description), or None."""
    return next(simplified_tet_surfaces(mesh, target_particles, clock), None)
