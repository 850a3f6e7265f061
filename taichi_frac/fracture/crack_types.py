"""What an impact's analysis finds (``cracks.analyze_impact``), body frame, SI units: the
crack planes, the concentric ring cracks, and the analysis itself (stress field, groups,
cracks) that ``fragments.split_body`` cuts along and the cache records."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
