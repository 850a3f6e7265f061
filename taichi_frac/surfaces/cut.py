"""Render surfaces of broken pieces: the artist's surface outside, the crack's own surface inside.

The physics decides which pieces exist (tets joined by bonds, cut by crack discs and rings;
``fracture/fragments.py``); this module only gives each piece the surface an artist sees.
A body's *render solid* is the artist's closed surface (``PrepareReport.surface``, full
resolution, with its corner normals and UVs) as an exact-arithmetic ``manifold3d`` solid in
the body's frame. When the body breaks, the render solid is cut by thin slabs lying on the
crack geometry, one per crack, covering exactly the part of the crack that separates two
different pieces, and the connected parts that remain are handed to the pieces whose tets
they hold. So:

- crack faces lie on their crack plane (or ring sphere) to within half the slab thickness
  (``SLAB_THICKNESS_FACTOR`` x the particle spacing), not on the tets' staircase; the planes
  are moved within the staircase so each large piece holds its tets' volume, a plane that
  parts many pairs of pieces in stretches, one per pair, with a small step between
  (``crack_offsets``, ``crack_slabs``);
- the outside is the artist's triangles clipped at the crack faces, keeping their UVs and
  normals (interpolated where a triangle is cut); inner faces get a planar projection along
  their crack as UVs and their own flat normal (``mesh.piece_mesh``);
- the tip of a wedge a piece's flat faces run past its tets, into a neighbour's, is cut
  away at ``piece_reach.REACH_FACTOR`` spacings from its tets (``reach.py``);
- every piece is closed, manifold and outward wound (the boolean library guarantees it);
- a piece that breaks again cuts its own render solid.

Why slabs and not plain half-space splits: a crack disc is finite, so a crack plane
separates two pieces in one place and runs through one piece elsewhere. Splitting by the
infinite plane and gluing the same piece's halves back is a union of solids that touch on
coplanar faces, which exact booleans resolve by symbolic perturbation into separate shells
(measured: 158 of 200 random fans of planes through a torus failed to glue). A slab is cut
only where the tets say the crack separates different pieces: its 2-D outline is the union
of the cut tet faces' projections onto the crack plane, grown by one particle spacing so it
reaches through the surface. Where a crack ends against another crack the slab runs up to
one spacing past it, a hairline notch in the piece beyond.

Where a crack cut bonds inside what stayed one piece (a merged small piece, a piece joined
around the crack's end) its slab cuts that piece too; the piece's parts are welded back into
one shell by the render solid within a slab three times as thick over those crossings. A
part reaching far past its piece's tets (the artist's surface joins two pieces across a gap
their tets leave open) is divided by the tets' nearest-centroid cells
(``piece_parts.divide_joined_parts``). What the cut still cannot resolve falls back to the
solid nearest the piece's tets: a piece left with under half its tets' volume, one whose
render solid reaches more than ``piece_parts.OVERREACH_FACTOR`` spacings past its tets or
holds well over their volume (it holds a neighbour's material), and the neighbour that lost
it (``surfaces/parts.py``) get the solid nearer their tet centroids than those of the
other pieces so failed, less what the other pieces hold: the artist's surface outside, the
other pieces' crack faces against them, faces between nearest-centroid cells between them.
A piece's crumbs are dropped and its other stray shells bridged to the main shell they lie
against, its own or a neighbour's (``shells.plan_stray_shells``).

``crack_roughness`` (FractureOptions) displaces the slabs' faces along the crack normal
by smooth value noise, the same on both faces, so the two sides of a crack still fit; a
rough crack's stretches are shifted within that one warped sheet
(``crack_slabs.warped_slab``).
"""

from __future__ import annotations

from typing import NamedTuple

import manifold3d as m3
import numpy as np

from ..fracture.crack_types import CrackPlane, RingCrack
from .crack_fit import (FITTED_PIECE_TETS, MOVES, crack_segments, moved_crack, piece_target_volumes,
                        segment_shifts, tilt_frames, volume_errors, volume_misfit, volume_offsets)
