"""Controllable cracks at an impact (BRIEF.md steps 8-9, and the decisions of section 3).

Everything here is in the body frame of the struck body (``BodyModel``): the stress field
of a contact never needs the body's world pose.

Decisions (the paper leaves them open; docs/method.md explains them for artists):

- **Analysis point**: for each contact, the physics particle of largest principal stress
  within 2 smoothing lengths (kernel support radii) of the contact point (the "maximum
  only" choice: under a point load the material right below the load is in compression;
  the tension that cracks a brittle solid peaks beside it). Under the "fem" stress model,
  which sees the body bend, the search covers every particle nearer to that contact than
  to the step's other contacts: a ring's bending peak lies a tube's width from the contact. The full stress field (every
  particle, every neighbour) is also computed: it sets the crack extent when
  ``crack_length`` is None and the per-fragment peak stress.
- **Several contacts in one step** are analysed together: linear elasticity superposes, so
  the displacement field is the sum of every contact's Boussinesq-Cerruti field; each
  contact then gets its own analysis point and its own cracks (the union is cut).
- **Grouping (step 9)**: the analysis point's SPH neighbours are split into n =
  ``crack_count`` sectors by their azimuth around the contact-normal axis through the
  analysis point, measured from a
  start angle drawn from ``seed`` (and the contact's index, so two contacts of one step do
  not share it). Sector k holds the neighbours with azimuth in
  [theta0 + 2 pi k / n, theta0 + 2 pi (k+1) / n). Each sector's neighbours alone give a
  displacement gradient, a stress and principal stresses at the analysis point; n = 1 uses
  every neighbour and is the physical answer. Azimuthal sectors are used because a point
  load's surface stresses vary around the normal (radial tension), so sectors see different
  stress states and give different directions, and the groups depend on nothing but the
  geometry and the seed.
  Groups use the plain kernel sum of BRIEF.md eq. 7 (n = 1 follows
  ``options.corrected_gradient``): the Bonet-Lok correction recovers a smooth field's
  gradient from any non-degenerate subset, so corrected sectors give n noisy copies of one
  direction, while the plain sum over a one-sided sector leans toward that sector and the
  n cracks fan out around the contact -- which is what step 9 asks for.
- **Stress model** (``options.stress_model``, docs/guide/stress-models.md): "halfspace"
  evaluates the exact stress of the regularised half-space load at the particles
  (``halfspace.py``), "sph" the paper's SPH gradient of its displacement (``fused.py``),
  "fem" linear elasticity on the body's tets (``fem.py``). The analysis point, the Rankine
  test, the crack extent and a single group's direction read that stress; n > 1 groups take
  the plain SPH sector sums of the model's displacement (the half-space field, or the FEM
  nodal displacement averaged to the tet), so the cracks fan out alike under every model.
- **Rankine (step 8)** decides *whether*: a contact cracks only if the largest principal
  stress of the full field at its analysis point exceeds ``material.tensile_strength``
  (the physical stress, every neighbour). The groups decide *where*: each non-empty group
  then gives one crack, its plane through the analysis point with normal = the group's
  largest principal direction. So an artist asking for n cracks gets n (or fewer if a
  sector is empty) whenever the impact is strong enough.
- **Crack extent**: a crack is a disc of radius ``extent`` about the analysis point in its
  plane. ``extent = options.crack_length`` if given; otherwise the distance to the farthest
  over-threshold particle (full field) lying within one smoothing length of the plane, and
  at least one smoothing length (the crack must at least cross the analysis point's own
  bonds).
- **Concentric cracks** (``ring_crack_count`` = m, beyond the paper, whose cracks are
  planes): each cracking contact also gets m spheres about its analysis point, radii
  j / (m + 1) of its longest crack, which cut the planes' wedges into rings, as a pane
  struck by a ball breaks. m = 0 (the default) is the paper's model.
"""

from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass

import numpy as np

