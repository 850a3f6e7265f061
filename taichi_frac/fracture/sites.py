"""Cracks away from the contact: every separate region of the body over its strength.

Under a stress model that sees the body bend, one impact can overload places far from the
contact: a ring struck on its rim is stretched at the back of its tube and, beside the
load, on the far side of the ring. Rankine's criterion holds everywhere, so with an
automatic crack count (``crack_count = "auto"``) other overloaded places crack too, unless
a crack that started earlier has relieved them first (the obscuration of dynamic
fragmentation: Grady & Kipp, Int. J. Rock Mech. 17, 1980; Denoual & Hild, 2000). The load
rises to its peak in half the contact time t_c, so a place of peak stress sigma reaches the
strength at a time proportional to strength / sigma; a crack that started at time t_j
unloads the body around it with a relief wave at the bar speed c = sqrt(E / rho). A place
cracks on its own if no earlier crack's relief has reached it when it reaches the strength:
if its distance to every earlier crack's origin exceeds

    c t_c / 2 x strength x (1 / sigma - 1 / sigma_j),

and a resolution floor of two smoothing lengths. The most stressed places go first. The
harder the hit, the more the peak exceeds the strength, the less time relief has, and the
more places crack.

Each such crack goes through its particle, normal to the largest principal direction there
(mode I), across the body's whole section, where that section is narrow (at most
:data:`SEVERS` times the body's thickness under the contact): a rod, a ring's tube, a
handle, a leg -- not a plate, whose far tension its star of radial cracks answers.

Body frame, SI units.
"""

from __future__ import annotations

import numpy as np

from ..model import BodyModel
from .crack_types import CrackPlane
from .energy import body_span
from .stress import principal_stresses

#: At most this many cracks away from the contacts per analysis (the most stressed regions).
MAX_SITES = 16
#: A site cracks only where its crack severs the body: where the body's section in the
#: crack's plane (``energy.body_span`` from the site) is at most this many times the body's
#: thickness under the contact (a rod, a ring's tube, a handle), not across a plate.
SEVERS = 2.0


def stress_sites(model: BodyModel, peak: np.ndarray, strength: float, origins, min_spacing: float,
                 relief_length: float) -> np.ndarray:
    """(S,) the over-strength particles that crack on their own, most stressed first (at most
    :data:`MAX_SITES`; module docstring). ``peak``: (T,) [Pa] every particle's largest
    principal stress; ``origins``: the particles where cracks start already (the contacts'
    analysis points); ``min_spacing`` [m]: no two crack origins closer; ``relief_length``
    [m]: c t_c / 2, how far a stress-relief wave runs while the load rises to its peak."""
    over = np.nonzero(np.isfinite(peak) & (peak > strength))[0]
    origins = np.asarray(origins, dtype=np.int64)
    if len(over) == 0:
        return np.zeros(0, dtype=np.int64)
    over = over[np.argsort(-peak[over], kind="stable")]
    positions = np.asarray(model.particle_position, dtype=np.float64)
    started = list(origins)
    sites = []
    for i in over:
        if len(sites) == MAX_SITES:
            break
        at = np.asarray(started, dtype=np.int64)
        # Crack j started when the rising load brought its particle to the strength, at a
        # time proportional to strength / peak_j; particle i gets there later, by when j's
        # relief has run relief_length x strength x (1/peak_i - 1/peak_j).
        reach = relief_length * strength * (1.0 / peak[i] - 1.0 / peak[at])
        gap = np.linalg.norm(positions[at] - positions[i], axis=1)
        if np.all(gap > np.maximum(reach, min_spacing)):
            started.append(int(i))
            sites.append(int(i))
    return np.asarray(sites, dtype=np.int64)


def site_cracks(model: BodyModel, stress: np.ndarray, peak: np.ndarray, sites: np.ndarray, h: float,
                spacing: float, impact_index: int, first_group: int) -> list[CrackPlane]:
    """One crack plane per site whose section is narrow (module docstring), reaching across
    that section: groups numbered on from ``first_group``."""
    if len(sites) == 0:
        return []
    points = np.asarray(model.particle_position, dtype=np.float64)
    _values, directions = principal_stresses(stress[sites])
    cracks = []
    for j, i in enumerate(sites):
        normal = np.asarray(directions[j][:, 0], dtype=np.float64)
        normal = normal / np.linalg.norm(normal)
        span = body_span(points, points[i], normal, h)
        if span > SEVERS * spacing:
            continue  # (a wide section: a plate's far tension is its star's to answer)
        cracks.append(CrackPlane(point=points[i].copy(), normal=normal, extent=span, peak_stress=float(peak[i]),
                                 impact_index=impact_index, group_index=first_group + len(cracks)))
    return cracks
