"""Controllable cracks at an impact (BRIEF.md steps 8-9, and the decisions of section 3).

Everything here is in the body frame of the struck body (``BodyModel``): the stress field
of a contact never needs the body's world pose. What the analysis returns (``CrackPlane``,
``RingCrack``, ``ImpactAnalysis``) is defined in ``crack_types.py`` (and importable from
here); the SPH neighbour lists it reads are the model's (``neighbors.py``).

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

import numpy as np

from ..geometry import rows
from ..model import BodyModel
from ..options import AUTO, FractureOptions, Material
from .crack_types import CrackPlane, ImpactAnalysis, RingCrack
from .energy import (bent_force_scale, body_span, crack_counts, energy_limited_extent, impact_energies,
                     relief_length, stress_model_of)
from .sites import site_cracks, stress_sites
from .fem import contact_loads, elastic_body_of, fem_response, inertia_relief
from .field import load_rows
from .fused import stress_at as _stress_at
from .halfspace import halfspace_stress_rows
from .neighbors import model_neighbor_lists, neighbor_rows, smoothing_length
from .stress import largest_principal_stress, principal_stresses

# Analysis points are sought within this many smoothing lengths (kernel support radii,
# fracture/sph.py) of the contact point.
ANALYSIS_RADIUS_FACTOR = 2.0


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


def analyze_impact(
    model: BodyModel,
    contact_point_body,
    normal_in_body,
    force_body,
    material: Material,
    options: FractureOptions,
    *,
    full_field: bool = True,
    energy=None,
    bending_share=None,
) -> ImpactAnalysis:
    """Stress and crack planes of one body's contacts in one step (body frame).

    ``contact_point_body``, ``normal_in_body`` (into the body) and ``force_body`` (on the
    body, [N]) are (3,) for one contact or (K,3) for several analysed together. Contacts
    with |force| below ``options.impact_force_threshold`` are ignored. ``energy``: (K,) [J]
    each contact's approach energy, which sets the crack count under ``crack_count =
    "auto"`` (``energy.py``) and, under "fem", the force a bending body meets
    (``energy.bent_force_scale``); None: the count from the energy of the Hertz impact of each
    force, and the forces taken as they are.
    ``bending_share``: (K,) in [0, 1], how much of the body's bending each contact's impact
    loads (``energy.bent_force_scale``); None: 1 (the ground, a heavier body).

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
    contact, normal, force, energy, bending_share = _analysed_contacts(
        contact_point_body, normal_in_body, force_body, options.impact_force_threshold, energy, bending_share)
    h = smoothing_length(model, options)  # support radius
    points = np.ascontiguousarray(model.particle_position, dtype=np.float64)
    d2, nearest, radius = _load_patches(model, points, contact, options)
    if len(contact) == 0:
        return _no_contact(model, points, contact, normal, force, nearest, radius, h, material, options)

    field = _StressField(model, points, material, options, contact, normal, force, radius, h, energy,
                         bending_share)
    in_reach = _analysis_reach(d2, nearest, h, field.kind)
    # (FEM solves the whole body at once: its field is always the full one.)
    local = None if full_field or field.kind == "fem" else np.nonzero(in_reach.any(axis=0))[0]
    displacement, stress, peak = field.at(local)
    if local is None:
        particle_peak = peak
    else:
        particle_peak = np.full(model.tet_count, np.nan)
        particle_peak[local] = peak
    # Analysis point of each contact: the particle of largest principal stress within its
    # reach (right under a point load the stress is compressive; the tension that cracks
    # brittle solids peaks beside the load, BRIEF.md section 2).
    analysis = np.argmax(np.where(in_reach, particle_peak[None, :], -np.inf), axis=1)
    # Step 8 (Rankine): the physical (full-neighbourhood) stress at each analysis point
    # decides whether its contact cracks (the local field holds it exactly).
    cracking = particle_peak[analysis] > material.tensile_strength
    if local is not None and options.crack_length is None and np.any(cracking):
        local = None  # a crack whose extent reads the whole field
        displacement, stress, particle_peak = field.at(None)
    if local is not None:
        partial = np.full((model.tet_count, 3, 3), np.nan)
        partial[local] = stress
        stress = partial

    # Step 9, computed for the contacts that pass the Rankine test only in a local analysis
    # (the simulation's): only the crack directions read the groups, and most impacts crack
    # nothing, and each analysis skipped saves three launches.
    grouped = np.arange(len(contact)) if full_field else np.nonzero(cracking)[0]
    energies = impact_energies(model, material, force, energy)
    counts, thickness = crack_counts(model, material, options, contact[grouped], normal[grouped], energies[grouped], h)
    counts, thickness = _scatter(counts, grouped, len(contact), 1), _scatter(thickness, grouped, len(contact), np.nan)
    groups = _group_stresses(field, grouped, analysis, normal, displacement, stress, options, counts)
    reach = _energy_reach(options, energies, counts, material, thickness)
    cracks = _crack_shapes(points, analysis, cracking, groups, particle_peak, h, material, options, reach)
    if options.crack_count == AUTO and local is None and np.any(cracking):
        # Rankine away from the contacts: each other overloaded region cracks too (sites.py).
        spacing = max(2.0 * h, float(np.nanmax(np.where(cracking, thickness, np.nan))))
        relief = relief_length(model, material, force[cracking], energies[cracking],
                               None if bending_share is None else bending_share[cracking])
        sites = stress_sites(model, particle_peak, material.tensile_strength, analysis[cracking], 2.0 * h, relief)
        first = int(np.nonzero(cracking)[0][0])
        cracks = cracks + tuple(site_cracks(model, stress, particle_peak, sites, h, spacing, first,
                                            int(counts.max())))
    counts, group_stress, g_values, g_dirs = groups
    return ImpactAnalysis(
        contact_point=contact, normal_in=normal, force=force, analysis_particle=analysis,
        analysis_point=points[analysis].copy(), smoothing_length=h, contact_radius=radius,
        particle_stress=stress, particle_principal_stress=particle_peak,
        group_neighbor_count=counts, group_stress=group_stress, group_principal_values=g_values,
        group_principal_directions=g_dirs, cracks=cracks,
        tensile_strength=material.tensile_strength, field_particles=local,
    )