from ..geometry import rows
from ..model import BodyModel
from ..options import FractureOptions, Material
from .fem import elastic_body_of, fem_response
from .field import load_rows
from .fused import stress_at as _stress_at
from .halfspace import halfspace_stress_rows
from .sph import neighbor_lists
from .stress import largest_principal_stress, principal_stresses

# Analysis points are sought within this many smoothing lengths (kernel support radii,
# fracture/sph.py) of the contact point.
ANALYSIS_RADIUS_FACTOR = 2.0


@dataclass(frozen=True)
class CrackPlane:
    """One planar crack, body frame.

    Attributes:
        point: (3,) [m] a point of the plane (the analysis point).
        normal: (3,) unit normal (the largest principal stress direction).
        extent: [m] radius of the crack disc about ``point``.
        peak_stress: [Pa] the group's largest principal stress.
        impact_index: which contact of the analysis produced it.
        group_index: which neighbour group (0 .. crack_count - 1).
    """

    point: np.ndarray
    normal: np.ndarray
    extent: float
    peak_stress: float
    impact_index: int = 0
    group_index: int = 0


@dataclass(frozen=True)
class RingCrack:
    """One concentric crack, body frame: the sphere of ``radius`` [m] about ``point`` (3,)
    [m], the analysis point (``FractureOptions.ring_crack_count``). It cuts every bond whose
    two tet centroids lie on either side of the sphere. ``peak_stress`` [Pa]: the analysis
    point's largest principal stress; ``impact_index``: which contact; ``ring_index``:
    1 (innermost) .. ring_crack_count."""

    point: np.ndarray
    radius: float
    peak_stress: float
    impact_index: int = 0
    ring_index: int = 1


@dataclass(frozen=True, eq=False)
class ImpactAnalysis:
    """The stress analysis of one body's contacts in one step, body frame. K analysed
    contacts (those over ``impact_force_threshold``), n = crack_count groups, T particles.

    Attributes:
        contact_point: (K,3) [m]; normal_in: (K,3) unit, into the body; force: (K,3) [N] on
            the body.
        analysis_particle: (K,) int, each contact's analysis point (largest principal stress
            within 2 h of the contact point).
        analysis_point: (K,3) [m] its position.
        smoothing_length: h [m], the SPH kernel's support radius (fracture/sph.py).
        contact_radius: (K,) [m] regularisation radius used for each contact.
        particle_stress: (T,3,3) [Pa] full-field stress (every neighbour); zeros if K = 0.
        particle_principal_stress: (T,) [Pa] its largest principal value.
        field_particles: None when the stress was computed at every particle; else (L,)
            the particles it was computed at (those within reach of a contact, see
            ``analyze_impact(full_field=False)``), the other rows of the two arrays above
            being NaN.
        group_neighbor_count: (K,n) neighbours in each group.
        group_stress: (K,n,3,3) [Pa] each group's stress at its analysis point (a local
            analysis: NaN, and counts 0, for contacts that do not pass the Rankine test).
        group_principal_values: (K,n,3) [Pa] descending.
        group_principal_directions: (K,n,3,3) unit columns matching the values.
        cracks: the crack planes (union over contacts), in (contact, group) order, each
            contact's ``RingCrack``s (if ``ring_crack_count``) after its planes.
        tensile_strength: [Pa] the Rankine threshold used.
    """

    contact_point: np.ndarray
    normal_in: np.ndarray
    force: np.ndarray
    analysis_particle: np.ndarray
    analysis_point: np.ndarray
    smoothing_length: float
    contact_radius: np.ndarray
    particle_stress: np.ndarray
    particle_principal_stress: np.ndarray
    group_neighbor_count: np.ndarray
    group_stress: np.ndarray
    group_principal_values: np.ndarray
    group_principal_directions: np.ndarray
    cracks: tuple
    tensile_strength: float
    field_particles: np.ndarray | None = None

    @property
    def any_crack(self) -> bool:
        return len(self.cracks) > 0

    @property
    def peak_principal_stress(self) -> float:
        """[Pa] largest principal stress seen anywhere (full field and every group)."""
        peaks = [0.0]
        if self.particle_principal_stress.size:
            peaks.append(float(np.nanmax(self.particle_principal_stress)))
        if np.any(np.isfinite(self.group_principal_values)):
            peaks.append(float(np.nanmax(self.group_principal_values[..., 0])))
        return max(peaks)