from .layout import HULL_FACE
from .parts import (assign_parts, carve_lost_pieces, divide_joined_parts, failed_piece_shells, failed_pieces,
                    overfull_pieces, overreaching_pieces)
from .reach import KEPT_SHARE, trim_overreach
from .shells import StrayPlan, join_planned_shells, plan_stray_shells, planned_solids, without_crumbs
from .slabs import SLAB_PAST_FACTOR, plane_slab, segment_slabs, sphere_shell
from .solid import (DUST_VOLUME_FACTOR, WELD_REACH_FACTOR, WELD_THICKNESS_FACTOR, RenderSolid, with_crack_index,
                    without_dust)

#: The shares of the fitted plane offsets tried in turn until a cut's pieces come nearer their
#: tets' volumes than the first cut's: a moved plane can hand a small part where cracks meet
#: to another piece, which the fit's linear model does not foresee.
FIT_STEPS = (1.0, 0.5)
#: A fit is cut only when its linear model promises to take this share off the pieces'
#: squared volume errors: each cut costs as much as the first.
FIT_GAIN = 0.25

#: A piece whose relative volume error grows by more than this in a moved cut that is no
#: nearer took (or lost) material across a gap the move opened: the moves there are frozen.
JUMP_ERROR = 0.02

#: The moves frozen after such a jump: those of the crossings within this many spacings [-] of
#: the material that changed hands (the faces that opened the gap lie there).
NEAR_CHANGE_FACTOR = 2.0


def _separating_cracks(model, bonds, labels, cracks):
    """For each crack: (sites (N,3) [m], cut (N,) bool, inside (N,) int, ends (N,2) int):
    where bonds cross its plane, which of them it cuts, for a cut between two tets of one
    piece that piece (else -1), and the pieces of the bond's two tets (-1: dropped); empty
    when it separates no two pieces (a ring crack: (None, its cuts between pieces, None,
    None))."""

    x = model.particle_position
    a, b = x[bonds[:, 0]], x[bonds[:, 1]]
    separating = labels[bonds[:, 0]] != labels[bonds[:, 1]]
    per_crack = []
    for crack in cracks:
        if isinstance(crack, CrackPlane):
            da, db = (a - crack.point) @ crack.normal, (b - crack.point) @ crack.normal
            cross = (da >= 0) != (db >= 0)
            t = da / np.where(cross, da - db, 1.0)
            hit = a + t[:, None] * (b - a)
            offset = hit - crack.point
            cut = cross & (np.einsum("ij,ij->i", offset, offset) <= crack.extent**2)
            if not np.any(cut & separating):
                # (it separates no two pieces: no slit either)
                per_crack.append((hit[:0], cut[:0], labels[:0], bonds[:0]))
                continue
            # Sites: every crossing but those between pieces another crack cut. A cut inside
            # one piece (a merged small piece, a piece joined around) is cut too: that piece
            # then has two shells a slab apart, as a hairline crack would look.
            site = cross & (cut | ~separating)
            inside_one = np.where(cut & ~separating, labels[bonds[:, 0]], -1)
            ends = np.stack([labels[bonds[:, 0]], labels[bonds[:, 1]]], axis=1)
            per_crack.append((hit[site], cut[site], inside_one[site], ends[site]))
        elif isinstance(crack, RingCrack):
            inside_a = np.einsum("ij,ij->i", a - crack.point, a - crack.point) < crack.radius**2
            inside_b = np.einsum("ij,ij->i", b - crack.point, b - crack.point) < crack.radius**2
            cut = (inside_a != inside_b) & separating
            per_crack.append((None, cut[cut], None, None))  # (the whole sphere: rings run all round)
        else:
            raise TypeError(f"unknown crack type {type(crack).__name__}")
    return per_crack