def _analysed_contacts(contact_point_body, normal_in_body, force_body, force_threshold: float, energy=None,
                       bending_share=None):
    """(K,3) contact points, unit normals and forces of the contacts at or over
    ``force_threshold`` [N] (and not zero), and their energies (K,) [J] and bending shares
    (K,) (each None if not given)."""
    contact = _as_rows(contact_point_body, "contact_point_body")
    normal = _as_rows(normal_in_body, "normal_in_body")
    force = _as_rows(force_body, "force_body")
    if not (len(contact) == len(normal) == len(force)):
        raise ValueError("contact points, normals and forces must have the same length")
    per_contact = {}
    for name, values in (("energy", energy), ("bending_share", bending_share)):
        if values is not None:
            values = np.atleast_1d(np.asarray(values, dtype=np.float64))
            if values.shape != (len(contact),):
                raise ValueError(f"{name} must hold one value per contact ({len(contact)}), got shape {values.shape}")
        per_contact[name] = values
    normal = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    keep = np.linalg.norm(force, axis=1) >= force_threshold
    keep &= np.linalg.norm(force, axis=1) > 0.0
    return (contact[keep], normal[keep], force[keep],
            *(None if v is None else v[keep] for v in (per_contact["energy"], per_contact["bending_share"])))


def _scatter(values: np.ndarray, where: np.ndarray, size: int, fill) -> np.ndarray:
    """(size,) ``fill`` with ``values`` at ``where``."""
    out = np.full(size, fill, dtype=values.dtype)
    out[where] = values
    return out