def tangent_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (e1, e2) with (e1, e2, normal) right-handed, chosen deterministically
    from the normal alone (e1 = normal x the coordinate axis least aligned with it)."""
    axis = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(normal, axis)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


@functools.lru_cache(maxsize=4096)
def start_angle(seed: int, impact_index: int) -> float:
    """The seeded azimuth [rad] where the first neighbour sector begins. (Kept: making the
    generator takes ~0.2 ms, and a scene asks for the same few pairs again and again.)"""
    return float(np.random.default_rng([seed, impact_index]).uniform(0.0, 2.0 * np.pi))


def group_neighbors(
    positions: np.ndarray, neighbors: np.ndarray, center: np.ndarray, normal: np.ndarray,
    group_count: int, theta0: float,
) -> np.ndarray:
    """Sector index (M,) in [0, group_count) of each neighbour: its azimuth about the axis
    through ``center`` (the analysis point) along the contact normal, measured from
    ``theta0`` in the (e1, e2) tangent frame."""
    e1, e2 = tangent_frame(normal)
    d = positions[neighbors] - center
    azimuth = np.arctan2(d @ e2, d @ e1)
    turn = np.mod(azimuth - theta0, 2.0 * np.pi)
    return np.minimum((turn * group_count / (2.0 * np.pi)).astype(np.int64), group_count - 1)


def _as_rows(a, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1:
        a = a[None, :]
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be (3,) or (K,3), got shape {a.shape}")
    return a


_NEIGHBORS: "weakref.WeakKeyDictionary[BodyModel, dict]" = weakref.WeakKeyDictionary()


def model_neighbor_lists(model: BodyModel, h: float):
    """The full-field SPH neighbour lists (CSR offsets int64, indices int32) of a body model's
    physics particles within ``h`` [m]. They are fixed in the body frame, so they are
    built once per model and h and kept while the model lives (a ring struck again, or
    several rings built from one model, reuse them: 9 ms a build for a 5,550-particle
    ring, about half of an analysis). A fragment's are its root's restricted to its
    particles (``BodyModel.root``, ``source_tet``): the same pairs, the distances being
    the root's, ~1 ms instead of a grid search."""
    per_model = _NEIGHBORS.setdefault(model, {})
    if h not in per_model:
        if model.root is not None:
            per_model[h] = restrict_neighbor_lists(*model_neighbor_lists(model.root, h), model.source_tet,
                                                   model.root.tet_count)
        else:
            offsets, indices = neighbor_lists(model.particle_position, h)
            # int32 indices: what the gradient kernel takes (an int64 copy converted every
            # analysis cost ~0.1 ms for a ring's 130k pairs).
            per_model[h] = (np.asarray(offsets, dtype=np.int64), np.asarray(indices, dtype=np.int32))
    return per_model[h]


def restrict_neighbor_lists(offsets, indices, subset, count):
    """CSR neighbour lists of the points ``subset`` (S,) (ascending indices of ``count``
    points) from lists over all of them: row s keeps the neighbours of point subset[s] that
    are in the subset, renumbered to positions in it (still ascending)."""
    subset = np.asarray(subset, dtype=np.int64)
    local = np.full(count, -1, dtype=np.int32)
    local[subset] = np.arange(len(subset), dtype=np.int32)
    return _gather_rows(offsets, indices, subset, local)