def cut_render_solid(render: RenderSolid, model, fragment_tets, cracks, piece_origins, *,
                     roughness: float = 0.0, roughness_scale: float | None = None, seed: int = 0,
                     fit_rounds: int = 3, fit_min_tets: int = FITTED_PIECE_TETS):
    """Cut a body's render solid along the cracks that broke it.

    Args:
        render: the body's render solid (``model``'s body frame).
        model: the body's BodyModel (tets, bonds, particle positions).
        fragment_tets: the pieces' tet index arrays (``FractureResult.fragment_tets``); tets
            in none (dropped) lose their part of the render solid.
        cracks: the ``CrackPlane``/``RingCrack`` list that cut the bonds.
        piece_origins: (F,3) [m] each piece's body-frame origin in ``model``'s frame (its
            ``com_in_source``).
        roughness: [m] crack-face noise amplitude (0: flat); roughness_scale [m] its
            wavelength (None: 4 particle spacings); seed: the noise's seed.
        fit_rounds: how many times the cracks are moved to fit the pieces' volumes (below);
            0: cut on the cracks as the analysis placed them.
        fit_min_tets: the least tets of a piece whose volume the stretches are fitted to
            (the whole cracks are fitted to pieces of at least the larger of this and
            ``FITTED_PIECE_TETS``: a few pieces where cracks meet must not pull a plane that
            many larger pieces lie on).

    The cut is made on the cracks as the analysis placed them, then, while a piece of
    ``FITTED_PIECE_TETS`` tets or more is off its tets' volume by more than
    ``VOLUME_TOLERANCE`` (up to ``fit_rounds`` times), again with the cracks moved (planes
    shifted and tilted, ring cracks' spheres resized) by what brings those pieces' volumes
    nearest their tets' (``crack_offsets``), kept when it is nearer (else with half those
    moves, see FIT_STEPS). Where that is not enough (a plane between many pairs of pieces),
    up to ``fit_rounds`` times more, the stretch of a plane between each pair of pieces is
    shifted on its own (``crack_offsets.CrackSegments``, the fewest stretches that do it),
    with a wall across each step between two (``crack_slabs.segment_slabs``; a rough crack's
    blended into its one warped slab). A moved cut in which a piece fails that did not is
    never kept: a crack moved past the end of another's slab joins two pieces there. The cracks (stretches) of the
    pieces that failed then stay, and the others fit again. Last, each piece loses the wedge
    tips its flat faces run past its tets into a neighbour's (``piece_reach.trim_overreach``).

    Returns (pieces, stats): pieces a list of F RenderSolid or None (the caller then gives the
    piece its tets' boundary, exact in volume); stats a dict of counts (slabs, parts,
    unassigned parts, pieces without a part, ``fallback_pieces``: pieces the cut failed, see
    ``failed_pieces``, of which ``cell_pieces`` got the solid nearest their tets instead
    (``piece_parts.failed_piece_shells``) and the rest None; ``shells_moved``: stray shells
    joined to another piece, see ``shells.plan_stray_shells``; ``moved_cracks``: cracks
    the kept cut moved, ``largest_offset`` [particle spacings]: the largest shift of a moved
    crack (a plane's at its pivot plus its tilt's at its reach), ``moved_segments`` and
    ``largest_segment_shift`` [particle spacings]: the stretches shifted on their own and the
    largest such shift, ``fallback_ids`` the failed pieces, ``fit_cuts``: cuts made for
    the fit besides the first; ``trimmed_pieces`` and ``trimmed_volume`` [m^3]: the wedge
    tips cut away).
    """
    spacing = render.spacing
    roughness_scale = 4.0 * spacing if roughness_scale is None else float(roughness_scale)
    labels = np.full(model.tet_count, -1, dtype=np.int64)
    for k, tets in enumerate(fragment_tets):
        labels[np.asarray(tets, dtype=np.int64)] = k
    per_crack = _separating_cracks(model, np.asarray(model.bonds, dtype=np.int64), labels, cracks)
    frames = tilt_frames(cracks, [None if sites is None else sites[cut & (inside < 0)]
                                  for sites, cut, inside, _ in per_crack], spacing)
    scale = render.volume_scale if render.volume_scale is not None else render.solid.volume() / model.volume
    args = (render, model, fragment_tets, labels, cracks, per_crack, frames, roughness, roughness_scale, seed)

    def finished(kept: _Parts, **counts):
        pieces, stats = _pieces(render, kept, piece_origins, scale)
        return _trimmed(pieces, dict(stats, **counts), model, labels, piece_origins)

    first = _cut_parts(*args, np.zeros((len(cracks), MOVES)))
    index_of = first.index_of
    if not fit_rounds:
        return finished(first, moved_cracks=0, largest_offset=0.0, fit_cuts=0, moved_segments=0,
                        largest_segment_shift=0.0)
    targets = piece_target_volumes(scale, model, fragment_tets)
    plane_min_tets = max(int(fit_min_tets), FITTED_PIECE_TETS)
    # (the fit reads the cuts' parts in the body's frame, before the bridges: see _Parts)
    kept = _Kept(first, volume_misfit(first.solids, targets, fragment_tets, plane_min_tets))
    origins = np.zeros((len(fragment_tets), 3))
    # The whole cracks first: a crack is frozen when a piece on it fails.
    touching = [set(ends[cut & (inside < 0)].ravel().tolist()) if sites is not None else set()
                for sites, cut, inside, ends in per_crack]

    def on_failed(newly):
        return np.array([bool(pieces_of & set(newly.tolist())) for pieces_of in touching], dtype=bool)

    kept, moved, cuts = _fit_rounds(
        fit_rounds, kept, np.zeros((len(cracks), MOVES)), targets, fragment_tets, plane_min_tets,
        fit=lambda solids, _, moves, frozen: volume_offsets(solids, index_of, cracks, targets, fragment_tets, spacing,
                                                            moves, frames, origins, frozen=frozen,
                                                            min_tets=plane_min_tets),
        cut=lambda moves: _cut_parts(*args, moves),
        freeze=on_failed, near=None)
    # Then each stretch of a plane between one pair of pieces on its own (crack_offsets.CrackSegments).
    segments = crack_segments(per_crack, len(fragment_tets))
    if fit_min_tets != plane_min_tets:  # (the stretches read smaller pieces than the planes did)
        kept = kept._replace(misfit=volume_misfit(kept.solids, targets, fragment_tets, fit_min_tets))
    kept, shifts, more = _fit_rounds(
        fit_rounds if segments.count else 0, kept, np.zeros(segments.count), targets,
        fragment_tets, fit_min_tets,
        fit=lambda solids, sources, moves, frozen: segment_shifts(solids, origins, sources, cracks, segments,
                                                                  targets, fragment_tets, spacing, moves, frozen,
                                                                  fit_min_tets),
        cut=lambda moves: _cut_parts(*args, moved, segments, moves),
        freeze=lambda newly: np.isin(segments.pieces, newly).any(axis=1),
        near=lambda before, after, jumped, newly: _stretches_near(
            segments, np.concatenate([_changed_material(before, after, jumped, origins, spacing),
                                      model.particle_position[np.isin(labels, newly)]]), spacing))
    reach = np.abs(moved[:, 0]) + np.linalg.norm(moved[:, 1:], axis=1)
    return finished(kept.parts, moved_cracks=int(np.sum(reach > 0.0)),
                    largest_offset=float(np.max(reach, initial=0.0)) / spacing, fit_cuts=cuts + more,
                    moved_segments=int(np.sum(shifts != 0.0)),
                    largest_segment_shift=float(np.max(np.abs(shifts), initial=0.0)) / spacing)


