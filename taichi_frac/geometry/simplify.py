"""The surface the tets fill: a copy of the artist's surface simplified to the particles' size.

TetGen keeps every input triangle, so a surface finer than the spacing of the wanted particles
forces tiny tets along it and the particle count follows the surface, not the target (a 70k
face scan gave 316,218 particles for a target of 5,000). When the surface has more than
``FINER_FACTOR`` times the triangles a surface at the target spacing needs
(:func:`target_face_count`), a copy is made in four steps:

1. **decimation** by collapsing the shortest edge first, each to its midpoint, no collapse
   letting faces cross (libigl's ``decimate``): nearly equal triangles. TetGen's particle
   count follows the shape of the surface triangles more than their number: quadric
   decimation (which keeps the shape closer at a given count) leaves long thin triangles
   that its quality bound fills with small tets (a torus of 828 quadric triangles gave
   5,900-21,000 tets for a target of 5,000 under the quality bounds tried, 5,000 from the
   same count of even ones), so the even copy can have 2.5 times the triangles
   (:data:`EDGE_FACTOR`) for the same particles. A surface of over 16 times the wanted
   triangles is first decimated by quadric errors (``fast-simplification``) to 8 times, which
   takes a tenth of the time on a million faces;
2. **tangential relaxation** towards equal edges, vertices kept on the input
   (:func:`relax_tangentially`);
3. **a least-squares fit to the input** (:func:`fit_to_surface`): vertices on the input cut
   every convex part short by their chords and bulge out of concave ones; a uniform offset
   that gives the volume back pushes flat parts and tips out while curved and thin parts
   stay in (a quadric copy of the armadillo of 922 triangles so offset holds 96.4 % of its
   solid and overshoots its box by 1 %). The fit moves each vertex by its share of the gaps
   from the copy to points spread over the input, so the input lies as much outside the copy
   as inside around every vertex and a sharp rim or tip is pulled out to where it is; a
   small uniform offset then gives the exact volume, and the copy is held inside the input's
   box and made to span it;
4. **checks**: closed, not self-crossing, the volume within :data:`VOLUME_TOLERANCE`, and no
   point of the input farther than :data:`MAX_DEVIATION` tet edges (:func:`tet_edge`) from
   the copy (:func:`surface_deviation`). A thin part (a cow's tail, a handle) can decimate
   into the body next to it; removing the crossings then cuts the part away, and its volume
   is too small for any volume check to see (the cow's tail: 7 % of its length, 0.01 % of
   its volume); the distance sees it. A copy that fails is replaced by a finer one.

Where the copy of the shortest edges holds too little of the input's solid (parts thinner
than the tets, whose rims and tips the midpoint collapses cut back), the copies are made by
quadric-error collapses instead (``copy_kept``), through the same fit and checks.

The full-resolution surface stays the artist's (``PrepareReport.surface``); only the
simulation sees the copy.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from .copy_kept import MIN_COPY_KEPT, QUADRIC_MIN_GAIN, HeldShare, decimate_qslim
from .validate import self_intersections

#: A triangle of the simplified copy has edges about this many times the edge of a regular tet
#: of the target particle volume (:func:`tet_edge`), about 1.7 particle spacings: from copies
#: of such even triangles TetGen lands within 12 % of the target on the 30 test meshes, and
#: 2.5 times the triangles of a copy at 1.3 (the factor of primitives) follow curved parts 2.5
#: times as closely (a chord's gap from a curve goes with its length squared).
EDGE_FACTOR = 0.82
#: Simplify when the surface has more than this many times the triangles the target needs
#: (thin parts can need fewer than that count: the copies then get coarser, see below).
FINER_FACTOR = 1.0
#: A simplified copy's volume may differ from the input's by this fraction at most.
VOLUME_TOLERANCE = 0.005
#: Fewest triangles a simplified copy keeps (a coarser copy loses the shape, not just detail).
MIN_FACES = 500
#: Largest distance from a point of the input to the copy, in tet edges (:func:`tet_edge`).
#: The fitted copies of the test meshes lie within 0.9 edges of every input point (the
#: sword's tapered blade; 0.6 at most elsewhere); a lost thin part lies its length away (the
#: cow's tail: 2.4 edges).
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


def _decimate_quadric(vertices: np.ndarray, faces: np.ndarray, face_count: int):
    """``face_count`` triangles of (``vertices``, ``faces``) by quadric error metrics
    (fast-simplification): the staged copy of a large surface."""
    import fast_simplification

    reduction = 1.0 - face_count / len(faces)
    # The decimator's error thresholds are absolute: work at unit size so that the same shape
    # decimates the same way in millimetres or metres.
    centre = vertices.mean(axis=0)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    unit = np.ascontiguousarray((vertices - centre) / size, dtype=np.float64)
    v, f = fast_simplification.simplify(unit, np.ascontiguousarray(faces, dtype=np.int64), target_reduction=reduction)
    return np.asarray(v, dtype=np.float64) * size + centre, np.asarray(f, dtype=np.int64)


def _decimate(vertices: np.ndarray, faces: np.ndarray, face_count: int):
    """``face_count`` triangles of the closed manifold (``vertices``, ``faces``) by collapsing
    the shortest edge first, each to its midpoint, no collapse making faces cross (libigl's
    ``decimate``): triangles of nearly equal edges (1st-99th percentile 0.65-1.65 of the
    median), which TetGen fills with as few tets as their size allows. Quadric decimation
    keeps the shape closer at a given count, but its long thin triangles (edge ratios up to
    20 on a torus) make TetGen's quality bound add tets: 5,900-21,000 for a target of 5,000
    on a torus of 828 triangles, 5,000 from the same count of even ones. Falls back to
    quadric decimation when libigl stops short of the count."""
    import igl

    return libigl_decimation(lambda v, f, n: igl.decimate(v, f, n, True), vertices, faces, face_count)


def libigl_decimation(collapse, vertices: np.ndarray, faces: np.ndarray, face_count: int):
    """``face_count`` triangles of (``vertices``, ``faces``) by one of libigl's collapses
    (``collapse(V, F, n)`` returning its (V, F, ...) tuple), or by :func:`_decimate_quadric`
    where libigl fails or stops short of the count."""
    try:
        v, f, _, _ = collapse(np.asarray(vertices, dtype=np.float64, order="F"),
                              np.asarray(faces, dtype=np.int32, order="F"), int(face_count))
    except (RuntimeError, ValueError):
        return _decimate_quadric(vertices, faces, face_count)
    if len(f) == 0 or len(f) > 1.1 * face_count:
        return _decimate_quadric(vertices, faces, face_count)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


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
        _undo_turned(relaxed, before, normals_before, cos_turn)  # (the moves around faces that turned too far)
    return relaxed


def restore_volume(mesh: trimesh.Trimesh, volume: float, passes: int = 2) -> trimesh.Trimesh:
    """Move the vertices along their (area-weighted) normals by (volume - mesh volume) / area,
    ``passes`` times: the first-order offset that restores ``volume`` [m^3]."""
    mesh = mesh.copy()
    for _ in range(passes):
        offset = (volume - mesh.volume) / mesh.area
        mesh.vertices = mesh.vertices + offset * mesh.vertex_normals
    return mesh


#: Points sampled on the input for each triangle of the copy that is fitted to it
#: (:func:`fit_to_surface`), and rounds of the fit.
FIT_SAMPLES_PER_FACE = 30
FIT_ROUNDS = 4


def surface_samples(mesh: trimesh.Trimesh, count: int, seed: int = 0) -> np.ndarray:
    """(count,3) [m] random points on ``mesh``'s triangles, evenly by area."""
    tri = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces)]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    t = tri[pick]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _barycentric(points, a, b, c):
    """(P,3) barycentric weights of ``points`` in the triangles (a, b, c), clipped to [0, 1]."""
    e0, e1, e2 = b - a, c - a, points - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("ij,ij->i", e2, e0), np.einsum("ij,ij->i", e2, e1)
    det = np.maximum(d00 * d11 - d01 * d01, 1e-300)
    v = (d11 * d20 - d01 * d21) / det
    w = (d00 * d21 - d01 * d20) / det
    return np.clip(np.column_stack([1.0 - v - w, v, w]), 0.0, 1.0)