def neighbor_rows(model: BodyModel, h: float, query: np.ndarray):
    """CSR lists (offsets (Q+1,) int64, indices int32) of the SPH neighbours of the
    particles ``query`` (Q,) only: row q is :func:`model_neighbor_lists`' row
    ``query[q]``, the same neighbours in the same order. A piece whose own lists are not
    built yet reads its root's rows and maps them to its particles, so a local analysis
    of a new piece (a few hundred rows) does not restrict its root's lists over the whole
    piece first (2.5 ms on a ring's big piece)."""
    query = np.asarray(query, dtype=np.int64)
    if h in _NEIGHBORS.get(model, {}) or model.root is None:
        return _gather_rows(*model_neighbor_lists(model, h), query)
    local = np.full(model.root.tet_count, -1, dtype=np.int32)
    local[model.source_tet] = np.arange(model.tet_count, dtype=np.int32)
    return _gather_rows(*model_neighbor_lists(model.root, h), model.source_tet[query].astype(np.int64), local)


def _gather_rows(offsets, indices, rows, renumber=None):
    """CSR lists (offsets int64, indices int32) of the rows ``rows`` (R,) of the CSR lists
    ``offsets``, ``indices``, in that order; with ``renumber`` (int32, -1 = drop), each
    neighbour j becomes renumber[j] and the dropped ones leave their row."""
    begin = offsets[rows]
    lengths = offsets[rows + 1] - begin
    starts = np.cumsum(lengths) - lengths
    found = indices[np.arange(int(lengths.sum())) + np.repeat(begin - starts, lengths)]
    out_offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    if renumber is None:
        np.cumsum(lengths, out=out_offsets[1:])
        return out_offsets, np.asarray(found, dtype=np.int32)
    found = renumber[found]
    keep = found >= 0
    np.cumsum(np.bincount(np.repeat(np.arange(len(rows)), lengths)[keep], minlength=len(rows)), out=out_offsets[1:])
    return out_offsets, found[keep]


def smoothing_length(model: BodyModel, options: FractureOptions) -> float:
    """h [m] = ``options.smoothing_length_factor`` x the model's particle spacing (a
    fragment's is its root's, so its particles keep their neighbours)."""
    return float(options.smoothing_length_factor) * model.spacing