class _Kept(NamedTuple):
    """A cut the fit keeps: its ``_Parts`` and their ``volume_misfit``."""

    parts: "_Parts"
    misfit: float

    @property
    def solids(self) -> list:
        return self.parts.solids

    @property
    def sources(self) -> np.ndarray:
        return self.parts.sources

    @property
    def stats(self) -> dict:
        return self.parts.stats


def _fit_rounds(rounds: int, kept, moves: np.ndarray, targets, fragment_tets, min_tets: int, fit, cut, freeze,
                near):
    """Up to ``rounds`` times, the moves ``fit(solids, sources, moves, frozen)`` proposes
    (further moves, the misfit its linear model predicts), cut (``cut(moves)``: ``_cut_parts``'
    ``_Parts``) with all of them or else half (FIT_STEPS), kept when the pieces' volumes come
    nearer (``volume_misfit`` over the pieces of ``min_tets`` tets or more). A move that
    fails a piece the kept cut did not (one crack passing the end of another's slab joins
    two pieces there) is not kept: ``freeze(newly)`` (bool, per move row) says which moves
    then stay, and the rest fit again. Stops when the fit promises
    less than FIT_GAIN off the misfit. A cut that is no nearer, in which a piece's error grew by
    more than JUMP_ERROR (a moved face passed the end of another crack's and a part holding
    material of two pieces went to the other one, a change the linear model cannot know),
    freezes the moves ``near(before, after, jumped, failed)`` names (bool, per move row: those
    by the material that changed hands), else those of the pieces that jumped. A cut that
    fails pieces whose own moves are all frozen already freezes those by their tets too
    (``failed``; a neighbour's move opened the gap). ``near`` None: neither check, as for
    whole planes, most of which lie near whatever changes hands. ``kept``: the ``_Kept`` cut made with ``moves``.
    Returns (kept, moves, cuts made)."""
    frozen = np.zeros(len(moves), dtype=bool)
    cuts = 0
    made = {}  # the moves' bytes -> their cut: a fit that froze nothing new proposes the same moves again
    for _ in range(rounds):
        change, predicted = fit(kept.solids, kept.sources, moves, frozen)
        if not np.any(change != 0.0) or predicted > (1.0 - FIT_GAIN) * kept.misfit:
            break
        for step in FIT_STEPS:
            tried = moves + step * change
            parts = made.get(tried.tobytes())
            if parts is None:
                parts = made[tried.tobytes()] = cut(tried)
                cuts += 1
            newly = np.setdiff1d(parts.stats["fallback_ids"], kept.stats["fallback_ids"])
            if not len(newly):
                misfit = volume_misfit(parts.solids, targets, fragment_tets, min_tets)
                if misfit < kept.misfit:
                    kept, moves = _Kept(parts, misfit), tried
                    break
            jumped = (jumped_pieces(kept.solids, parts.solids, targets, fragment_tets, min_tets) if near
                      else np.zeros(0, dtype=np.int64))
            if len(newly) or len(jumped):
                rows = freeze(newly)
                # (failed pieces whose own moves are frozen already: a neighbour's move opened the gap)
                stuck = len(newly) and not np.any(rows & ~frozen)
                if near and (len(jumped) or stuck):
                    rows |= near(kept.solids, parts.solids, jumped, newly if stuck else newly[:0])
                frozen |= rows if rows.any() else freeze(jumped)
                break
        else:
            break
    return kept, moves, cuts