def _undo_turned(mesh: trimesh.Trimesh, before: np.ndarray, normals_before: np.ndarray, cos_turn: float) -> None:
    """Put back (to ``before``) the vertices of faces of ``mesh`` whose normal turned further
    than the angle of ``cos_turn`` from ``normals_before``, until none does."""
    faces = np.asarray(mesh.faces)
    for _ in range(5):
        turned = np.einsum("ij,ij->i", mesh.face_normals, normals_before) < cos_turn
        if not turned.any():
            return
        undo = np.unique(faces[turned])
        vertices = mesh.vertices.copy()
        vertices[undo] = before[undo]
        mesh.vertices = vertices


def _uncross(mesh: trimesh.Trimesh, before: np.ndarray, rounds: int = 8) -> trimesh.Trimesh:
    """``mesh`` with the vertices of faces that cross each other put back to ``before`` (a
    position where they did not), round after round until nothing crosses (or ``rounds``)."""
    for _ in range(rounds):
        pairs = self_intersections(mesh.vertices, mesh.faces)
        if len(pairs) == 0:
            break
        undo = np.unique(np.asarray(mesh.faces)[np.unique(pairs)])
        vertices = np.asarray(mesh.vertices, dtype=np.float64).copy()
        vertices[undo] = before[undo]
        mesh = mesh.copy()
        mesh.vertices = vertices
    return mesh


