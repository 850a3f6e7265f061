"""Where the flat crack faces go so each piece keeps its tets' volume.

A crack cuts the bonds whose particles (tet centroids) lie on its two sides; the tets
themselves straddle it, so two pieces' tets meet along a staircase about a tet deep (some
two particle spacings), and a flat crack face through it gives one side more than its tets
and the other less: a piece of a hundred tets is off by several per cent. The physics fixes
the face's position only to within that staircase. This module measures a first cut's
pieces and moves each crack within it so that the pieces' volumes come as near their tets'
as the cracks allow in the least-squares sense:

- a crack plane is shifted along its normal by d and tilted: its shift at a point u of the
  plane (in its tangent frame about a pivot, the mean of the bond crossings it cuts) is
  d + (a1 u1 + a2 u2) / R, R the farthest crossing's distance from the pivot. A row of
  pieces along one radial crack of a pane needs the tilt: one shift cannot suit them all;
- a ring crack's sphere grows or shrinks by d.

A face on a crack of outward area vector A changes its piece's volume by the shift under it
times A . n (n the crack's normal there), so the pieces' volumes are linear in (d, a1, a2)
and the moves solve a small bounded linear problem. The bonds, the pieces and their mass
stay as the physics made them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blas import one_blas_thread
from ..fracture.crack_types import CrackPlane

#: Largest shift [particle spacings] of a crack plane at its pivot, or of a ring crack's radius:
#: about a quarter of a tet's height, well inside the staircase the same cut bonds allow.
MAX_OFFSET_FACTOR = 0.5
#: Largest shift [particle spacings] the tilt adds at a plane's farthest crossing (each of a1,
#: a2 within this over sqrt(2)): a plane moves at most a spacing anywhere, about half a tet.
MAX_TILT_FACTOR = 0.5

#: The columns of an offset row: the shift at the pivot (a sphere: its radius), then the
#: tilt's shifts [m] at the reach R along the plane's two tangent axes.
MOVES = 3

#: Only pieces of this many tets or more enter the fit: a piece of a few tets where cracks meet
#: differs from its planes by a large share whatever they do, and must not pull the planes of
#: the large pieces around it.
FITTED_PIECE_TETS = 100

#: Where smaller pieces are fitted too (``cut_render_solid``'s ``fit_min_tets``), a piece of
#: fewer than FITTED_PIECE_TETS tets counts this much of a larger one's relative volume error:
#: the larger pieces keep their bound first (counted alike, stretches shifted for the small
#: pieces can push a large neighbour past its bound).
SMALL_PIECE_WEIGHT = 0.1

#: No second cut when every fitted piece is already within this share of its tets' volume.
VOLUME_TOLERANCE = 0.01

#: Weight of the offsets themselves [per particle spacing, squared] against the pieces'
#: relative volume errors: keeps a plane no piece measures where the analysis put it.
OFFSET_WEIGHT = 1e-4


def piece_target_volumes(scale: float, model, fragment_tets) -> np.ndarray:
    """(F,) [m^3] each piece's share of the render solid: its tets' volume times ``scale``, the
    unbroken body's render volume over its tets' (the artist's surface and the tets' boundary
    differ). Not the breaking piece's own ratio: that carries its own cut's misfit, which
    would pass to all its pieces alike instead of being mended where it lies."""
    return np.array([scale * model.tet_volume[np.asarray(t, dtype=np.int64)].sum() for t in fragment_tets])


def volume_errors(solids, targets: np.ndarray, fragment_tets, min_tets: int = FITTED_PIECE_TETS) -> np.ndarray:
    """(F,) the relative volume error of each piece the fit reads (a solid and at least
    ``min_tets`` tets; NaN for the others). ``solids``: manifolds or None."""
    return np.array([s.volume() / v - 1.0 if s is not None and len(t) >= min_tets and v > 0 else np.nan
                     for s, v, t in zip(solids, targets, fragment_tets)])


def volume_misfit(solids, targets: np.ndarray, fragment_tets, min_tets: int = FITTED_PIECE_TETS) -> float:
    """The fit's measure: the sum of the squared ``volume_errors``, each weighted by
    ``error_weights``."""
    return float(np.nansum((error_weights(fragment_tets) * volume_errors(solids, targets, fragment_tets,
                                                                          min_tets)) ** 2))


def error_weights(fragment_tets) -> np.ndarray:
    """(F,) each piece's weight on its relative volume error: 1, or SMALL_PIECE_WEIGHT under
    FITTED_PIECE_TETS tets."""
    return np.array([1.0 if len(t) >= FITTED_PIECE_TETS else SMALL_PIECE_WEIGHT for t in fragment_tets])


@dataclass(frozen=True)
class TiltFrame:
    """Where a plane crack tilts about: ``pivot`` (3,) [m] on the analysis plane, its tangent
    axes ``e1``, ``e2`` (3,) and ``reach`` [m], the farthest crossing's distance from it."""

    pivot: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    reach: float