def jumped_pieces(before, after, targets, fragment_tets, min_tets: int) -> np.ndarray:
    """The pieces (indices) of ``min_tets`` tets or more whose relative volume error grows by
    more than JUMP_ERROR from the solids ``before`` to ``after`` (manifolds or None)."""
    was = np.abs(volume_errors(before, targets, fragment_tets, min_tets))
    now = np.abs(volume_errors(after, targets, fragment_tets, min_tets))
    return np.nonzero(np.nan_to_num(now - was) > JUMP_ERROR)[0]


def _changed_material(before, after, jumped, origins, spacing: float) -> np.ndarray:
    """(K,3) [m] the body-frame vertices of the material that left or joined the pieces
    ``jumped`` between the solids ``before`` and ``after`` (each in its piece's frame, whose
    origin is ``origins[k]``), in bits of a tet's volume (one spacing cubed) or more."""
    points = []
    for k in jumped:
        if before[k] is None or after[k] is None:
            continue
        for bit in (after[k] - before[k]).decompose() + (before[k] - after[k]).decompose():
            if bit.volume() >= spacing**3:
                points.append(np.asarray(bit.to_mesh().vert_properties)[:, :3] + np.asarray(origins[k]))
    return np.concatenate(points) if points else np.zeros((0, 3))