def _pull(vertices: np.ndarray, faces: np.ndarray, samples: np.ndarray, reach: float):
    """Each vertex's share of the gaps from the surface (``vertices``, ``faces``) to
    ``samples``: every sample's vector from its closest point on the surface (left out beyond
    ``reach``), shared among that triangle's corners by their barycentric weights. Returns the
    (V,3) weighted mean gap of each vertex [m] and (P,) each sample's gap length [m] and
    closest face."""
    import igl

    squared, face, closest = igl.point_mesh_squared_distance(samples, vertices, faces)
    gap = samples - closest
    use = squared <= reach**2
    weights = _barycentric(closest[use], *(vertices[faces[face[use], k]] for k in range(3)))
    corners = faces[face[use]].ravel()
    total = np.bincount(corners, weights=weights.ravel(), minlength=len(vertices))
    move = np.stack([np.bincount(corners, weights=(weights * gap[use, k, None]).ravel(), minlength=len(vertices))
                     for k in range(3)], axis=1)
    return move / np.maximum(total, 1e-300)[:, None], np.sqrt(squared), face


def fit_to_surface(copy: trimesh.Trimesh, reference: trimesh.Trimesh, volume: float | None = None, *,
                   rounds: int = FIT_ROUNDS, samples: np.ndarray | None = None,
                   max_turn_deg: float = 25.0) -> trimesh.Trimesh:
    """``copy`` with its vertices moved to the least-squares fit of the ``reference`` surface
    (the finer surface it approximates), given ``volume`` [m^3] back (default: none), inside
    the reference's bounding box and spanning it.

    A copy whose vertices lie on the reference cuts every convex part short by its chords
    (and bulges out of concave ones); a uniform offset that gives the volume back pushes flat
    parts and tips out and leaves curved and thin parts in (a quadric copy of the armadillo
    of 922 triangles: 96.4 % of its solid inside, the box 1 % larger). Here each round takes
    points spread evenly on the reference (``samples``; :data:`FIT_SAMPLES_PER_FACE` a
    triangle of the copy by default) and moves every vertex by its share of their gaps
    (:func:`_pull`): where a sample's closest point lies inside a triangle its gap is along
    the normal, so the reference ends up as much outside the copy as inside around every
    vertex; where it lies on an edge or corner (beyond a blunted rim or tip) the gap also
    pulls sideways, out to the rim. After :data:`FIT_ROUNDS` rounds the volume is nearly right by itself (0.2 % off
    on the armadillo), and the uniform offset that follows is small. Samples farther from the
    copy than two of its mean edges (a part it does not follow) are left out; a move that
    turns a face by more than ``max_turn_deg``, or makes faces cross, is undone. No vertex may
    leave the reference's box, and on each side of it the copy's outermost vertex moves out
    onto it (:func:`_snap_extremes`), so the extents are the reference's.
    """
    fitted = copy.copy()
    faces = np.asarray(fitted.faces, dtype=np.int64)
    if samples is None:
        samples = surface_samples(reference, max(20_000, FIT_SAMPLES_PER_FACE * len(faces)))
    lo, hi = reference.bounds
    reach = 2.0 * float(np.mean(fitted.edges_unique_length))
    cos_turn = np.cos(np.radians(max_turn_deg))
    for _ in range(rounds):
        vertices = np.asarray(fitted.vertices, dtype=np.float64)
        normals_before = fitted.face_normals.copy()
        move, _, _ = _pull(vertices, faces, samples, reach)
        fitted.vertices = np.clip(vertices + move, lo, hi)
        _undo_turned(fitted, vertices, normals_before, cos_turn)
    fitted = _uncross(fitted, np.asarray(copy.vertices, dtype=np.float64))
    if volume is not None:
        before = np.asarray(fitted.vertices, dtype=np.float64).copy()
        fitted = restore_volume(fitted, volume)
        fitted.vertices = np.clip(fitted.vertices, lo, hi)
        fitted = _uncross(fitted, before)
    return _snap_extremes(fitted, reference)