def tilt_frames(cracks, crossings, spacing: float) -> list:
    """For each crack, its TiltFrame (a plane crack with crossings) or None: ``crossings`` a
    list of (N,3) [m] points where the bonds it cuts between pieces cross it (or None)."""
    from .solid import tangent_frame

    frames = []
    for crack, sites in zip(cracks, crossings):
        if not isinstance(crack, CrackPlane) or sites is None or not len(sites):
            frames.append(None)
            continue
        normal = np.asarray(crack.normal, dtype=np.float64)
        centre = np.mean(sites, axis=0)
        pivot = centre - float((centre - crack.point) @ normal) * normal
        rel = sites - pivot
        rel -= np.outer(rel @ normal, normal)
        e1, e2 = tangent_frame(normal)
        frames.append(TiltFrame(pivot, e1, e2, max(float(np.sqrt(np.max(np.einsum("ij,ij->i", rel, rel)))),
                                                   spacing)))
    return frames


def moved_crack(crack, frame: TiltFrame | None, move: np.ndarray):
    """The CrackSurface of ``crack`` (CrackPlane / RingCrack) moved by ``move`` (MOVES,) [m]:
    a plane shifted by move[0] at ``frame``'s pivot and tilted so that it is shifted by
    move[1] (move[2]) more at the reach along e1 (e2); a sphere's radius grown by move[0]."""
    from .solid import CrackSurface

    move = np.asarray(move, dtype=np.float64)
    if not isinstance(crack, CrackPlane):
        return CrackSurface(np.asarray(crack.point, float), np.zeros(3), float(crack.radius) + float(move[0]))
    normal = np.asarray(crack.normal, dtype=np.float64)
    if frame is None or not np.any(move):
        return CrackSurface(np.asarray(crack.point, float) + float(move[0]) * normal, normal)
    # The plane h(u) = d + (a1 u1 + a2 u2) / R over the pivot's tangent frame.
    tilted = normal - (move[1] * frame.e1 + move[2] * frame.e2) / frame.reach
    return CrackSurface(frame.pivot + float(move[0]) * normal, tilted / np.linalg.norm(tilted))


def crack_face_moves(solid, origin, index_of: np.ndarray, cracks, frames) -> np.ndarray:
    """(C, MOVES) [m^2] how ``solid``'s volume changes per metre of each crack's moves (see
    ``moved_crack``): for each crack with a slab (``index_of`` its crack-property index, -1
    none), the sum over its faces of (outward area vector . the crack's normal) times the
    shift each move makes under the face's centroid; 0 for the others. ``origin`` (3,) [m]:
    the solid's frame origin in the body's (where ``frames`` are). The faces of a slit inside
    the piece, one of each side, cancel."""

    crack, area_vector, centroid = _crack_faces(solid, origin)
    moves = np.zeros((len(index_of), MOVES))
    for k, index in enumerate(index_of):
        rows = crack == index
        if index < 0 or not rows.any():
            continue
        if isinstance(cracks[k], CrackPlane):
            flux = area_vector[rows] @ np.asarray(cracks[k].normal, dtype=np.float64)
            moves[k, 0] = float(np.sum(flux))
            frame = frames[k] if frames is not None else None
            if frame is not None:
                rel = centroid[rows] - frame.pivot
                moves[k, 1] = float(np.sum(flux * (rel @ frame.e1))) / frame.reach
                moves[k, 2] = float(np.sum(flux * (rel @ frame.e2))) / frame.reach
        else:
            radial = centroid[rows] - np.asarray(cracks[k].point, dtype=np.float64)
            radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
            moves[k, 0] = float(np.einsum("ij,ij->", area_vector[rows], radial))
    return moves