def _stretches_near(segments, points: np.ndarray, spacing: float) -> np.ndarray:
    """(S,) bool: the ``segments`` (``crack_offsets.CrackSegments``) with a cut crossing within
    NEAR_CHANGE_FACTOR spacings of one of ``points`` (K,3) [m]."""
    rows = np.zeros(segments.count, dtype=bool)
    if not len(points):
        return rows
    for tree, cut_segment in zip(segments.trees, segments.cut_segment):
        if tree is None:
            continue
        found = [i for row in tree.query_ball_point(points, NEAR_CHANGE_FACTOR * spacing) for i in row]
        hit = cut_segment[np.unique(np.asarray(found, dtype=np.int64))]
        rows[hit[hit >= 0]] = True
    return rows


def _trimmed(pieces, stats, model, labels, piece_origins):
    """``pieces`` each less its wedges past its tets (``piece_reach.trim_overreach``) and
    the crumbs a trim leaves apart; ``stats`` gains ``trimmed_pieces`` and ``trimmed_volume``
    [m^3] (what they lost)."""
    stats.update(trimmed_pieces=0, trimmed_volume=0.0)
    pieces = list(pieces)
    for k, piece in enumerate(pieces):
        if piece is None:
            continue
        origin = np.asarray(piece_origins[k], dtype=np.float64)
        solid, volume = trim_overreach(piece.solid.translate(tuple(origin)), model, labels, k, piece.spacing)
        if not volume > 0.0:
            continue
        bits = without_crumbs(without_dust(solid, piece.spacing), piece.spacing)
        solid = m3.Manifold.compose(bits) if len(bits) > 1 else (bits[0] if bits else m3.Manifold())
        before, after = piece.solid.volume(), solid.volume()
        if after >= KEPT_SHARE * before:
            pieces[k] = RenderSolid(solid.translate(tuple(-origin)), piece.cracks, piece.spacing, piece.volume_scale)
            stats["trimmed_pieces"] += 1
            stats["trimmed_volume"] += before - after
    return pieces, stats


class _Parts:
    """One cut's pieces before the bridges that join their stray shells (``_cut_parts``):
    every cut the fit tries is measured, only the one it keeps needs them (``_pieces``).
    ``cracks`` the pieces' crack surfaces; ``stats`` the cut's counts (``cut_render_solid``'s);
    ``index_of`` and ``sources`` as ``_cut_parts`` says. ``plan`` where each piece's shells
    go (the body's frame [m]) and ``solids`` per piece its shells as ``plan`` gives them out,
    one manifold (the body's frame) or None (what the fit measures: a bridge adds a gap's
    volume, CONTACT_GAP_FACTOR spacings deep) are made when first read: a moved cut that
    fails a piece the kept one did not is never kept, and where the fit does not ask what
    its pieces' volumes became (a whole crack moved) nothing reads them (the failed pieces'
    shells, the welds and the plan are a fifth of the 13 rings' cut time)."""

    def __init__(self, cracks: tuple, stats: dict, index_of: np.ndarray, sources: np.ndarray, make):
        self.cracks, self.stats, self.index_of, self.sources = cracks, stats, index_of, sources
        self._make = make  # () -> (plan, solids); it adds its counts to stats
        self._made = None

    def _shells(self) -> tuple:
        if self._made is None:
            self._made, self._make = self._make(), None
        return self._made

    @property
    def plan(self) -> StrayPlan:
        return self._shells()[0]

    @property
    def solids(self) -> list:
        return self._shells()[1]