def _snap_extremes(copy: trimesh.Trimesh, reference: trimesh.Trimesh) -> trimesh.Trimesh:
    """``copy`` with its outermost vertex on each side of the reference's bounding box moved
    out along that axis onto the box's side, so the copy spans the box (a tip the copy cut
    short is its reference's length again); a move that turns a face over or makes faces
    cross is left out."""
    lo, hi = reference.bounds
    result = copy
    for side in range(6):
        axis = side % 3
        vertices = np.asarray(result.vertices, dtype=np.float64)
        index = int(vertices[:, axis].argmin() if side < 3 else vertices[:, axis].argmax())
        bound = lo[axis] if side < 3 else hi[axis]
        if vertices[index, axis] == bound:
            continue
        moved = vertices.copy()
        moved[index, axis] = bound
        candidate = result.copy()
        candidate.vertices = moved
        around = np.flatnonzero((np.asarray(result.faces) == index).any(axis=1))
        if np.any(np.einsum("ij,ij->i", candidate.face_normals[around], result.face_normals[around]) <= 0.0):
            continue
        if len(self_intersections(candidate.vertices, candidate.faces)) == 0:
            result = candidate
    return result


def _copy_at(mesh: trimesh.Trimesh, count: int, volume: float, near, clock=None, relax: bool = True,
             reference: trimesh.Trimesh | None = None, decimate=None, fit: bool = True):
    """One decimation of ``mesh`` to ``count`` faces (``decimate``, default :func:`_decimate`),
    relaxed (``relax``), fitted to ``reference`` (the full surface, default ``mesh``; ``fit``)
    and given ``volume`` [m^3] back: (copy, how) when it comes out closed, non-crossing,
    within :data:`VOLUME_TOLERANCE` of ``volume`` and ``near`` the input, else None."""
    decimate = decimate or _decimate
    step = ("simplify (fast-simplification)" if decimate is _decimate_quadric else
            "simplify (libigl qslim)" if decimate is decimate_qslim else "simplify (libigl)")
    if clock is not None:
        v, f = clock.run(step, decimate, mesh.vertices, mesh.faces, count)
    else:
        v, f = decimate(mesh.vertices, mesh.faces, count)
    copy = trimesh.Trimesh(v, f, process=True)
    if not (copy.is_watertight and copy.is_winding_consistent and copy.volume > 0
            and abs(copy.volume / volume - 1.0) < 0.2):
        return None
    reference = mesh if reference is None else reference
    relaxed = relax_tangentially(copy, reference=mesh) if relax else copy
    # Fitted to the input first; fitting or restoring the volume can push thin walls through
    # each other: then the copy with a uniform offset, or as it is, if its volume is within
    # VOLUME_TOLERANCE; the unrelaxed copy is the last resort (its thin triangles make more
    # tets than asked for).
    lo, hi = reference.bounds

    def in_box(candidate):
        candidate = candidate.copy()
        candidate.vertices = np.clip(candidate.vertices, lo, hi)
        return candidate

    fits = {}

    def fitted(start):  # (each fit once: the MeshFix fall-back below starts from one of them)
        if id(start) not in fits:
            fits[id(start)] = fit_to_surface(start, reference, volume)
        return fits[id(start)]

    candidates = [(lambda: fitted(copy), "fitted to the input")] if fit else []
    if relax:
        if fit:
            candidates[:0] = [(lambda: fitted(relaxed), "relaxed, fitted to the input")]
        candidates += [(lambda: in_box(restore_volume(relaxed, volume)), "relaxed, volume restored"),
                       (lambda: relaxed, "relaxed")]
    candidates += [(lambda: in_box(restore_volume(copy, volume)), "volume restored"), (lambda: copy, "as decimated")]
    for make, how in candidates:
        candidate = make()
        if abs(candidate.volume / volume - 1.0) > VOLUME_TOLERANCE:
            continue
        if len(self_intersections(candidate.vertices, candidate.faces)) == 0 and near(candidate):
            return candidate, how
    # Thin parts (legs, ears) decimated into each other: MeshFix removes the crossings (and,
    # when it cuts a thin part away, the distance bound refuses the result).
    cleaned = _meshfix_copy(fitted(relaxed) if fit else restore_volume(relaxed, volume), clock)
    if cleaned is not None and abs(cleaned.volume / volume - 1.0) < 0.05:
        cleaned = in_box(restore_volume(cleaned, volume))
        if (abs(cleaned.volume / volume - 1.0) <= VOLUME_TOLERANCE
                and len(self_intersections(cleaned.vertices, cleaned.faces)) == 0 and near(cleaned)):
            return cleaned, ("relaxed, " if relax else "") + "crossings removed by pymeshfix, volume restored"
    return None


