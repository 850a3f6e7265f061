"""What an impact can pay for: the automatic crack count and the automatic stress model.

**How many cracks** (``crack_count = "auto"``). An impact brings the energy E of its
approach (1/2 m* v^2, the reduced mass of the touching pair and their approach speed).
A crack through the body costs its area times the fracture energy G_c = K_Ic^2 / E_Young
(Griffith; ``Material.fracture_energy``), and the scale of that cost is one crack right
through the struck body: E_1 = G_c d L, with d the body's thickness under the contact,
along the contact normal (the wall it strikes: a ring's tube, not the ring), and
L = sqrt(V / (pi d)) the radius of a disc of that thickness holding the body's volume V (a
pane's half-width). The count is

    n = crack_scale x (E / E_1)^(1/4), rounded, 1 to 64.

The fourth root is the star-crack law of Vandenberghe, Vermorel & Villermaux (Phys. Rev.
Lett. 110, 174302, 2013): the number of radial cracks in a struck plate grows as the
square root of the impact speed, i.e. as the fourth root of the impact energy, and falls
with the plate's thickness; their Griffith balance of bending and fracture energy explains
it. Here E_1 grows with d, so a thicker body gets fewer cracks, and a weaker material (lower
K_Ic) more. Once the stress at the hit exceeds the strength, the cracks run as far as the
energy pays for (a brittle crack, once started, runs until the energy it releases no longer
covers its new surface): n cracks through thickness d cost n G_c d per metre, so each runs
E / (n G_c d) from the analysis point, across the whole body unless the hit is barely over
the threshold; and no further than the body reaches without a break in the crack's plane
(:func:`body_span`: a crack cannot run across a hole). With a number for ``crack_count`` they run as far as the stress exceeds the
strength (or ``crack_length``): the artist then sets the pattern.

**The force a bending body meets.** The contact force is the peak of a Hertz impact
(``dynamics/impacts.py``), which assumes a rigid body behind the contact. A body that bends
under the hit (the "fem" model) is softer: its bending takes part of the approach energy,
and the peak force is lower. Under "fem" the stress field is scaled by the factor
:func:`bent_force_scale` finds from the energy balance (linear elasticity: the field is
proportional to the force), for impacts with the ground or heavier bodies in full and for
light projectiles in proportion to their mass.

**Which stress model** (``stress_model = "auto"``). A slender body -- a plate, a rod, a
ring, a shell -- breaks by bending: tension on the far side of the hit, which the
half-space model (a contact on an infinite solid) cannot have. "auto" takes the body's own
elasticity ("fem") where the body is slender, and the exact half-space field where it is
compact. Slenderness is the mean thickness 2 V / A (V the volume, A the surface area) over
the diagonal of its bounding box: 0.19 for a cube or a sphere, 0.07 for a ring of radii 0.1
and 0.025 m, 0.014 for a 4 mm pane of 0.2 m; under :data:`SLENDER` (0.12: a 4:1 bar and
anything thinner) the body is slender.

Units SI.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from ..model import BodyModel
from ..options import AUTO, FractureOptions, Material

#: Bodies whose slenderness (module docstring) is below this take the "fem" model under "auto".
SLENDER = 0.12

_SLENDERNESS: "weakref.WeakKeyDictionary[BodyModel, float]" = weakref.WeakKeyDictionary()


def slenderness(model: BodyModel) -> float:
    """2 V / A over the bounding-box diagonal [-] of a body (module docstring); kept per model."""
    value = _SLENDERNESS.get(model)
    if value is None:
        verts = np.asarray(model.vertices, dtype=np.float64)
        tri = verts[np.asarray(model.surface_faces)]
        area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
        volume = float(np.sum(model.tet_volume))
        diagonal = float(np.linalg.norm(verts.max(axis=0) - verts.min(axis=0)))
        value = 2.0 * volume / area / diagonal if area > 0.0 and diagonal > 0.0 else 1.0
        _SLENDERNESS[model] = value
    return value


def stress_model_of(model: BodyModel, options: FractureOptions) -> str:
    """The stress model a body's impacts use: ``options.stress_model``, with "auto" resolved
    by the body's slenderness ("fem" under :data:`SLENDER`, else "halfspace")."""
    if options.stress_model != AUTO:
        return options.stress_model
    return "fem" if slenderness(model) < SLENDER else "halfspace"