def analyze_impact(
    model: BodyModel,
    contact_point_body,
    normal_in_body,
    force_body,
    material: Material,
    options: FractureOptions,
    *,
    full_field: bool = True,
) -> ImpactAnalysis:
    """Stress and crack planes of one body's contacts in one step (body frame).

    ``contact_point_body``, ``normal_in_body`` (into the body) and ``force_body`` (on the
    body, [N]) are (3,) for one contact or (K,3) for several analysed together. Contacts
    with |force| below ``options.impact_force_threshold`` are ignored.

    ``full_field=False`` (the simulation's choice) first computes the stress only at the
    particles within reach of the contacts, which is all the Rankine test and the crack
    planes read, and the whole field only where a crack's extent needs it (a contact
    passes the test and ``options.crack_length`` is None: the extent is the reach of the
    over-strength particles): most impacts over the force threshold crack nothing (the
    glass scene: 78 of 84), and for them the analysis touches a few hundred particles
    instead of every one. The cracks are the same either way (the stress at a particle
    depends on its neighbours only). A local analysis has ``field_particles`` set and NaN
    stress elsewhere; where its cracks do split the body, the fragments' peak stress needs
    the whole field: analyse again with ``full_field=True`` (the simulation does when it
    writes a cache, whose per-face stress reads it).
    """
    points = np.ascontiguousarray(model.particle_position, dtype=np.float64)
    volumes = np.ascontiguousarray(model.tet_volume, dtype=np.float64)
    t_count = model.tet_count
    n_groups = options.crack_count
    contact = _as_rows(contact_point_body, "contact_point_body")
    normal = _as_rows(normal_in_body, "normal_in_body")
    force = _as_rows(force_body, "force_body")
    if not (len(contact) == len(normal) == len(force)):
        raise ValueError("contact points, normals and forces must have the same length")
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    keep = np.linalg.norm(force, axis=1) >= options.impact_force_threshold
    keep &= np.linalg.norm(force, axis=1) > 0.0
    contact, normal, force = contact[keep], normal[keep], force[keep]
    k_count = len(contact)
    h = smoothing_length(model, options)  # support radius

    # Load-patch radius: given, or the radius of the particle nearest the contact.
    offset = points[None, :, :] - contact[:, None, :]
    d2 = np.einsum("ktx,ktx->kt", offset, offset)  # (K,T)
    nearest = np.argmin(d2, axis=1) if k_count else np.zeros(0, dtype=np.int64)
    if options.contact_radius is not None:
        radius = np.full(k_count, options.contact_radius)
    else:
        radius = model.particle_radius[nearest].astype(np.float64)
    analysis = nearest

    empty = ImpactAnalysis(
        contact_point=contact, normal_in=normal, force=force, analysis_particle=analysis,
        analysis_point=points[analysis], smoothing_length=h, contact_radius=radius,
        particle_stress=np.zeros((t_count, 3, 3)), particle_principal_stress=np.zeros(t_count),
        group_neighbor_count=np.zeros((0, n_groups), dtype=np.int64),
        group_stress=np.zeros((0, n_groups, 3, 3)), group_principal_values=np.zeros((0, n_groups, 3)),
        group_principal_directions=np.zeros((0, n_groups, 3, 3)), cracks=(),
        tensile_strength=material.tensile_strength,
    )
    if k_count == 0:
        return empty

    # Analysis point of each contact: the particle of largest principal stress within
    # ANALYSIS_RADIUS_FACTOR h of it (right under a point load the stress is compressive;
    # the tension that cracks brittle solids peaks beside the load, BRIEF.md section 2).
    in_reach = d2 <= (ANALYSIS_RADIUS_FACTOR * h) ** 2
    in_reach[np.arange(k_count), nearest] = True

    lists = {}  # the neighbour rows in hand: "local" (rows of ``local``) or "all"
    loads = load_rows(contact, normal, force, radius)
    model_kind = options.stress_model
    if model_kind == "fem" and elastic_body_of(model, material) is None:
        model_kind = "halfspace"  # a piece whose stiffness cannot be factorised (fem.elastic_body_of)
    if model_kind == "fem":
        # The body's own tension peak can lie far from the contact (a struck ring bends and
        # is stretched on the far side of its tube): each contact's analysis point is sought
        # among every particle nearer to it than to the step's other contacts.
        in_reach = d2 <= d2.min(axis=0, keepdims=True)
    solved = {}  # "fem": the whole body's (displacement, stress), solved once

    def field(query):
        """Steps 5-7 at particles ``query`` (None: all): the stress and largest principal
        stress of ``options.stress_model``, and the displacement (T,3) the SPH sums of the
        groups read (None where it is not computed yet)."""
        q_ids = np.arange(t_count) if query is None else query
        if model_kind == "halfspace":
            _grad, stress, peak = halfspace_stress_rows(points, loads, q_ids, material.young_modulus,
                                                        material.poisson_ratio)
            return None, stress, peak
        if model_kind == "fem":
            if not solved:
                body = elastic_body_of(model, material)
                nodal, tet_stress = fem_response(body, contact, normal, force, radius)
                solved["field"] = (nodal[model.tets].mean(axis=1), tet_stress,
                                   largest_principal_stress(tet_stress))
            displacement, stress, peak = solved["field"]
            return displacement, stress[q_ids], peak[q_ids]
        if query is None:
            lists["all"] = model_neighbor_lists(model, h)
            q_off, q_idx = lists["all"]
            where = q_ids
        else:
            lists["local"] = q_off, q_idx = neighbor_rows(model, h, query)
            where = np.unique(np.concatenate([query, q_idx]))
        displacement = np.zeros((t_count, 3))
        stress, peak = _stress_at(points, volumes, displacement, loads, where, q_ids, q_off, q_idx, h,
                                  options.corrected_gradient, material)
        return displacement, stress, peak

    def neighbours_of(i):
        """Particle i's SPH neighbours (from the lists in hand when the field built them)."""
        if "all" in lists:
            offsets, indices = lists["all"]
        elif "local" in lists:
            offsets, indices = lists["local"]
            i = int(np.searchsorted(local, i))
        else:
            offsets, indices = neighbor_rows(model, h, np.array([i]))
            i = 0
        return indices[offsets[i]:offsets[i + 1]]

    # (FEM solves the whole body at once: its field is always the full one.)
    local = None if full_field or model_kind == "fem" else np.nonzero(in_reach.any(axis=0))[0]
    displacement, stress, peak = field(local)
    if local is None:
        particle_peak = peak
    else:
        particle_peak = np.full(t_count, np.nan)
        particle_peak[local] = peak
    analysis = np.argmax(np.where(in_reach, particle_peak[None, :], -np.inf), axis=1)
    # Step 8 (Rankine): the physical (full-neighbourhood) stress at each analysis point
    # decides whether its contact cracks (the local field holds it exactly).
    cracking = particle_peak[analysis] > material.tensile_strength
    if local is not None and options.crack_length is None and np.any(cracking):
        local = None  # a crack whose extent reads the whole field
        displacement, stress, particle_peak = field(None)
    if local is not None:
        partial = np.full((t_count, 3, 3), np.nan)
        partial[local] = stress
        stress = partial

    # Step 9: each contact's neighbours in n azimuthal sectors, one stress per sector. Only
    # the crack directions read them, so a local analysis (the simulation's) computes them
    # only for the contacts that pass the Rankine test; the others' are NaN (most impacts
    # crack nothing: in the glass scene 390 of 461 analyses, each saving three launches).
    grouped = np.arange(k_count) if full_field else np.nonzero(cracking)[0]
    counts = np.zeros((k_count, n_groups), dtype=np.int64)
    group_stress = np.full((k_count, n_groups, 3, 3), np.nan)
    g_values = np.full((k_count, n_groups, 3), np.nan)
    g_dirs = np.full((k_count, n_groups, 3, 3), np.nan)
    if len(grouped):
        group_rows, query = [], []
        for k in grouped:
            i = int(analysis[k])
            nbrs = neighbours_of(i)
            sector = group_neighbors(points, nbrs, points[i], normal[k], n_groups,
                                     start_angle(options.seed, int(k)))
            order = np.argsort(sector, kind="stable")
            counts[k] = np.bincount(sector, minlength=n_groups)
            group_rows.append(nbrs[order])
            query.extend([i] * n_groups)
        group_offsets = np.zeros(len(grouped) * n_groups + 1, dtype=np.int64)
        np.cumsum(counts[grouped].reshape(-1), out=group_offsets[1:])
        group_indices = np.concatenate(group_rows)
        query = np.asarray(query, dtype=np.int32)
        if n_groups == 1 and model_kind != "sph":
            # One group is the whole neighbourhood: the physical answer, the model's own stress.
            stress_g = stress[query]
            values_g, dirs_g = principal_stresses(stress_g)
        else:
            # n > 1: the plain kernel sum (BRIEF.md eq. 7) of the model's displacement. The
            # Bonet-Lok correction reproduces a smooth field's gradient from any
            # non-degenerate subset, so corrected sectors would give n noisy copies of one
            # direction; the plain sum over a one-sided sector leans toward the sector, which
            # is what fans the n cracks out (module docstring).
            group_corrected = options.corrected_gradient if n_groups == 1 else False
            where = None if displacement is not None else np.unique(np.concatenate([query, group_indices]))
            if displacement is None:
                displacement = np.zeros((t_count, 3))
            stress_g, _, values_g, dirs_g = _stress_at(points, volumes, displacement, loads, where, query,
                                                       group_offsets, group_indices, h, group_corrected, material,
                                                       decompose=True)
        group_stress[grouped] = stress_g.reshape(len(grouped), n_groups, 3, 3)
        g_values[grouped] = np.asarray(values_g).reshape(len(grouped), n_groups, 3)
        g_dirs[grouped] = np.asarray(dirs_g).reshape(len(grouped), n_groups, 3, 3)

    # Step 8 (Rankine) and the extent of each crack.
    over = particle_peak > material.tensile_strength
    cracks = []
    for k in range(k_count):
        origin = points[analysis[k]]
        if not cracking[k]:
            continue
        for g in range(n_groups):
            peak = float(g_values[k, g, 0])
            if not np.all(np.isfinite(g_dirs[k, g])) or counts[k, g] == 0:
                continue
            crack_normal = g_dirs[k, g, :, 0]
            crack_normal = crack_normal / np.linalg.norm(crack_normal)
            if options.crack_length is not None:
                extent = float(options.crack_length)
            else:
                rel = points[over] - origin
                near_plane = np.abs(rel @ crack_normal) <= h
                reach = np.linalg.norm(rel[near_plane], axis=1)
                extent = max(h, float(reach.max()) if reach.size else 0.0)
            cracks.append(CrackPlane(point=origin.copy(), normal=crack_normal, extent=extent,
                                     peak_stress=peak, impact_index=k, group_index=g))
        planes = [c for c in cracks if isinstance(c, CrackPlane) and c.impact_index == k]
        rings = options.ring_crack_count
        if planes and rings:
            longest = max(c.extent for c in planes)
            cracks.extend(RingCrack(point=origin.copy(), radius=longest * j / (rings + 1),
                                    peak_stress=float(particle_peak[analysis[k]]), impact_index=k, ring_index=j)
                          for j in range(1, rings + 1))

    return ImpactAnalysis(
        contact_point=contact, normal_in=normal, force=force, analysis_particle=analysis,
        analysis_point=points[analysis].copy(), smoothing_length=h, contact_radius=radius,
        particle_stress=stress, particle_principal_stress=particle_peak,
        group_neighbor_count=counts, group_stress=group_stress, group_principal_values=g_values,
        group_principal_directions=g_dirs, cracks=tuple(cracks),
        tensile_strength=material.tensile_strength, field_particles=local,
    )


