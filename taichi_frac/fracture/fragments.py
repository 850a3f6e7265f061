"""Fragments: cut bonds, connected tet sets, new rigid bodies (BRIEF.md step 10).

Smith, Witkin & Baraff 2001: the tets of a body are joined by breakable links (here the
face-sharing bonds of ``BodyModel.bonds``); a crack breaks links, never remeshes. After
cutting, each connected set of tets is a new rigid body whose exact mass properties,
surface and boundary particles come from ``build_fragment_models`` on that tet subset (the
parent's face adjacency restricted to it): faces whose neighbour is in another fragment
become boundary faces, so crack faces are new surface automatically.

Decisions (docs/method.md):

- **Small fragments** (fewer than ``min_fragment_particles`` tets), per
  ``small_fragment_policy``: "merge" joins the smallest small piece to the neighbouring piece
  it shares the most cut faces with (ties: the lower label), repeated until none is small
  or only one piece is left; "debris" keeps it as a separate body flagged unbreakable;
  "drop" removes it and reports its tets and mass in ``FractureResult`` (never hidden).
- **Kinematics**: a fragment's body frame has its origin at its own centre of mass and the
  parent's body axes, so its orientation is the parent's; its position is
  ``parent_position + R(q) c`` (c = its COM in the parent's body frame), its velocity the
  parent's rigid velocity field there, ``v + omega x (R c)``, and its angular velocity
  ``omega``. Mass, linear and angular momentum are conserved exactly (parallel-axis rule);
  tests check it against an independent tet integration.
- **Refracture**: a fragment's ``source_tet`` is composed with the parent's, so it always
  indexes the root solid's tet mesh; ``generation`` counts how many times its material has
  broken, and ``breakable`` is False for debris and once ``generation`` exceeds
  ``max_generations`` or refracture is off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.components import connected_tets
from ..kinematics.quaternion import quaternion_matrix
from ..model import BodyModel, build_fragment_models
from ..options import FractureOptions, Material, ParticleOptions
from .crack_types import ImpactAnalysis
from .cracks import cut_bonds


@dataclass(frozen=True, eq=False)
class FractureResult:
    """Outcome of cutting one body, in its body frame. F kept fragments, B bonds.

    Attributes:
        cut_bonds: (B,) bool, bonds the cracks cut (before any merge).
        fragment_tets: F int arrays of the parent's tet indices, one per kept fragment,
            ordered by their smallest tet index (deterministic).
        fragment_is_debris: (F,) bool, small pieces kept unbreakable ("debris" policy).
        fragment_peak_stress: (F,) [Pa] largest principal stress over each fragment's tets
            (over the particles the analysis evaluated: all of them for a full-field one,
            NaN for a piece a local one did not reach), or the largest crack peak bounding
            it when no field was given.
        dropped_tets: (D,) parent tet indices removed by the "drop" policy.
        dropped_mass: [kg] their exact mass (density x tet volume).
        component_count: connected pieces right after cutting, before the small-fragment
            policy.
    """

    cut_bonds: np.ndarray
    fragment_tets: list
    fragment_is_debris: np.ndarray
    fragment_peak_stress: np.ndarray
    dropped_tets: np.ndarray
    dropped_mass: float
    component_count: int

    @property
    def fragment_count(self) -> int:
        return len(self.fragment_tets)

    @property
    def broke(self) -> bool:
        """True if the parent must be replaced (more than one piece, or mass dropped)."""
        return self.fragment_count > 1 or len(self.dropped_tets) > 0


@dataclass(frozen=True)
class ImpactRecord:
    """The impact that made a fragment, world frame: point [m], normal (unit, into the
    parent), force [N] on the parent. For several contacts in one step, the one whose
    analysis found the largest principal stress."""

    point: np.ndarray
    normal: np.ndarray
    force: np.ndarray


@dataclass(frozen=True, eq=False)
class Fragment:
    """A new rigid body made by a fracture.

    Attributes:
        model: its BodyModel (body frame: own COM, the parent's axes).
        position: (3,) [m] world position of its COM.
        orientation: (4,) unit quaternion (w, x, y, z), the parent's.
        linear_velocity: (3,) [m/s]; angular_velocity: (3,) [rad/s], world frame.
        source_tets: (T,) root-solid tet indices (= model.source_tet).
        parent_tets: (T,) the parent's tet indices.
        peak_principal_stress: [Pa] largest principal stress over its tets at the impact (see
            ``FractureResult.fragment_peak_stress``; the simulation computes the whole field
            for it only when it writes a cache).
        birth_frame: output frame it appeared in (the caller's).
        parent: the parent body's id (the caller's), or None.
        impact: the impact that made it, or None.
        generation: 1 for a piece of a scene object, 2 for a piece of a piece, ...
        breakable: False for debris and when refracture is off or the generation limit is
            reached.
    """

    model: BodyModel
    position: np.ndarray
    orientation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    source_tets: np.ndarray
    parent_tets: np.ndarray
    peak_principal_stress: float
    birth_frame: int = 0
    parent: int | None = None
    impact: ImpactRecord | None = None
    generation: int = 1
    breakable: bool = True


def _merge_small(labels: np.ndarray, bonds: np.ndarray, cut: np.ndarray, min_size: int) -> np.ndarray:
    """The "merge" policy on component labels: the smallest small piece (ties: the lowest
    label) joins the piece it shares the most cut bonds with (ties: the lower label),
    repeated until none is small or only one piece is left; a small piece that touches
    no other stays. On a graph of pieces (cut-bond counts between them), not on the
    bonds: the pieces are few, the cut bonds hundreds."""
    labels = labels.copy()
    sizes = {int(p): int(n) for p, n in enumerate(np.bincount(labels)) if n > 0}
    pairs = labels[bonds[cut]]
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    adjacent: dict[int, dict[int, int]] = {p: {} for p in sizes}
    if len(pairs):
        # (pairs as one integer key: np.unique over rows sorts a structured view, far slower)
        span = int(labels.max()) + 1
        keys, counts = np.unique(np.concatenate([pairs[:, 0] * span + pairs[:, 1], pairs[:, 1] * span + pairs[:, 0]]),
                                 return_counts=True)
        for key, c in zip(keys.tolist(), counts.tolist()):
            adjacent[key // span][key % span] = c
    merged_into: dict[int, int] = {}
    while len(sizes) > 1:
        small = sorted((n, p) for p, n in sizes.items() if n < min_size)
        piece = next((p for _, p in small if adjacent[p]), None)
        if piece is None:
            break
        target = min(adjacent[piece].items(), key=lambda kv: (-kv[1], kv[0]))[0]
        sizes[target] += sizes.pop(piece)
        for other, count in adjacent.pop(piece).items():
            del adjacent[other][piece]
            if other != target:
                adjacent[other][target] = adjacent[other].get(target, 0) + count
                adjacent[target][other] = adjacent[target].get(other, 0) + count
        merged_into[piece] = target
    if merged_into:
        final = np.arange(labels.max() + 1)
        for piece in merged_into:
            target = piece
            while target in merged_into:
                target = merged_into[target]
            final[piece] = target
        labels = final[labels]
    return labels


def fragment_peak_stress(pieces, principal_stress) -> np.ndarray:
    """(F,) [Pa] the largest of ``principal_stress`` (T,) over each piece's tets. NaN
    entries (the particles a local analysis did not evaluate) are skipped: a piece with
    none evaluated gets NaN."""
    peaks = []
    for p in pieces:
        values = principal_stress[p]
        values = values[~np.isnan(values)]
        peaks.append(float(values.max()) if len(values) else np.nan)
    return np.array(peaks)


def split_body(
    model: BodyModel,
    cracks,
    options: FractureOptions,
    *,
    principal_stress: np.ndarray | None = None,
) -> FractureResult:
    """Cut ``model``'s bonds with ``cracks`` and apply the small-fragment policy.

    ``cracks`` is a sequence of ``CrackPlane`` or an ``ImpactAnalysis`` (whose full-field
    principal stress then gives each fragment's peak stress; ``principal_stress`` (T,) [Pa]
    does the same for a plain crack list).
    """
    if isinstance(cracks, ImpactAnalysis):
        if principal_stress is None:
            principal_stress = cracks.particle_principal_stress
        cracks = cracks.cracks
    cracks = list(cracks)
    t_count = model.tet_count
    cut = cut_bonds(model, cracks)
    component_count, labels = connected_tets(t_count, model.bonds, cut)

    small_limit = options.min_fragment_particles
    sizes = np.bincount(labels, minlength=component_count)
    is_debris_label = np.zeros(component_count, dtype=bool)
    dropped = np.zeros(0, dtype=np.int64)
    if component_count > 1:
        if options.small_fragment_policy == "merge":
            labels = _merge_small(labels, model.bonds, cut, small_limit)
        elif options.small_fragment_policy == "debris":
            is_debris_label = sizes < small_limit
        elif options.small_fragment_policy == "drop":
            small = sizes[labels] < small_limit
            dropped = np.nonzero(small)[0]
            labels = np.where(small, -1, labels)

    # Group tets by label; order fragments by their smallest tet index.
    kept = np.nonzero(labels >= 0)[0]
    order = np.argsort(labels[kept], kind="stable")
    sorted_tets = kept[order]
    uniq, starts = np.unique(labels[sorted_tets], return_index=True)
    pieces = np.split(sorted_tets, starts[1:]) if len(sorted_tets) else []
    first = [p.min() for p in pieces]
    rank = np.argsort(first, kind="stable")
    pieces = [pieces[r].astype(np.int64) for r in rank]
    debris = np.array([bool(is_debris_label[uniq[r]]) for r in rank], dtype=bool)

    if principal_stress is not None:
        peak = fragment_peak_stress(pieces, principal_stress)
    else:
        peak = _crack_peak_per_piece(model, cracks, cut, labels, uniq[rank])

    return FractureResult(
        cut_bonds=cut,
        fragment_tets=pieces,
        fragment_is_debris=debris,
        fragment_peak_stress=peak,
        dropped_tets=dropped,
        dropped_mass=float(model.density * model.tet_volume[dropped].sum()),
        component_count=int(component_count),
    )


def _crack_peak_per_piece(model, cracks, cut, labels, piece_labels) -> np.ndarray:
    """Largest ``peak_stress`` of the cracks cutting a bond of each piece (0 if none)."""
    peak = np.zeros(len(piece_labels))
    if not cracks or not cut.any():
        return peak
    crack_peak = max(c.peak_stress for c in cracks)
    touched = np.unique(labels[model.bonds[cut].reshape(-1)])
    peak[np.isin(piece_labels, touched)] = crack_peak
    return peak


def make_fragments(
    model: BodyModel,
    split: FractureResult,
    position,
    orientation_wxyz,
    linear_velocity,
    angular_velocity,
    material: Material | None,
    particle_options: ParticleOptions,
    *,
    options: FractureOptions | None = None,
    analysis: ImpactAnalysis | None = None,
    birth_frame: int = 0,
    parent: int | None = None,
    parent_generation: int = 0,
) -> list[Fragment]:
    """New rigid bodies for the pieces of ``split``; the parent's pose and velocities are
    world-frame. Density comes from ``model`` (exactly the parent's); ``material`` is
    accepted for the caller's symmetry and not needed. ``analysis`` (the impact) and
    ``birth_frame``/``parent`` are recorded on each fragment; ``options`` sets
    ``breakable`` (refracture, max_generations)."""
    del material  # density is the parent model's; nothing else of the material is needed
    pos = np.asarray(position, dtype=np.float64)
    rot = quaternion_matrix(orientation_wxyz)
    vel = np.asarray(linear_velocity, dtype=np.float64)
    omega = np.asarray(angular_velocity, dtype=np.float64)
    quat = np.asarray(orientation_wxyz, dtype=np.float64)
    quat = quat / np.linalg.norm(quat)
    impact = _impact_record(analysis, pos, rot)
    generation = parent_generation + 1
    can_break_again = options is None or (options.refracture and generation <= options.max_generations)

    fragments = []
    models = build_fragment_models(model, split.fragment_tets, boundary_group_size=particle_options.boundary_group_size,
                                   keep_leftovers=particle_options.keep_leftovers)
    for frag_model, tets, is_debris, peak in zip(models, split.fragment_tets, split.fragment_is_debris,
                                                 split.fragment_peak_stress):
        offset = rot @ frag_model.com_in_source  # parent COM -> fragment COM, world frame
        fragments.append(Fragment(
            model=frag_model,
            position=pos + offset,
            orientation=quat.copy(),
            linear_velocity=vel + np.cross(omega, offset),
            angular_velocity=omega.copy(),
            source_tets=frag_model.source_tet,
            parent_tets=np.asarray(tets),
            peak_principal_stress=float(peak),
            birth_frame=int(birth_frame),
            parent=parent,
            impact=impact,
            generation=generation,
            breakable=bool(can_break_again and not is_debris),
        ))
    return fragments


def _impact_record(analysis: ImpactAnalysis | None, pos: np.ndarray, rot: np.ndarray) -> ImpactRecord | None:
    if analysis is None or len(analysis.contact_point) == 0:
        return None
    k = 0
    if np.any(np.isfinite(analysis.group_principal_values)):
        # (a local analysis leaves the groups of contacts that crack nothing NaN)
        peak = np.where(np.isfinite(analysis.group_principal_values[..., 0]), analysis.group_principal_values[..., 0],
                        -np.inf)
        k = int(np.argmax(peak.max(axis=1)))
    return ImpactRecord(point=pos + rot @ analysis.contact_point[k], normal=rot @ analysis.normal_in[k],
                        force=rot @ analysis.force[k])