def thickness_under(model: BodyModel, point, normal, radius: float) -> float:
    """d [m]: the body's extent along ``normal`` through ``point`` (body frame): the spread of
    the particles within ``radius`` of that line, from the first to the last before a gap of
    more than ``radius`` (the wall the line enters first), plus one particle spacing (the
    particles are tet centroids, half a spacing inside each face). At least one spacing."""
    x = np.asarray(model.particle_position, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    rel = x - np.asarray(point, dtype=np.float64)
    along = rel @ n
    off = rel - np.outer(along, n)
    near = np.einsum("ij,ij->i", off, off) <= radius * radius
    spacing = float(np.mean(model.tet_volume)) ** (1.0 / 3.0)
    if np.count_nonzero(near) < 2:
        return spacing
    # From the contact's side to the first gap (a hole: a ring's far side is another wall).
    run = np.sort(along[near])
    gaps = np.nonzero(np.diff(run) > radius)[0]
    end = run[gaps[0]] if gaps.size else run[-1]
    return float(end - run[0]) + spacing


def crack_energy_scale(model: BodyModel, material: Material, thickness: float) -> float:
    """E_1 = G_c d L [J]: one crack right through the body (module docstring)."""
    volume = float(np.sum(model.tet_volume))
    reach = math.sqrt(volume / (math.pi * thickness))
    return material.fracture_energy * thickness * reach


def auto_crack_count(energy: float, unit_energy: float, scale: float = 1.0) -> int:
    """n = scale x (energy / unit_energy)^(1/4), rounded, in [1, 64] (module docstring)."""
    if not (energy > 0.0 and unit_energy > 0.0):
        return 1
    return int(min(64, max(1, round(scale * (energy / unit_energy) ** 0.25))))


def hertz_impact_energy(force: float, model: BodyModel, material: Material) -> float:
    """[J] the approach energy of the Hertz impact on a rigid flat whose peak force is
    ``force`` [N] (the body as the sphere of its own volume, as ``dynamics/impacts.py``
    models impacts): W = 2/5 F delta, delta = (3 F / (4 E* sqrt(R)))^(2/3). Used when an
    analysis is given forces but no energies."""
    radius = (3.0 * float(np.sum(model.tet_volume)) / (4.0 * math.pi)) ** (1.0 / 3.0)
    e_star = material.young_modulus / (1.0 - material.poisson_ratio**2)
    delta = (3.0 * force / (4.0 * e_star * math.sqrt(radius))) ** (2.0 / 3.0)
    return 0.4 * force * delta


def impact_energies(model: BodyModel, material: Material, force, energy=None) -> np.ndarray:
    """(K,) [J] the approach energies of impacts of peak forces ``force`` (K,3) [N]:
    ``energy`` where given, else each force's :func:`hertz_impact_energy`."""
    if energy is not None:
        return np.asarray(energy, dtype=np.float64)
    return np.array([hertz_impact_energy(float(f), model, material)
                     for f in np.linalg.norm(np.atleast_2d(np.asarray(force, dtype=np.float64)), axis=1)])


def crack_counts(model: BodyModel, material: Material, options: FractureOptions, contact, normal, energy,
                 radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Per contact (K,): the crack count and the thickness d [m] under it; ``energy`` (K,)
    [J] the impacts' (:func:`impact_energies`)."""
    k = len(contact)
    if options.crack_count != AUTO:
        return np.full(k, int(options.crack_count), dtype=np.int64), np.full(k, np.nan)
    counts = np.ones(k, dtype=np.int64)
    thickness = np.zeros(k)
    for i in range(k):
        thickness[i] = thickness_under(model, contact[i], normal[i], radius)
        counts[i] = auto_crack_count(float(energy[i]), crack_energy_scale(model, material, thickness[i]),
                                     options.crack_scale)
    return counts, thickness


def body_span(points: np.ndarray, origin, normal, h: float) -> float:
    """[m] how far the body reaches, without a break, from ``origin`` in the plane through it
    normal to ``normal``: the distance to the last particle within ``h`` of the plane before
    the first gap of more than ``h`` between particles' distances (a hole, the body's edge).
    A crack cannot run across empty space: a crack through a ring's tube stops at the hole,
    and does not cut the far side of the ring."""
    rel = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    off = rel @ np.asarray(normal, dtype=np.float64)
    near = np.abs(off) <= h
    r = np.sort(np.sqrt(np.maximum(np.einsum("ij,ij->i", rel[near], rel[near]) - off[near] ** 2, 0.0)))
    if r.size == 0 or r[0] > h:
        return h
    gaps = np.nonzero(np.diff(r) > h)[0]
    return float(r[gaps[0]] if gaps.size else r[-1]) + 0.5 * h


def bent_force_scale(impact_energy: float, bending_energy: float, share: float = 1.0) -> float:
    """s in (0, 1]: the peak force of an impact on a body that bends, as a fraction of the
    Hertz force F_H that a rigid body behind the contact would meet (module docstring).

    A Hertz impact stores all its approach energy E in the contact's indentation at its
    peak, W = 2/5 F delta(F) with delta ~ F^(2/3), so W(s F_H) = s^(5/3) E. A body that also
    bends (quasi-statically, as its own elasticity answers: ``bending_energy`` U = 1/2 u.K u
    under F_H) stores s^2 U more, of which ``share`` [0, 1] is loaded: the struck body's
    share of the pair's mass, m_other / (m_body + m_other) (1 against the ground). A light
    projectile's short contact is over before a heavy body bends as a whole (the impact is
    wave-controlled; Olsson, Composites A 31, 2000), a heavy one's or the ground's is not.
    Energy: s^(5/3) E + share s^2 U = E, solved for s."""
    if not (impact_energy > 0.0) or not (bending_energy > 0.0) or not (share > 0.0):
        return 1.0
    ratio = share * bending_energy / impact_energy
    low, high = 0.0, 1.0
    for _ in range(60):  # (monotone in s: bisection to double precision)
        mid = 0.5 * (low + high)
        if mid ** (5.0 / 3.0) + ratio * mid * mid > 1.0:
            high = mid
        else:
            low = mid
    return 0.5 * (low + high)


def relief_length(model: BodyModel, material: Material, force, energy, share=None) -> float:
    """[m] c t_c / 2 of a step's cracking impacts (``sites.py``): the bar wave speed
    c = sqrt(E / rho) times half the longest Hertz contact time, t_c = 2.94 delta / v with
    delta = 5 W / (2 F) (W = 2/5 F delta, the approach energy ``energy`` (K,) [J]) and
    v = sqrt(2 W / m*), m* the body's mass times its ``share`` (the reduced mass; 1 against
    the ground)."""
    force = np.linalg.norm(np.atleast_2d(np.asarray(force, dtype=np.float64)), axis=1)
    energy = np.asarray(energy, dtype=np.float64)
    share = np.ones(len(force)) if share is None else np.asarray(share, dtype=np.float64)
    mass = float(model.mass)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = 2.5 * energy / force
        speed = np.sqrt(2.0 * energy / (mass * np.maximum(share, 1e-12)))
        duration = np.where((force > 0) & (speed > 0), 2.94 * depth / speed, 0.0)
    wave = math.sqrt(material.young_modulus / material.density)
    return wave * 0.5 * float(np.max(duration, initial=0.0))


def energy_limited_extent(energy: float, count: int, material: Material, thickness: float) -> float:
    """[m] how far ``count`` cracks through ``thickness`` can run on ``energy``: E / (n G_c d)."""
    return float(energy) / (max(count, 1) * material.fracture_energy * thickness)