def cut_bonds(model: BodyModel, cracks) -> np.ndarray:
    """Which bonds the cracks cut: (B,) bool.

    A crack plane cuts bond (i, j) when the segment between the two tets' centroids
    crosses the plane (the centroids lie strictly on opposite sides, or one on it) and the
    crossing point lies within ``extent`` of the crack's point. A ``RingCrack`` cuts it
    when one centroid lies inside its sphere and the other on or outside. Vectorised over
    cracks x bonds.
    """
    bonds = model.bonds
    cut = np.zeros(len(bonds), dtype=bool)
    if not len(cracks) or not len(bonds):
        return cut
    x = model.particle_position
    first, second = bonds[:, 0], bonds[:, 1]
    planes = [c for c in cracks if isinstance(c, CrackPlane)]
    rings = [c for c in cracks if isinstance(c, RingCrack)]
    if planes:
        p = np.stack([c.point for c in planes])  # (C,3)
        nrm = np.stack([c.normal for c in planes])  # (C,3)
        ext = np.array([c.extent for c in planes])  # (C,)
        side = x @ nrm.T - rows.dot(p, nrm)  # (T,C) signed distances, per particle (not per bond end)
        above = side >= 0.0
        if len(planes) <= 62:
            # Each particle's sides of all planes as the bits of one integer: a bond crosses
            # plane c where its ends' codes differ in bit c (two integer gathers over the
            # bonds instead of two of (B,C) floats; the same pairs, in the same order).
            code = above.astype(np.int64) @ (np.int64(1) << np.arange(len(planes), dtype=np.int64))
            flips = code[first] ^ code[second]
            crossing = np.nonzero(flips)[0]
            which, crack = np.nonzero((flips[crossing, None] >> np.arange(len(planes))) & 1)
            bond = crossing[which]
        else:
            bond, crack = np.nonzero(above[first] != above[second])  # the crossings only (a few %)
        di, dj = side[first[bond], crack], side[second[bond], crack]
        t = di / (di - dj)
        xi = x[first[bond]]
        hit = xi + t[:, None] * (x[second[bond]] - xi) - p[crack]
        within = rows.dot(hit, hit) <= ext[crack] ** 2
        cut[bond[within]] = True
    for ring in rings:
        d = x - ring.point
        inside = rows.dot(d, d) < ring.radius ** 2
        cut |= inside[first] != inside[second]
    return cut