def simplify_to_faces(mesh: trimesh.Trimesh, face_count: int, clock=None, reference_volume: float | None = None,
                      max_deviation: float | None = None, reference_points: np.ndarray | None = None,
                      finer: trimesh.Trimesh | None = None, relax: bool = True, fit: bool = True,
                      decimate=None):
    """A closed, non-crossing copy of ``mesh`` [m] decimated to about ``face_count`` faces
    (``decimate``: default :func:`_decimate`), relaxed, fitted to the full surface (``finer``,
    else ``mesh``; :func:`fit_to_surface`), with ``reference_volume`` (default: the mesh's)
    [m^3], and no point of
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
            copy = _copy_at(source, count, volume, near, clock, relax, reference=finer if finer is not None else mesh,
                            decimate=decimate, fit=fit)
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
    """Surfaces for ``target_particles`` tets, coarsest last: a generator the caller drives
    with the tet count each surface gave (``send``). Yields (surface, description or None).

    The first is a copy with :func:`target_face_count` faces, or, when ``mesh`` is not finer
    than that, ``mesh`` itself (description None). When its tets overshoot the target by more
    than 15 % (thin parts, many sharp features), the next is a copy with fewer faces, by the
    overshoot to the 2/3 (tets ~ faces^(3/2) where the surface sets the count); three copies
    at most. A large input is first decimated once to 8x the wanted faces, so later copies
    start small. A first copy that holds under :data:`MIN_COPY_KEPT` of ``mesh``'s solid is
    replaced by a quadric-error copy (:func:`_quadric_copy`) where that holds more, and the
    later copies are made that way too (by the overshoot to the power 1: a thin part one tet
    thick has tets ~ faces). Every copy lies within :data:`MAX_DEVIATION` tet edges of every point of
    ``mesh`` and is fitted to it (:func:`fit_to_surface`).
    """
    wanted = target_face_count(mesh.volume, mesh.area, target_particles)
    count = wanted
    if len(mesh.faces) <= FINER_FACTOR * wanted:
        tets = yield mesh, None
        if tets is None or tets <= 1.15 * target_particles:
            return
        count = int(len(mesh.faces) * (target_particles / tets) ** (2 / 3) * 0.95)
        if count < MIN_FACES:
            return
    volume = float(mesh.volume)
    bound = dict(max_deviation=MAX_DEVIATION * tet_edge(volume, target_particles),
                 reference_points=deviation_points(mesh))
    source = mesh
    if len(mesh.faces) > 16 * wanted:
        # Only decimated further (by quadric errors: libigl takes seconds on a million faces):
        # relaxing or fitting it would buy nothing.
        staged = simplify_to_faces(mesh, 8 * wanted, clock, relax=False, fit=False, decimate=_decimate_quadric,
                                   **bound)
        if staged is not None:
            source = staged[0]
    # Which decimation the copies take: shortest edges first; quadric errors from the first
    # copy on whose shortest-edge copy holds less than MIN_COPY_KEPT of the solid and whose
    # quadric copy holds QUADRIC_MIN_GAIN more (thin parts; see copy_kept).
    held, quadric = HeldShare(mesh, clock), None
    for _ in range(3):
        copy = None if quadric else simplify_to_faces(source, count, clock, reference_volume=volume,
                                                      finer=None if source is mesh else mesh, **bound)
        if copy is not None:
            copy, how = copy[0], f"shortest edges collapsed, {copy[1]}"
        if quadric is None and copy is not None:
            share = held(copy)
            if share < MIN_COPY_KEPT:
                other = _quadric_copy(source, mesh, count, volume, clock, bound)
                other_share = held(other[0]) if other is not None else 0.0
                quadric = other_share > share + QUADRIC_MIN_GAIN
                if quadric:
                    copy, how = other[0], (f"quadric-error collapses, {other[1]}: it holds {100 * other_share:.1f} % "
                                           f"of the solid, the copy of the shortest edges {100 * share:.1f} %")
        elif quadric:
            other = _quadric_copy(source, mesh, count, volume, clock, bound)
            copy, how = (other[0], f"quadric-error collapses, {other[1]}") if other is not None else (None, None)
        if copy is None:
            return
        tets = yield copy, (f"tetrahedralized a copy simplified to the particle spacing: {len(mesh.faces):,} -> "
                            f"{len(copy.faces):,} faces ({how})")
        if tets is None or tets <= 1.15 * target_particles:
            return
        if len(copy.faces) <= MIN_FACES * 1.05:
            return
        # Where the surface sets the count, tets ~ faces^(3/2); a quadric copy's thin parts are
        # one tet thick under the mesher's unsplit surface, where tets ~ faces.
        power = 1.0 if quadric else 2 / 3
        count = max(int(len(copy.faces) * (target_particles / tets) ** power * 0.95), MIN_FACES)


def _quadric_copy(source, mesh, count: int, volume: float, clock, bound: dict):
    """(copy, how) of ``source`` with ``count`` faces by quadric-error collapses
    (``copy_kept.decimate_qslim``), fitted to ``mesh``, or None."""
    return simplify_to_faces(source, count, clock, reference_volume=volume, finer=None if source is mesh else mesh,
                             relax=False, decimate=decimate_qslim, **bound)


def simplify_for_target(mesh: trimesh.Trimesh, target_particles: int, clock=None):
    """The first copy of :func:`simplified_tet_surfaces` (copy, description), or None when
    ``mesh`` is not finer than the target spacing."""
    first = next(simplified_tet_surfaces(mesh, target_particles, clock), None)
    return None if first is None or first[1] is None else first
