"""One impact's stress field in a body: ``contact_field`` (particles) and ``body_stress``
(a tet mesh), under any of the three stress models (docs/guide/stress-models.md).

``contact_field`` chains the stages of BRIEF.md §1 steps 5-8: Boussinesq-Cerruti
displacement at every physics particle (``field.py``), its gradient -- exact in closed form
(``halfspace.py``, method "halfspace") or by SPH (``sph.py``, method "sph") --,
Green-Saint-Venant strain, Hooke stress and principal stresses (``stress.py``).
``body_stress`` does the same on a tet mesh's centroids, and also offers method "fem",
linear elasticity on the tets (``fem.py``). Everything is in the body frame and in SI units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..options import AUTO, STRESS_MODELS, FractureOptions
from .field import load_rows, point_load_displacement, point_loads_displacement
from .halfspace import halfspace_stress_rows
from .sph import default_smoothing_length, displacement_gradient, neighbor_lists
from .stress import largest_principal_stress, principal_stresses, stress_from_gradient


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
            lists within h (reusable for per-group gradients); method "halfspace" needs none:
            offsets all 0, no indices.
        correction_fallback: (N,) bool, particles where the Bonet-Lok correction was skipped
            (near-singular neighbourhood; plain sum used). All False when not corrected.
        method: the stress model used, "halfspace" or "sph".
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
    method: str = "sph"


def contact_field(points, volumes, contact_point, normal, force, young_modulus, poisson_ratio,
                  smoothing_length=None, corrected=True, *, contact_radius=None,
                  options: FractureOptions | None = None, method: str | None = None) -> ContactField:
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
        method: "halfspace" (the gradient in closed form: exact, no neighbour search) or
            "sph" (the paper's SPH gradient, ``corrected`` or plain); None =
            ``options.stress_model``. "fem" needs the tets: use :func:`body_stress`; "auto" is "halfspace" here.

    Returns:
        :class:`ContactField` (numpy float64 arrays, SI units).
    """
    options = FractureOptions() if options is None else options
    method = options.stress_model if method is None else method
    if method == AUTO:  # (points alone have no shape to bend: the half-space answer)
        method = "halfspace"
    if method not in ("halfspace", "sph"):
        raise ValueError(f"contact_field method {method!r}: use 'halfspace' or 'sph' ('fem' needs the tets: "
                         "use body_stress(vertices, tets, ...))")
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
    if method == "halfspace":
        loads = load_rows(origin[None], np.reshape(normal, (1, 3)), np.reshape(force, (1, 3)), [contact_radius])
        gradient, stress, _largest = halfspace_stress_rows(pts, loads, np.arange(len(pts)), young_modulus,
                                                           poisson_ratio)
        offsets, indices = np.zeros(len(pts) + 1, np.int32), np.zeros(0, np.int32)
        fallback = np.zeros(len(pts), dtype=bool)
    else:
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
        method=method,
    )


@dataclass(frozen=True, eq=False)
class BodyStress:
    """The stress of a tet mesh under one impact's contacts, at its T tet centroids.

    Attributes:
        stress: (T,3,3) [Pa], symmetric.
        principal_stress: (T,) [Pa] the largest principal stress (Rankine).
        displacement: (T,3) [m] at the centroids (for "fem", the mean of the tet's nodes,
            rigid motion removed).
        centroids: (T,3) [m]; volumes: (T,) [m^3].
        contact_radius: (K,) [m] the load patches' radii.
        method: "halfspace", "sph" or "fem".
    """

    stress: np.ndarray
    principal_stress: np.ndarray
    displacement: np.ndarray
    centroids: np.ndarray
    volumes: np.ndarray
    contact_radius: np.ndarray
    method: str


def body_stress(vertices, tets, density, contact_points, normals, forces, young_modulus, poisson_ratio,
                method: str = "halfspace", *, contact_radius=None, smoothing_length_factor: float = 2.0,
                corrected: bool = True) -> BodyStress:
    """Stress at a body's tet centroids (its physics particles) under K contact forces.

    Args:
        vertices: (V,3) [m]; tets: (T,4) vertex indices; density [kg/m^3] (used by "fem":
            the inertia relief that balances the load on the free body).
        contact_points: (K,3) or (3,) [m]; normals: (K,3) or (3,) pointing INTO the body;
            forces: (K,3) or (3,) [N] on the body.
        young_modulus: E [Pa]; poisson_ratio: nu in [0, 0.5).
        method: "halfspace" (exact stress of the regularised Boussinesq-Cerruti load, closed
            form), "sph" (its SPH gradient, the paper's) or "fem" (linear elasticity on the
            tets; assembles and factorises the stiffness: keep ``fracture.fem.elastic_body``
            to analyse many impacts on one body).
        contact_radius: a [m] of every load patch, or (K,); None = the radius
            (3V / 4 pi)^(1/3) of the tet nearest each contact point.
        smoothing_length_factor, corrected: the SPH settings ("sph" only).
    """
    from ..geometry.topology import signed_volumes
    from .fem import elastic_body, fem_response

    if method not in STRESS_MODELS or method == AUTO:
        raise ValueError(f"body_stress method {method!r}: use one of "
                         + ", ".join(m for m in STRESS_MODELS if m != AUTO))
    verts = np.ascontiguousarray(vertices, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    if verts.ndim != 2 or verts.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 or len(tets) == 0:
        raise ValueError(f"vertices {verts.shape} and tets {tets.shape} must be (V,3) and (T,4), T > 0")
    centroids = verts[tets].mean(axis=1)
    volumes = np.abs(signed_volumes(verts, tets))
    points = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    count = len(points)
    normals = np.asarray(normals, dtype=np.float64).reshape(count, 3)
    forces = np.asarray(forces, dtype=np.float64).reshape(count, 3)
    if contact_radius is None:
        d2 = ((centroids[None, :, :] - points[:, None, :]) ** 2).sum(axis=2)
        radii = np.cbrt(3.0 * volumes[np.argmin(d2, axis=1)] / (4.0 * np.pi))
    else:
        radii = np.broadcast_to(np.asarray(contact_radius, dtype=np.float64), (count,)).copy()
    if method == "fem":
        body = elastic_body(verts, tets, density, young_modulus, poisson_ratio)
        nodal, stress = fem_response(body, points, normals, forces, radii)
        displacement = nodal[body.tets].mean(axis=1)
    else:
        shear = float(young_modulus) / (2.0 * (1.0 + float(poisson_ratio)))
        displacement = point_loads_displacement(centroids, points, normals, forces, shear, poisson_ratio, radii)
        if method == "halfspace":
            _grad, stress, _largest = halfspace_stress_rows(centroids, load_rows(points, normals, forces, radii),
                                                            np.arange(len(centroids)), young_modulus, poisson_ratio)
        else:
            h = default_smoothing_length(volumes, smoothing_length_factor)
            offsets, indices = neighbor_lists(centroids, h)
            grad = displacement_gradient(centroids, volumes, displacement, offsets, indices, h, corrected)
            stress = stress_from_gradient(grad, young_modulus, poisson_ratio)
    return BodyStress(stress=stress, principal_stress=largest_principal_stress(stress), displacement=displacement,
                      centroids=centroids, volumes=volumes, contact_radius=radii, method=method)