def _energy_reach(options: FractureOptions, energies, counts, material: Material, thickness):
    """(K,) [m] how far each contact's cracks run on its energy ``energies`` (K,) [J]
    (``energy.py``); inf where the count is the artist's (a number) or the length is given."""
    reach = np.full(len(counts), np.inf)
    if options.crack_count != AUTO or options.crack_length is not None:
        return reach
    for k in range(len(counts)):
        reach[k] = energy_limited_extent(float(energies[k]), int(counts[k]), material, float(thickness[k]))
    return reach


def _load_patches(model: BodyModel, points: np.ndarray, contact: np.ndarray, options: FractureOptions):
    """Squared distances (K,T) [m^2] from each contact to every particle, the nearest
    particle (K,), and each load patch's radius (K,) [m]: ``options.contact_radius``, or
    the radius of the particle nearest the contact."""
    offset = points[None, :, :] - contact[:, None, :]
    d2 = np.einsum("ktx,ktx->kt", offset, offset)  # (K,T)
    nearest = np.argmin(d2, axis=1) if len(contact) else np.zeros(0, dtype=np.int64)
    if options.contact_radius is not None:
        radius = np.full(len(contact), options.contact_radius)
    else:
        radius = model.particle_radius[nearest].astype(np.float64)
    return d2, nearest, radius


def _no_contact(model, points, contact, normal, force, nearest, radius, h, material, options) -> ImpactAnalysis:
    """The analysis of a step whose contacts are all under the force threshold."""
    t_count, n_groups = model.tet_count, 1 if options.crack_count == AUTO else options.crack_count
    return ImpactAnalysis(
        contact_point=contact, normal_in=normal, force=force, analysis_particle=nearest,
        analysis_point=points[nearest], smoothing_length=h, contact_radius=radius,
        particle_stress=np.zeros((t_count, 3, 3)), particle_principal_stress=np.zeros(t_count),
        group_neighbor_count=np.zeros((0, n_groups), dtype=np.int64),
        group_stress=np.zeros((0, n_groups, 3, 3)), group_principal_values=np.zeros((0, n_groups, 3)),
        group_principal_directions=np.zeros((0, n_groups, 3, 3)), cracks=(),
        tensile_strength=material.tensile_strength,
    )


def _analysis_reach(d2: np.ndarray, nearest: np.ndarray, h: float, stress_model: str) -> np.ndarray:
    """(K,T) bool: the particles where each contact's analysis point is sought. Within
    ANALYSIS_RADIUS_FACTOR h of the contact (and its nearest particle); under "fem" every
    particle nearer to it than to the step's other contacts: the body's own tension peak
    can lie far from the contact (a struck ring bends and is stretched on the far side of
    its tube)."""
    if stress_model == "fem":
        return d2 <= d2.min(axis=0, keepdims=True)
    in_reach = d2 <= (ANALYSIS_RADIUS_FACTOR * h) ** 2
    in_reach[np.arange(len(d2)), nearest] = True
    return in_reach