def _crack_faces(solid, origin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``solid``'s faces: (crack (F,) the crack index all three corners carry, -1 where they
    differ; outward area vectors (F,3) [m^2]; centroids (F,3) [m]), in the body's frame
    (``origin`` (3,) [m] the solid's frame origin there)."""
    from .layout import CRACK
    from .solid import solid_arrays

    props, tri = solid_arrays(solid)
    crack = np.rint(np.nan_to_num(props[tri, CRACK], nan=-1.0)).astype(np.int64)  # (F,3)
    crack = np.where((crack == crack[:, :1]).all(axis=1), crack[:, 0], -1)
    corners = props[tri, :3] + np.asarray(origin, dtype=np.float64)
    area_vector = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return crack, area_vector, corners.mean(axis=1)


def volume_offsets(solids, index_of: np.ndarray, cracks, targets: np.ndarray, fragment_tets,
                   spacing: float, moved: np.ndarray | None = None, frames=None,
                   origins=None, shifts_only: bool = False, frozen=None,
                   min_tets: int = FITTED_PIECE_TETS) -> tuple[np.ndarray, float]:
    """The moves of each crack (see ``moved_crack``) that bring the pieces' volumes nearest
    ``targets`` (F,) [m^3]: least squares over the ``volume_errors``, each plane's shift within
    MAX_OFFSET_FACTOR ``spacing`` at its pivot and its tilt within MAX_TILT_FACTOR at its
    reach, a sphere's radius within MAX_OFFSET_FACTOR. ``solids``: a cut's pieces' manifolds
    (None: no solid) in their frames, whose origins in the body's are ``origins`` (F,3) [m]
    (None: the body's own), made with the cracks already ``moved`` (C, MOVES) [m] (None: none);
    ``frames``: each crack's TiltFrame or None (no tilt; None: none tilts); ``frozen`` (C,)
    bool the cracks that stay (None: none); ``min_tets``: the least tets of a piece the fit
    reads.

    The planes' shifts alone are fitted first, and kept when they promise as much as every
    move (tilts and the spheres' radii too) or every piece within VOLUME_TOLERANCE: fewer
    moves keep the linear model nearer what the cut gives (``shifts_only``: only those).
    Returns (change, predicted): change (C, MOVES) [m] the further moves (all 0 when every
    error is within VOLUME_TOLERANCE), predicted the ``volume_misfit`` the linear model
    expects after it. Cracks without a slab stay."""

    errors = volume_errors(solids, targets, fragment_tets, min_tets)
    now = float(np.nansum(errors**2))
    if not np.nanmax(np.abs(errors), initial=0.0) > VOLUME_TOLERANCE:
        return np.zeros((len(cracks), MOVES)), now
    # Each fitted piece's relative error after the moves x [spacings]: error + moves . x / target.
    origins = np.zeros((len(solids), 3)) if origins is None else np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    pieces = [(crack_face_moves(solid, origin, index_of, cracks, frames) * spacing / target, error)
              for solid, origin, target, error in zip(solids, origins, targets, errors) if not np.isnan(error)]
    moved = np.zeros((len(cracks), MOVES)) if moved is None else np.asarray(moved).reshape(len(cracks), MOVES)
    # The free columns: the planes' shifts; then every slab's shift (a sphere: its radius) and
    # the tilts of planes with a frame.
    movable = (index_of >= 0) & (True if frozen is None else ~np.asarray(frozen, dtype=bool))
    free = np.zeros((len(cracks), MOVES), dtype=bool)
    free[:, 0] = movable & np.array([isinstance(c, CrackPlane) for c in cracks], dtype=bool)
    shifts = _fit(free, pieces, moved / spacing, now, spacing)
    if shifts_only:
        return shifts
    free[:, 0] = movable
    if frames is not None:
        free[:, 1:] = np.array([f is not None for f in frames], dtype=bool)[:, None] & movable[:, None]
    every = _fit(free, pieces, moved / spacing, now, spacing)
    return shifts if shifts[1] <= max(every[1], VOLUME_TOLERANCE**2) else every


def _fit_problem(free: np.ndarray, pieces, already: np.ndarray):
    """The fit over the moves ``free`` (C, MOVES) bool (``_fit``'s arguments): (rows (P, n)
    each piece's error change per spacing of each free move, the pieces' errors (P,), the
    further moves' bounds lo, hi (n,) [spacings]: a shift within MAX_OFFSET_FACTOR, a tilt
    within MAX_TILT_FACTOR / sqrt 2, less the moves made), or None when no piece has a face
    on a free crack."""
    rows = [(moves[free], error) for moves, error in pieces if np.any(moves[free])]
    if not rows:
        return None
    bound = np.where(np.nonzero(free)[1] == 0, MAX_OFFSET_FACTOR, MAX_TILT_FACTOR / np.sqrt(2.0))
    return (np.array([row for row, _ in rows]), np.array([error for _, error in rows]),
            -bound - already[free], bound - already[free])


def _fit(free: np.ndarray, pieces, already: np.ndarray, now: float, spacing: float) -> tuple[np.ndarray, float]:
    """``volume_offsets``' least squares over the moves ``free`` (C, MOVES) bool: ``pieces``
    each fitted piece's (moves (C, MOVES) per spacing over its target, error), ``already``
    (C, MOVES) the moves made [spacings], ``now`` the misfit before. Returns (change (C,
    MOVES) [m], predicted misfit)."""
    from scipy.optimize import lsq_linear

    change = np.zeros(free.shape)
    problem = _fit_problem(free, pieces, already)
    if problem is None:
        return change, now
    rows, misfits, lo, hi = problem
    already = already[free]
    # (the weight is on the total moves)
    a = np.vstack([rows, np.sqrt(OFFSET_WEIGHT) * np.eye(len(already))])
    b = np.concatenate([-misfits, -np.sqrt(OFFSET_WEIGHT) * already])
    with one_blas_thread():
        fit = lsq_linear(a, b, bounds=(lo, hi))
    change[free] = fit.x * spacing
    # (the pieces without faces on a free crack keep their errors)
    return change, now - float(np.sum(misfits**2)) + float(np.sum((rows @ fit.x + misfits) ** 2))


# Segments: one plane crack, a shift of its own under each pair of pieces it parts.

#: The sparse segment fit's price of a piece's relative volume error against a shift of a
#: segment by one particle spacing.
ERROR_PRICE = 1e3


@dataclass(frozen=True)
class CrackSegments:
    """The stretches of the plane cracks between one pair of pieces each. A plane crack that
    parts many pieces (a radial crack of a pane, a row of shards on each side) has a dozen
    volumes to suit and three moves to do it with; giving each of its pairs of pieces its own
    shift along the normal fits them one by one. ``crack`` (S,) the crack each segment lies
    on; ``of_site`` for each crack, (N,) the segment of each of its bond crossings (the sites
    of ``piece_surface._separating_cracks``; -1: a crossing cut inside one piece, or one it
    does not cut), or None for a crack without segments (a ring crack, or a plane between one
    pair of pieces: its own shift does that); ``pieces`` (S,2) the pair (-1: dropped tets);
    ``trees`` each crack's k-d tree of its cut
    crossings (None: none), ``cut_segment`` (M,) their segments."""

    crack: np.ndarray
    pieces: np.ndarray
    of_site: list
    trees: list
    cut_segment: list

    @property
    def count(self) -> int:
        return len(self.crack)


def crack_segments(per_crack, piece_count: int) -> CrackSegments:
    """The segments of the plane cracks: ``per_crack`` each crack's (sites (N,3) [m], cut (N,)
    bool, inside (N,), pieces (N,2) the pieces on the bond's two ends, -1: a dropped tet) as
    ``piece_surface._separating_cracks`` gives them (a ring crack's sites None)."""
    from scipy.spatial import cKDTree

    crack, pieces, of_site, trees, cut_segment = [], [], [], [], []
    for i, (sites, cut, inside, ends) in enumerate(per_crack):
        if sites is None or not len(sites):
            of_site.append(None), trees.append(None), cut_segment.append(None)
            continue
        between = cut & (inside < 0)
        ends = np.sort(ends, axis=1) + 1
        code = np.where(between, ends[:, 0] * (piece_count + 1) + ends[:, 1], -1)
        pairs = np.unique(code[between])
        if len(pairs) < 2:
            of_site.append(None), trees.append(None), cut_segment.append(None)
            continue
        segment = np.full(len(sites), -1, dtype=np.int64)
        segment[between] = len(crack) + np.searchsorted(pairs, code[between])
        crack.extend([i] * len(pairs))
        pieces.extend(np.stack([pairs // (piece_count + 1), pairs % (piece_count + 1)], axis=1) - 1)
        of_site.append(segment)
        trees.append(cKDTree(sites[cut]))
        cut_segment.append(segment[cut])
    return CrackSegments(np.array(crack, dtype=np.int64), np.array(pieces, dtype=np.int64).reshape(-1, 2), of_site,
                         trees, cut_segment)


def segment_face_moves(solid, origin, sources: np.ndarray, cracks, segments: CrackSegments) -> np.ndarray:
    """(S,) [m^2] how ``solid``'s volume changes per metre each segment is shifted along its
    crack's normal: the sum of (outward area vector . normal) over the crack faces nearer
    that segment's crossings than any other cut crossing of the crack. ``sources`` (K,) the
    crack behind each crack index of the solid's faces (-1: one it inherited); ``origin``
    (3,) [m] the solid's frame origin in the body's."""
    index, area_vector, centroid = _crack_faces(solid, origin)
    source = np.full(len(index), -1, dtype=np.int64)
    source[index >= 0] = np.asarray(sources, dtype=np.int64)[index[index >= 0]]
    moves = np.zeros(segments.count)
    for k in np.unique(source[source >= 0]):
        if segments.trees[k] is None:
            continue
        rows = source == k
        flux = area_vector[rows] @ np.asarray(cracks[k].normal, dtype=np.float64)
        segment = segments.cut_segment[k][segments.trees[k].query(centroid[rows])[1]]
        mine = segment >= 0
        moves += np.bincount(segment[mine], weights=flux[mine], minlength=segments.count)
    return moves


def segment_shifts(solids, origins, sources: np.ndarray, cracks, segments: CrackSegments, targets: np.ndarray,
                   fragment_tets, spacing: float, already: np.ndarray, frozen=None,
                   min_tets: int = FITTED_PIECE_TETS) -> tuple[np.ndarray, float]:
    """The further shifts (S,) [m] of the segments that bring the pieces' volumes nearest
    ``targets``: the fit of least total shift (``_sparse_fit``) where it promises about as
    much as least squares over the ``volume_errors`` (as ``volume_offsets``), else the
    latter; each segment's whole shift within MAX_OFFSET_FACTOR ``spacing``; ``already`` (S,) [m] the
    shifts the ``solids`` were cut with, ``sources`` their cut's crack behind each crack
    index; ``frozen`` (S,) bool the segments that stay; ``min_tets``: the least tets of a
    piece the fit reads. Returns (change, predicted misfit)."""
    errors = volume_errors(solids, targets, fragment_tets, min_tets)
    weights = error_weights(fragment_tets)
    now = float(np.nansum((weights * errors) ** 2))
    if not segments.count or not np.nanmax(np.abs(errors), initial=0.0) > VOLUME_TOLERANCE:
        return np.zeros(segments.count), now
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    # (each piece's row and error weighted: the fits below then weigh its error so)
    pieces = [(w * segment_face_moves(solid, origin, sources, cracks, segments)[:, None] * spacing / target, w * error)
              for solid, origin, target, error, w in zip(solids, origins, targets, errors, weights)
              if not np.isnan(error)]
    free = np.ones((segments.count, 1), dtype=bool) if frozen is None else ~np.asarray(frozen, dtype=bool)[:, None]
    already = np.asarray(already, dtype=np.float64)[:, None] / spacing
    change, predicted = _fit(free, pieces, already, now, spacing)
    # Least squares spreads the moves over every segment a fitted piece touches, most of them
    # by a hair; each moved segment is a slab of its own, and each step between two a wall
    # the cut must also make. The fit with the fewest moves (least total shift, a linear
    # program) is kept when it promises about as much.
    sparse = _sparse_fit(free, pieces, already, now, spacing)
    if sparse is not None and sparse[1] <= predicted + 0.25 * VOLUME_TOLERANCE**2:
        change, predicted = sparse
    return change[:, 0], predicted


def _sparse_fit(free: np.ndarray, pieces, already: np.ndarray, now: float, spacing: float):
    """As ``_fit``, but minimising ERROR_PRICE x the sum of the pieces' absolute relative
    volume errors plus the sum of the absolute moves [spacings] (a linear program, so most
    moves come out exactly 0). None when the program fails."""
    from scipy.optimize import linprog

    problem = _fit_problem(free, pieces, already)
    if problem is None:
        return None
    a, errors, lo, hi = problem
    p, n = a.shape
    # Variables: moves up, moves down, errors over, errors under (all >= 0); a (up - down) - (over - under) = -e.
    cost = np.concatenate([np.ones(2 * n), ERROR_PRICE * np.ones(2 * p)])
    equality = np.hstack([a, -a, -np.eye(p), np.eye(p)])
    bounds = ([(0.0, max(h, 0.0)) for h in hi] + [(0.0, max(-l, 0.0)) for l in lo] + [(0.0, None)] * (2 * p))
    with one_blas_thread():
        result = linprog(cost, A_eq=equality, b_eq=-errors, bounds=bounds, method="highs")
    if result.status != 0:
        return None
    x = result.x[:n] - result.x[n:2 * n]
    change = np.zeros(free.shape)
    change[free] = x * spacing
    return change, now - float(np.sum(errors**2)) + float(np.sum((a @ x + errors) ** 2))