def _cut_parts(render: RenderSolid, model, fragment_tets, labels, cracks, per_crack, frames, roughness,
               roughness_scale, seed, offsets, segments=None, shifts=None) -> _Parts:
    """One cut of ``cut_render_solid`` up to the pieces' shells (``_Parts``; ``_pieces``
    finishes it), with crack i moved by ``offsets[i]`` (MOVES,) [m] (see
    ``crack_offsets.moved_crack``; ``frames`` each crack's TiltFrame or None) and each of the
    ``segments`` (``crack_offsets.CrackSegments``) shifted further along its plane's normal by
    ``shifts`` (S,) [m]. Its ``index_of`` (len(cracks),) holds each crack's (first) index in
    the pieces' ``cracks`` (-1: it made no slab), its ``sources`` the crack behind each index
    of the pieces' ``cracks`` (-1: one the body had)."""
    spacing = render.spacing
    new_cracks = list(render.cracks)
    slabs, planes, sources = [], [], []
    index_of = np.full(len(cracks), -1, dtype=np.int64)
    for i, (crack, (sites, separating, inside_one, _)) in enumerate(zip(cracks, per_crack)):
        if not len(separating) or not separating.any():
            continue
        first = len(new_cracks)
        surface = moved_crack(crack, frames[i], offsets[i])
        segment = segments.of_site[i] if segments is not None else None
        stretched = segment is not None and np.any(shifts[segment[segment >= 0]])
        if stretched and roughness == 0:
            parts, wall = segment_slabs(surface, sites, separating, segment, shifts, spacing)
            if wall is not None:
                slabs.append(with_crack_index(wall, HULL_FACE))
        elif isinstance(crack, CrackPlane):
            parts = [(surface, plane_slab(surface, sites, separating, spacing, roughness, roughness_scale, seed,
                                           first, past=SLAB_PAST_FACTOR + roughness / spacing,
                                           segment=segment if stretched else None, shifts=shifts))]
        else:
            parts = [(surface, sphere_shell(surface, spacing))]
        for part, slab in parts:
            if slab is None or slab.is_empty():
                continue
            index = len(new_cracks)
            new_cracks.append(part)
            sources.append(i)
            if index_of[i] < 0:
                index_of[i] = index
            slabs.append(with_crack_index(slab, index))
        if isinstance(crack, CrackPlane) and index_of[i] >= 0:
            planes.append((surface, sites, inside_one, index_of[i]))
    sources = np.concatenate([np.full(len(render.cracks), -1, dtype=np.int64), np.array(sources, dtype=np.int64)])
    stats = dict(slabs=len(slabs), parts=0, unassigned_parts=0, empty_pieces=0, welded_pieces=0, cell_pieces=0)
    # (in one batch, not solid.difference's one slab at a time: the vote that hands out the
    # parts samples their faces, and other triangles gave a 3-tet part of the struck glass
    # wall, a near tie, to the other piece, after which the fit left a piece 3 % off)
    cut = m3.Manifold.batch_boolean([render.solid, *slabs], m3.OpType.Subtract) if slabs else render.solid
    every_part = cut.decompose()
    parts = [part for part in every_part if part.volume() >= DUST_VOLUME_FACTOR * spacing**3]
    stats["dust_parts"] = len(every_part) - len(parts)
    corners = {}  # id(part) -> (part, its vertices (N,3) [m]): read by the vote and the reach check
    owner = assign_parts(parts, model, labels, spacing, corners)
    parts, owner, received = divide_joined_parts(parts, owner, model, labels, spacing, corners)
    stats["pieces_given_divided_parts"] = len(received)
    parts, owner = carve_lost_pieces(parts, owner, model, fragment_tets, labels, spacing, roughness)
    stats["parts"] = len(parts)
    stats["carved_pieces"] = len({o for o in owner if o < -1})
    owner = [-(o + 2) if o < -1 else o for o in owner]
    failed = failed_pieces(parts, owner, model, fragment_tets)
    failed |= overreaching_pieces(parts, owner, model, labels, spacing, corners)
    # (a piece given the material nearest its tets beyond a gap they leave holds more than
    # them by that gap's volume: not a neighbour's material)
    failed |= overfull_pieces(parts, owner, model, labels, spacing, roughness) - received
    stats["fallback_pieces"] = len(failed)
    stats["fallback_ids"] = sorted(failed)
    stats["unassigned_parts"] = int(sum(1 for o in owner if o == -1))
    def shells_and_plan():
        # Each piece's parts without its crumbs, once: the welds and the pieces read them.
        kept = {k: without_crumbs([p for p, o in zip(parts, owner) if o == k], spacing) for k in set(owner) if k >= 0}
        shells = {}  # piece -> its shells, the body's frame
        for k in range(len(fragment_tets)):
            if k in failed:
                # Its share of the solid nearest its own tets (see failed_piece_shells).
                shells[k] = without_crumbs(failed_piece_shells(render.solid, model, labels, k, failed, parts, owner,
                                                               spacing), spacing)
                stats["cell_pieces"] += bool(shells[k])
            elif not kept.get(k):
                stats["empty_pieces"] += 1
            else:
                shells[k] = kept[k]
        # A piece whose own parts a crack's slab parted is welded into one shell again.
        split_up = {k for k, mine in kept.items() if k not in failed and len(mine) > 1}
        spheres = [surface for surface in new_cracks[len(render.cracks):] if surface.radius is not None]
        for k, bits in _weld_bits(render.solid, planes, spheres, split_up, spacing, roughness, roughness_scale,
                                  seed).items():
            shells[k] = without_dust(m3.Manifold.batch_boolean([*shells[k], *bits], m3.OpType.Add), spacing)
            stats["welded_pieces"] += 1
        plan = plan_stray_shells({k: mine for k, mine in shells.items() if mine}, spacing)
        stats["shells_moved"] = plan.moved
        planned = planned_solids(plan)
        return plan, [planned.get(k) for k in range(len(fragment_tets))]

    return _Parts(tuple(new_cracks), stats, index_of, sources, shells_and_plan)