class _StressField:
    """Steps 5-7 of one step's contacts in one body: the stress of ``options.stress_model``
    at chosen particles. Keeps the SPH neighbour rows it read (the groups' neighbourhoods
    come from them) and, under "fem", the whole body's solution (solved once)."""

    def __init__(self, model: BodyModel, points: np.ndarray, material: Material, options: FractureOptions,
                 contact, normal, force, radius, h: float, energy=None, bending_share=None):
        self.model, self.points, self.material, self.options, self.h = model, points, material, options, h
        self.volumes = np.ascontiguousarray(model.tet_volume, dtype=np.float64)
        self.contact, self.normal, self.force, self.radius = contact, normal, force, radius
        self.energy, self.bending_share = energy, bending_share
        self.loads = load_rows(contact, normal, force, radius)
        kind = stress_model_of(model, options)
        if kind == "fem" and elastic_body_of(model, material) is None:
            kind = "halfspace"  # a piece whose stiffness cannot be factorised (fem.elastic_body_of)
        self.kind = kind
        self._all_rows = None  # (offsets, indices) of every particle, once read
        self._local_rows = None  # (query, offsets, indices) of the last local evaluation
        self._fem = None  # (displacement (T,3), stress (T,3,3), peak (T,)) of the whole body

    def at(self, query):
        """The stress (Q,3,3) [Pa] and largest principal stress (Q,) [Pa] at particles
        ``query`` (None: all), and the displacement (T,3) [m] the groups' SPH sums read
        (None where it is not computed yet)."""
        model, material = self.model, self.material
        q_ids = np.arange(model.tet_count) if query is None else query
        if self.kind == "halfspace":
            _grad, stress, peak = halfspace_stress_rows(self.points, self.loads, q_ids, material.young_modulus,
                                                        material.poisson_ratio)
            return None, stress, peak
        if self.kind == "fem":
            if self._fem is None:
                body = elastic_body_of(model, material)
                nodal, tet_stress = fem_response(body, self.contact, self.normal, self.force, self.radius)
                scale = self._bent_scale(body, nodal)
                nodal, tet_stress = scale * nodal, scale * tet_stress
                self._fem = (nodal[model.tets].mean(axis=1), tet_stress, largest_principal_stress(tet_stress))
            displacement, stress, peak = self._fem
            return displacement, stress[q_ids], peak[q_ids]
        if query is None:
            self._all_rows = q_off, q_idx = model_neighbor_lists(model, self.h)
            where = q_ids
        else:
            q_off, q_idx = neighbor_rows(model, self.h, query)
            self._local_rows = query, q_off, q_idx
            where = np.unique(np.concatenate([query, q_idx]))
        displacement = np.zeros((model.tet_count, 3))
        stress, peak = _stress_at(self.points, self.volumes, displacement, self.loads, where, q_ids, q_off, q_idx,
                                  self.h, self.options.corrected_gradient, material)
        return displacement, stress, peak

    def _bent_scale(self, body, nodal) -> float:
        """``energy.bent_force_scale`` of this step's impacts on the body (their energies and
        bending shares summed, the bending energy of the joint solution); 1 for forces given
        without the impacts' energies (the stress of those forces as they are)."""
        if self.energy is None:
            return 1.0
        loads = contact_loads(body, self.contact, self.normal, self.force, self.radius)
        bending = 0.5 * float(np.sum((loads + inertia_relief(body, loads)) * nodal))
        energies = self.energy
        share = np.ones(len(energies)) if self.bending_share is None else self.bending_share
        total = float(np.sum(energies))
        weight = float(np.sum(energies * share) / total) if total > 0.0 else 1.0
        return bent_force_scale(total, bending, weight)

    def neighbours_of(self, i: int) -> np.ndarray:
        """Particle i's SPH neighbours (from the rows in hand when the field read them)."""
        if self._all_rows is not None:
            offsets, indices = self._all_rows
        elif self._local_rows is not None:
            query, offsets, indices = self._local_rows
            i = int(np.searchsorted(query, i))
        else:
            offsets, indices = neighbor_rows(self.model, self.h, np.array([i]))
            i = 0
        return indices[offsets[i]:offsets[i + 1]]


