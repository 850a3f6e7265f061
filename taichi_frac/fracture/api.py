"""One impact's stress field in a body: ``contact_field``.

Chains the stages of BRIEF.md §1 steps 5-8: Boussinesq-Cerruti displacement at every
physics particle (``field.py``), SPH displacement gradient (``sph.py``), Green-Saint-Venant
strain, Hooke stress and principal stresses (``stress.py``). Everything is in the body
frame and in SI units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..options import FractureOptions
from .field import point_load_displacement
from .sph import default_smoothing_length, displacement_gradient, neighbor_lists
from .stress import principal_stresses, stress_from_gradient


@dataclass(frozen=True, eq=False)
class ContactField:
    """The elastic state of one body under one contact force. N particles, M pairs.

    Attributes:
        displacement: (N,3) [m] body frame.
        gradient: (N,3,3) [-] grad u, gradient[n, a, b] = d u_a / d x_b.
        stress: (N,3,3) [Pa], symmetric.
        principal_values: (N,3) [Pa], descending.
        principal_directions: (N,3,3) unit columns matching principal_values.
        principal_stress: (N,) [Pa] the largest principal stress (Rankine).
        principal_direction: (N,3) unit, its direction (the crack plane's normal).
        smoothing_length: h [m] used (kernel support radius).
        contact_radius: a [m] used to regularise the load (field.py).
        neighbor_offsets: (N+1,) int32 and neighbor_indices: (M,) int32, the CSR neighbour
            lists within h (reusable for per-group gradients).
        correction_fallback: (N,) bool, particles where the Bonet-Lok correction was skipped
            (near-singular neighbourhood; plain sum used). All False when not corrected.
    """

    displacement: np.ndarray
    gradient: np.ndarray
    stress: np.ndarray
    principal_values: np.ndarray
    principal_directions: np.ndarray
    principal_stress: np.ndarray
    principal_direction: np.ndarray
    smoothing_length: float
    contact_radius: float
    neighbor_offsets: np.ndarray
    neighbor_indices: np.ndarray
    correction_fallback: np.ndarray


def contact_field(points, volumes, contact_point, normal, force, young_modulus, poisson_ratio,
                  smoothing_length=None, corrected=True, *, contact_radius=None,
                  options: FractureOptions | None = None) -> ContactField:
    """Displacement, stress and principal stress at a body's particles for one contact.

    Args:
        points: (N,3) [m] physics particles of one body, body frame.
        volumes: (N,) [m^3] their volumes (m / rho), > 0.
        contact_point: (3,) [m] body frame.
        normal: (3,) contact normal pointing INTO the body.
        force: (3,) [N] contact force ON the body (impulse / dt): P = force . n, Q the
            tangential part.
        young_modulus: E [Pa]; poisson_ratio: nu in [0, 0.5).
        smoothing_length: h [m]; None = options.smoothing_length_factor x mean spacing
            (spacing = V^(1/3)).
        corrected: Bonet-Lok corrected gradient (recommended; the plain sum is biased near
            free surfaces).
        contact_radius: a [m] (keyword only); None = options.contact_radius, or if that is
            None the radius (3V / 4 pi)^(1/3) of the particle nearest the contact point.
        options: FractureOptions for those defaults (default ``FractureOptions()``).

    Returns:
        :class:`ContactField` (numpy float64 arrays, SI units).
    """
    options = FractureOptions() if options is None else options
    pts = np.ascontiguousarray(points, dtype=np.float64)
    vol = np.ascontiguousarray(volumes, dtype=np.float64).reshape(-1)
    if pts.ndim != 2 or pts.shape[1] != 3 or vol.shape != (len(pts),):
        raise ValueError(f"points {pts.shape} and volumes {vol.shape} must be (N,3) and (N,)")
    if len(pts) == 0:
        raise ValueError("contact_field needs at least one particle")
    origin = np.asarray(contact_point, dtype=np.float64).reshape(3)
    if smoothing_length is None:
        smoothing_length = default_smoothing_length(vol, options.smoothing_length_factor)
    h = float(smoothing_length)
    if contact_radius is None:
        contact_radius = options.contact_radius
    if contact_radius is None:
        nearest = int(np.argmin(np.einsum("ij,ij->i", pts - origin, pts - origin)))
        contact_radius = float(np.cbrt(3.0 * vol[nearest] / (4.0 * np.pi)))
    shear_modulus = float(young_modulus) / (2.0 * (1.0 + float(poisson_ratio)))

    displacement = point_load_displacement(pts, origin, normal, force, shear_modulus,
                                           poisson_ratio, contact_radius)
    offsets, indices = neighbor_lists(pts, h)
    gradient, fallback = displacement_gradient(pts, vol, displacement, offsets, indices, h,
                                               corrected, return_fallback=True)
    stress = stress_from_gradient(gradient, young_modulus, poisson_ratio)
    values, directions = principal_stresses(stress)
    return ContactField(
        displacement=displacement,
        gradient=gradient,
        stress=stress,
        principal_values=values,
        principal_directions=directions,
        principal_stress=values[:, 0].copy(),
        principal_direction=np.ascontiguousarray(directions[:, :, 0]),
        smoothing_length=h,
        contact_radius=float(contact_radius),
        neighbor_offsets=offsets,
        neighbor_indices=indices,
        correction_fallback=fallback,
    )