def _pieces(render: RenderSolid, parts: _Parts, piece_origins, volume_scale) -> tuple[list, dict]:
    """The pieces of a cut's ``parts``, each stray shell joined where the plan sends it
    (``shells.join_planned_shells``), in its frame (origin ``piece_origins[k]`` (3,) [m] in the
    body's). Returns (pieces (RenderSolid or None), the cut's stats)."""
    solids = join_planned_shells(parts.plan, render.spacing)  # (its making completes parts.stats)
    origins = np.asarray(piece_origins, dtype=np.float64).reshape(-1, 3)
    pieces = [RenderSolid(solids[k], parts.cracks, render.spacing, volume_scale).moved(origin) if k in solids else None
              for k, origin in enumerate(origins)]
    return pieces, dict(parts.stats)


def _weld_bits(solid: m3.Manifold, planes, spheres, split_up: set, spacing: float, roughness: float,
               roughness_scale: float, seed: int) -> dict:
    """Piece -> the bit of the render ``solid`` that joins its parts again where a crack's slab
    cut through the piece itself (a bond cut between two of its own tets: a merged small piece,
    a piece joined around the crack's end): the solid within a slab WELD_THICKNESS_FACTOR
    spacings thick over those crossings (squares WELD_REACH_FACTOR spacings about each), which
    overlaps the parts on both sides of the hairline, so their union is one shell. So that a
    square reaching past another crack does not join the piece to a sliver in its neighbour,
    the weld keeps off the other plane cracks' lines through its plane (the sliver left
    beyond is apart, under the crumb volume, dropped), and crossings whose square would reach
    a ring crack's sphere (``spheres``) are left out; one overlap is enough to join two
    parts. Only for the pieces in ``split_up``; ``planes``: (surface, sites, inside, index)
    of each plane crack's slab."""
    bits = {}
    for k in sorted(split_up):
        welds = []
        for surface, sites, inside_one, index in planes:
            own = inside_one == k
            for sphere in spheres:
                own &= np.abs(sphere.distance(sites)) > np.sqrt(2.0) * WELD_REACH_FACTOR * spacing
            if not own.any():
                continue
            weld = plane_slab(surface, sites[own], np.ones(int(own.sum()), dtype=bool), spacing, roughness,
                               roughness_scale, seed, index, thickness_factor=WELD_THICKNESS_FACTOR,
                               reach_factor=WELD_REACH_FACTOR,
                               apart_from=[other for other, _, _, _ in planes if other is not surface])
            if weld is not None and not weld.is_empty():
                welds.append(with_crack_index(weld, index))
        if welds:
            bits[k] = [solid ^ (m3.Manifold.batch_boolean(welds, m3.OpType.Add) if len(welds) > 1 else welds[0])]
    return bits