def _group_stresses(field: _StressField, grouped: np.ndarray, analysis: np.ndarray, normal: np.ndarray,
                    displacement, stress: np.ndarray, options: FractureOptions, crack_count: np.ndarray):
    """Step 9 for the contacts ``grouped``: each one's analysis-point neighbours in n_k =
    ``crack_count[k]`` azimuthal sectors, one stress per sector. Returns the neighbour counts
    (K,n), stresses (K,n,3,3) [Pa], principal values (K,n,3) [Pa] and directions
    (K,n,3,3), n the largest count (a contact's sectors past its own count are empty); NaN
    (and counts 0) for the contacts not grouped."""
    k_count = len(analysis)
    n_groups = int(max(crack_count.max(initial=1), 1))
    points = field.points
    counts = np.zeros((k_count, n_groups), dtype=np.int64)
    group_stress = np.full((k_count, n_groups, 3, 3), np.nan)
    g_values = np.full((k_count, n_groups, 3), np.nan)
    g_dirs = np.full((k_count, n_groups, 3, 3), np.nan)
    if len(grouped) == 0:
        return counts, group_stress, g_values, g_dirs
    group_rows, query = [], []
    for k in grouped:
        i = int(analysis[k])
        nbrs = field.neighbours_of(i)
        sector = group_neighbors(points, nbrs, points[i], normal[k], int(crack_count[k]),
                                 start_angle(options.seed, int(k)))
        order = np.argsort(sector, kind="stable")
        counts[k] = np.bincount(sector, minlength=n_groups)
        group_rows.append(nbrs[order])
        query.extend([i] * n_groups)
    group_offsets = np.zeros(len(grouped) * n_groups + 1, dtype=np.int64)
    np.cumsum(counts[grouped].reshape(-1), out=group_offsets[1:])
    group_indices = np.concatenate(group_rows)
    query = np.asarray(query, dtype=np.int32)
    if n_groups == 1 and field.kind != "sph":
        # One group is the whole neighbourhood: the physical answer, the model's own stress.
        stress_g = stress[query]
        values_g, dirs_g = principal_stresses(stress_g)
    else:
        # n > 1: the plain kernel sum (BRIEF.md eq. 7) of the model's displacement. The
        # Bonet-Lok correction reproduces a smooth field's gradient from any non-degenerate
        # subset, so corrected sectors would give n noisy copies of one direction; the plain
        # sum over a one-sided sector leans toward the sector, which is what fans the n
        # cracks out (module docstring).
        group_corrected = options.corrected_gradient if n_groups == 1 else False
        where = None if displacement is not None else np.unique(np.concatenate([query, group_indices]))
        if displacement is None:
            displacement = np.zeros((len(points), 3))
        stress_g, _, values_g, dirs_g = _stress_at(points, field.volumes, displacement, field.loads, where, query,
                                                   group_offsets, group_indices, field.h, group_corrected,
                                                   field.material, decompose=True)
    group_stress[grouped] = stress_g.reshape(len(grouped), n_groups, 3, 3)
    g_values[grouped] = np.asarray(values_g).reshape(len(grouped), n_groups, 3)
    g_dirs[grouped] = np.asarray(dirs_g).reshape(len(grouped), n_groups, 3, 3)
    single = [int(k) for k in grouped if crack_count[k] == 1]
    if n_groups > 1 and single and field.kind != "sph":
        # A contact of one crack among contacts of several: its whole neighbourhood, the
        # model's own stress, as when every contact has one.
        at = analysis[single]
        values_1, dirs_1 = principal_stresses(stress[at])
        group_stress[single, 0] = stress[at]
        g_values[single, 0] = np.asarray(values_1)
        g_dirs[single, 0] = np.asarray(dirs_1)
    return counts, group_stress, g_values, g_dirs


def _crack_shapes(points, analysis, cracking, groups, particle_peak, h: float, material: Material,
                  options: FractureOptions, energy_reach) -> tuple:
    """Step 8's cracks: each cracking contact's planes (one per non-empty group, normal =
    the group's largest principal direction, extent ``crack_length``, or under an automatic
    count the contact's ``energy_reach`` (K,) [m], else the reach of the over-strength
    particles near the plane), then its ring cracks, in (contact, group) order."""
    counts, _stress, g_values, g_dirs = groups
    n_groups = counts.shape[1]
    over = particle_peak > material.tensile_strength
    cracks = []
    for k in range(len(analysis)):
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
            if np.isfinite(energy_reach[k]):
                extent = max(h, min(float(energy_reach[k]), body_span(points, origin, crack_normal, h)))
            cracks.append(CrackPlane(point=origin.copy(), normal=crack_normal, extent=extent,
                                     peak_stress=peak, impact_index=k, group_index=g))
        planes = [c for c in cracks if isinstance(c, CrackPlane) and c.impact_index == k]
        rings = options.ring_crack_count
        if planes and rings:
            longest = max(c.extent for c in planes)
            cracks.extend(RingCrack(point=origin.copy(), radius=longest * j / (rings + 1),
                                    peak_stress=float(particle_peak[analysis[k]]), impact_index=k, ring_index=j)
                          for j in range(1, rings + 1))
    return tuple(cracks)


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
