"""Where the flat crack faces go so each piece keeps its tets' volume.

A crack plane cuts the bonds whose particles (tet centroids) lie on its two sides; the tets
themselves straddle it, so two pieces' tets meet along a staircase about a tet deep (some
two particle spacings), and a flat crack face through it gives one side more than its tets
and the other less: a piece of a hundred tets is off by several per cent. The physics fixes
the face's position only to within that staircase. This module measures a first cut's
pieces and moves each crack plane parallel to itself, by at most MAX_OFFSET_FACTOR particle
spacings, so that the pieces' volumes come as near their tets' as the planes allow in the
least-squares sense: moving plane k by d changes a piece's volume by d times the signed area
of its faces on that plane, so the offsets solve a small bounded linear problem. The bonds,
the pieces and their mass stay as the physics made them.
"""

from __future__ import annotations

import numpy as np

#: Largest shift [particle spacings] of a crack face from its crack plane: about a quarter of a
#: tet's height, well inside the staircase the same cut bonds allow.
MAX_OFFSET_FACTOR = 0.5

#: Only pieces of this many tets or more enter the fit: a piece of a few tets where cracks meet
#: differs from its planes by a large share whatever they do, and must not pull the planes of
#: the large pieces around it.
FITTED_PIECE_TETS = 100

#: No second cut when every fitted piece is already within this share of its tets' volume.
VOLUME_TOLERANCE = 0.01

#: Weight of the offsets themselves [per particle spacing, squared] against the pieces'
#: relative volume errors: keeps a plane no piece measures where the analysis put it.
OFFSET_WEIGHT = 1e-4


def piece_target_volumes(render_volume: float, model, fragment_tets) -> np.ndarray:
    """(F,) [m^3] each piece's share of the render solid: its tets' volume, scaled by the render
    solid's volume over all the tets' (the artist's surface and the tets' boundary differ)."""
    scale = render_volume / model.volume
    return np.array([scale * model.tet_volume[np.asarray(t, dtype=np.int64)].sum() for t in fragment_tets])


def volume_errors(solids, targets: np.ndarray, fragment_tets) -> np.ndarray:
    """(F,) the relative volume error of each piece the fit reads (a solid and at least
    FITTED_PIECE_TETS tets; NaN for the others). ``solids``: manifolds or None."""
    return np.array([s.volume() / v - 1.0 if s is not None and len(t) >= FITTED_PIECE_TETS and v > 0 else np.nan
                     for s, v, t in zip(solids, targets, fragment_tets)])


def volume_misfit(solids, targets: np.ndarray, fragment_tets) -> float:
    """The fit's measure: the sum of the squared ``volume_errors``."""
    return float(np.nansum(volume_errors(solids, targets, fragment_tets) ** 2))


def plane_face_areas(solid, index_of: np.ndarray, cracks) -> np.ndarray:
    """(C,) [m^2] for each plane crack with a slab (``index_of`` its crack-property index, -1
    none), the signed area of ``solid``'s faces on it: the sum over its faces of area x
    (outward normal . crack normal); 0 for the others. Moving the plane by d along its normal
    changes the solid's volume by d times this; the faces of a slit inside the piece, one of
    each side, cancel."""
    from ..fracture.crack_types import CrackPlane
    from .render_solid import _CRACK, solid_arrays

    props, tri = solid_arrays(solid)
    crack = np.rint(np.nan_to_num(props[tri, _CRACK], nan=-1.0)).astype(np.int64)  # (F,3)
    on_one = (crack == crack[:, :1]).all(axis=1)
    corners = props[tri, :3]
    area_vector = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])  # (F,3)
    areas = np.zeros(len(index_of))
    for k, index in enumerate(index_of):
        if index >= 0 and isinstance(cracks[k], CrackPlane):
            rows = on_one & (crack[:, 0] == index)
            areas[k] = float(np.sum(area_vector[rows] @ np.asarray(cracks[k].normal, dtype=np.float64)))
    return areas


def volume_offsets(solids, index_of: np.ndarray, cracks, targets: np.ndarray, fragment_tets,
                   spacing: float, moved: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The shift of each crack plane along its normal that brings the pieces' volumes nearest
    ``targets`` (F,) [m^3]: least squares over the ``volume_errors``, each plane within
    MAX_OFFSET_FACTOR ``spacing`` of where the analysis put it. ``solids``: a cut's pieces'
    manifolds (None: no solid), made with the planes already ``moved`` (C,) [m] (None: none).
    Returns (change, predicted): change (C,) [m] the further shift (all 0 when every error is
    within VOLUME_TOLERANCE), predicted the ``volume_misfit`` the linear model expects after
    it. Ring cracks and cracks without a slab stay."""
    from scipy.optimize import lsq_linear

    from ..fracture.crack_types import CrackPlane

    offsets = np.zeros(len(cracks))
    errors = volume_errors(solids, targets, fragment_tets)
    now = float(np.nansum(errors**2))
    if not np.nanmax(np.abs(errors), initial=0.0) > VOLUME_TOLERANCE:
        return offsets, now
    # (a ring crack's sphere stays: moving radial planes and rings together re-sorts the
    # small parts where they meet, and the glass walls' pieces came out further off)
    movable = (index_of >= 0) & np.array([isinstance(c, CrackPlane) for c in cracks], dtype=bool)
    if not movable.any():
        return offsets, now
    rows, misfits = [], []
    for solid, target, error in zip(solids, targets, errors):
        if np.isnan(error):
            continue
        areas = plane_face_areas(solid, index_of, cracks)
        if not np.any(areas):
            continue
        # The relative error after the move, error + areas . d / target, d in spacings.
        rows.append(areas * spacing / target)
        misfits.append(error)
    if not rows:
        return offsets, now
    columns = np.nonzero(movable)[0]
    rows, misfits = np.array(rows)[:, columns], np.array(misfits)
    already = np.zeros(len(columns)) if moved is None else np.asarray(moved)[columns] / spacing
    # (the weight is on the total shift)
    a = np.vstack([rows, np.sqrt(OFFSET_WEIGHT) * np.eye(len(columns))])
    b = np.concatenate([-misfits, -np.sqrt(OFFSET_WEIGHT) * already])
    fit = lsq_linear(a, b, bounds=(-MAX_OFFSET_FACTOR - already, MAX_OFFSET_FACTOR - already))
    offsets[columns] = fit.x * spacing
    # (the pieces without faces on a movable plane keep their errors)
    return offsets, now - float(np.sum(misfits**2)) + float(np.sum((rows @ fit.x + misfits) ** 2))
