"""Elastic displacement of a body under a contact force (BRIEF.md §1 step 5, §2).

The contact force on a body is split, in a local frame Oxyz at the contact point O with z
along the inward normal, into a normal load P and a tangential load Q = (Qx, Qy). The
displacement is the sum of the half-space point-load solutions (Johnson, "Contact
Mechanics", CUP 1985, §3.2, eqs. 3.19 (Boussinesq) and 3.22 (Cerruti); BRIEF.md §2 gives
the corrected form of the paper's misprinted eq. (2)):

    u = u^n(P) + u^x(Qx) + u^y(Qy)

**Regularisation** (BRIEF.md §2: the fields are singular at O, u ~ 1/rho). We evaluate the
*exact* solution of the same load applied at depth -a, i.e. a distance ``a`` outside the
surface (``z -> z + a``; a = ``contact_radius``):

- it is still an exact elastic solution everywhere in the body (Navier's equations hold in
  the whole open half-space z > -a, which contains the body z >= 0), so div sigma = 0 holds
  exactly and the SPH stress can be checked against its analytic gradient;
- on the surface z = 0 it is the field of a smooth pressure patch of radius about ``a``
  (normal traction 3 P a^3 / (2 pi (r^2 + a^2)^(5/2)), which integrates to P; half of P
  lies within r = 0.77 a) -- a finite contact patch, as a real contact has;
- it is smooth and bounded (|u| <= ~P / (G a), |sigma| <= ~P / a^2), so the answer does not
  depend on which particle happens to sit nearest the contact point, and a particle lying
  exactly on O is harmless.

A minimum-distance clamp (rho >= a) would instead leave a kink in u at rho = a and a stress
that is not in equilibrium there; a Hertz patch needs the other body's curvature, which
the rigid solver does not give us.

Points of a non-convex body can lie on the outer side of the tangent plane (z < 0). The
half-space solution says nothing there; we clamp z to 0 for them (the field stays finite
and continuous). For a convex body near the contact this never happens.
"""


import math

import numpy as np

from ..runtime import ti
from .. import runtime
from ..kinematics import linalg3 as la

# Floor on rho [m] used only when contact_radius = 0 (the exact, singular point load), so a
# particle lying exactly on the load point gives a huge but finite displacement, not NaN.
_RHO_FLOOR = 1.0e-12

_vec3 = ti.types.vector(3, ti.f64)


def contact_frame(normal_in) -> np.ndarray:
    """Orthonormal local frame at a contact, rows (e1, e2, e3) with e3 = unit inward normal.

    e1 is the unit projection, onto the tangent plane, of the world axis least aligned with
    the normal, so the frame is a deterministic function of the normal. (3,3) float64.
    """
    n = np.asarray(normal_in, dtype=np.float64).reshape(3)
    length = float(np.linalg.norm(n))
    if not np.isfinite(length) or length == 0.0:
        raise ValueError(f"contact normal must be a finite non-zero vector, got {normal_in!r}")
    e3 = n / length
    axis = np.zeros(3)
    axis[int(np.argmin(np.abs(e3)))] = 1.0
    e1 = axis - np.dot(axis, e3) * e3
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e3, e1)
    return np.stack([e1, e2, e3])


@ti.func
def _local_displacement(x: ti.f64, y: ti.f64, z: ti.f64, normal_load: ti.f64, load_x: ti.f64,
                        load_y: ti.f64, shear_modulus: ti.f64, poisson_ratio: ti.f64):
    """Boussinesq + Cerruti displacement in the local frame, z >= 0 into the solid
    (BRIEF.md §2, corrected; Johnson 1985 eqs. 3.19, 3.22). Returns a f64 3-vector [m]."""
    rho = ti.max(ti.sqrt(x * x + y * y + z * z), ti.f64(_RHO_FLOOR))
    rz = rho + z  # > 0 for z >= 0
    a = 1.0 - 2.0 * poisson_ratio
    # ti.f64(): a bare float literal in a kernel is a default_fp (f32) constant, so pi would
    # carry f32's relative error even in this f64 expression.
    c = 1.0 / (4.0 * ti.f64(math.pi) * shear_modulus)
    rho3 = rho * rho * rho
    # Normal load P (Boussinesq).
    ux = normal_load * (x * z / rho3 - a * x / (rho * rz))
    uy = normal_load * (y * z / rho3 - a * y / (rho * rz))
    uz = normal_load * (z * z / rho3 + 2.0 * (1.0 - poisson_ratio) / rho)
    # Tangential load Qx (Cerruti).
    ux += load_x * (1.0 / rho + x * x / rho3 + a * (1.0 / rz - x * x / (rho * rz * rz)))
    uy += load_x * (x * y / rho3 - a * x * y / (rho * rz * rz))
    uz += load_x * (x * z / rho3 + a * x / (rho * rz))
    # Tangential load Qy (Cerruti with x and y swapped).
    uy += load_y * (1.0 / rho + y * y / rho3 + a * (1.0 / rz - y * y / (rho * rz * rz)))
    ux += load_y * (x * y / rho3 - a * x * y / (rho * rz * rz))
    uz += load_y * (y * z / rho3 + a * y / (rho * rz))
    return _vec3(ux * c, uy * c, uz * c)


@ti.kernel
def _point_loads_kernel(
    # Model:
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m] body frame
    # Loads: (K,16) per contact: origin (3) [m], local frame e1, e2, e3 (3 each, e3 = inward
    # normal), P, Qx, Qy [N], regularisation radius a [m]
    loads: ti.types.ndarray(dtype=ti.f64, ndim=2),
    shear_modulus: ti.f64, poisson_ratio: ti.f64,
    # Data out:
    displacement_out: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m] body frame, summed
):
    for i in range(points.shape[0]):
        total = displacement_at(points, i, loads, shear_modulus, poisson_ratio)
        for c in ti.static(range(3)):
            displacement_out[i, c] = total[c]


@ti.func
def displacement_at(points: ti.template(), i, loads: ti.template(), shear_modulus, poisson_ratio):
    """The displacement [m] (body frame) of particle ``i`` under every load row of
    ``loads`` (``_point_loads_kernel``'s layout), summed."""
    total = _vec3(0.0)
    for k in range(loads.shape[0]):
        origin = _vec3(loads[k, 0], loads[k, 1], loads[k, 2])
        e1 = _vec3(loads[k, 3], loads[k, 4], loads[k, 5])
        e2 = _vec3(loads[k, 6], loads[k, 7], loads[k, 8])
        e3 = _vec3(loads[k, 9], loads[k, 10], loads[k, 11])
        d = _vec3(points[i, 0], points[i, 1], points[i, 2]) - origin
        x = la.dot(d, e1)
        y = la.dot(d, e2)
        # Load moved to depth -a (module docstring); points above the tangent plane clamped.
        z = ti.max(la.dot(d, e3), 0.0) + loads[k, 15]
        u = _local_displacement(x, y, z, loads[k, 12], loads[k, 13], loads[k, 14], shear_modulus, poisson_ratio)
        total += u[0] * e1 + u[1] * e2 + u[2] * e3
    return total


def _as_points(points) -> np.ndarray:
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N,3), got {pts.shape}")
    return pts


def _loads(normal_in, force):
    frame = contact_frame(normal_in)
    f = np.asarray(force, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(f)):
        raise ValueError(f"contact force must be finite, got {force!r}")
    qx, qy, p = frame @ f
    return frame, float(p), float(qx), float(qy)


def _check_material(shear_modulus, poisson_ratio):
    if not (np.isfinite(shear_modulus) and shear_modulus > 0.0):
        raise ValueError(f"shear_modulus must be > 0, got {shear_modulus!r}")
    if not (0.0 <= poisson_ratio < 0.5):
        raise ValueError(f"poisson_ratio must be in [0, 0.5), got {poisson_ratio!r}")


def point_load_displacement(points, contact_point, normal_in, force, shear_modulus,
                            poisson_ratio, contact_radius=None) -> np.ndarray:
    """Displacement of a body's particles under one contact force (f64 Taichi kernel).

    Args:
        points: (N,3) [m] particle positions, body frame.
        contact_point: (3,) [m] contact point O, body frame.
        normal_in: (3,) contact normal pointing INTO the body (need not be unit).
        force: (3,) [N] contact force ON the body; P = force . n (> 0 pushes in),
            (Qx, Qy) its tangential part in :func:`contact_frame`.
        shear_modulus: G [Pa] (> 0).
        poisson_ratio: nu [-] in [0, 0.5).
        contact_radius: a [m], the regularisation (module docstring: load applied at depth
            -a). None or 0 gives the exact, singular point load (rho floored at 1e-12 m);
            callers analysing an impact should pass one (``contact_field`` uses the contact
            particle's radius).

    Returns:
        (N,3) float64 [m], body frame: u = u^n + u^x + u^y (BRIEF.md §2, corrected eqs.).
    """
    return point_loads_displacement(points, np.reshape(contact_point, (1, 3)), np.reshape(normal_in, (1, 3)),
                                    np.reshape(force, (1, 3)), shear_modulus, poisson_ratio,
                                    [0.0 if contact_radius is None else contact_radius])


def point_loads_displacement(points, contact_points, normals_in, forces, shear_modulus, poisson_ratio,
                             contact_radii) -> np.ndarray:
    """The displacement of K contact forces superposed (linear elasticity): the sum of
    :func:`point_load_displacement` over the rows of ``contact_points``, ``normals_in``,
    ``forces`` (K,3) and ``contact_radii`` (K,) [m], in one launch (a launch per contact
    would pay Python's argument handling each time). (N,3) float64 [m]."""
    runtime.init()
    pts = _as_points(points)
    loads = load_rows(contact_points, normals_in, forces, contact_radii)
    _check_material(shear_modulus, poisson_ratio)
    out = np.zeros_like(pts)
    if len(pts) and len(loads):
        _point_loads_kernel(pts, loads, float(shear_modulus), float(poisson_ratio), out)
    return out


def load_rows(contact_points, normals_in, forces, contact_radii) -> np.ndarray:
    """(K,16) the kernels' load rows of K contacts (``_point_loads_kernel``): origin,
    local frame, P, Qx, Qy [N] and the regularisation radius a [m]."""
    origins = np.asarray(contact_points, dtype=np.float64).reshape(-1, 3)
    count = len(origins)
    normals = np.asarray(normals_in, dtype=np.float64).reshape(count, 3)
    forces = np.asarray(forces, dtype=np.float64).reshape(count, 3)
    radii = np.asarray(contact_radii, dtype=np.float64).reshape(count)
    loads = np.zeros((count, 16))
    for k in range(count):
        frame, p, qx, qy = _loads(normals[k], forces[k])
        a = float(radii[k])
        if not (np.isfinite(a) and a >= 0.0):
            raise ValueError(f"contact_radius must be >= 0, got {a!r}")
        loads[k, 0:3] = origins[k]
        loads[k, 3:12] = frame.reshape(-1)
        loads[k, 12:16] = (p, qx, qy, a)
    return loads


# --- numpy reference (tests, benchmarks): same field, and its exact gradient -----------------

def local_displacement_reference(x, y, z, normal_load, load_x, load_y, shear_modulus,
                                 poisson_ratio):
    """Numpy twin of the kernel's local field (BRIEF.md §2 corrected), z > 0, no clamps.

    Works on real or complex arrays (so :func:`point_load_gradient_reference` can take
    complex-step derivatives). Returns (ux, uy, uz) [m] in the local frame.
    """
    rho = np.sqrt(x * x + y * y + z * z)
    rz = rho + z
    a = 1.0 - 2.0 * poisson_ratio
    c = 1.0 / (4.0 * np.pi * shear_modulus)
    rho3 = rho ** 3
    ux = normal_load * (x * z / rho3 - a * x / (rho * rz))
    uy = normal_load * (y * z / rho3 - a * y / (rho * rz))
    uz = normal_load * (z * z / rho3 + 2.0 * (1.0 - poisson_ratio) / rho)
    ux = ux + load_x * (1.0 / rho + x * x / rho3 + a * (1.0 / rz - x * x / (rho * rz * rz)))
    uy = uy + load_x * (x * y / rho3 - a * x * y / (rho * rz * rz))
    uz = uz + load_x * (x * z / rho3 + a * x / (rho * rz))
    uy = uy + load_y * (1.0 / rho + y * y / rho3 + a * (1.0 / rz - y * y / (rho * rz * rz)))
    ux = ux + load_y * (x * y / rho3 - a * x * y / (rho * rz * rz))
    uz = uz + load_y * (y * z / rho3 + a * y / (rho * rz))
    return c * ux, c * uy, c * uz


def point_load_gradient_reference(points, contact_point, normal_in, force, shear_modulus,
                                  poisson_ratio, contact_radius=0.0, field=None):
    """Exact displacement gradient grad u [-] (N,3,3), (grad u)_ab = d u_a / d x_b, body frame.

    Complex-step differentiation (Squire & Trapp 1998) of the numpy twin of the field:
    exact to rounding, no step-size error. Points must lie strictly inside the local half
    space (z + a > 0), where the field is analytic. For tests and benchmarks, not the hot
    path. ``field`` may replace the local field function (same signature as
    :func:`local_displacement_reference`), e.g. to test the paper's printed equations.
    """
    field = local_displacement_reference if field is None else field
    pts = _as_points(points)
    origin = np.asarray(contact_point, dtype=np.float64).reshape(3)
    frame, p, qx, qy = _loads(normal_in, force)
    local = (pts - origin) @ frame.T
    local[:, 2] += float(contact_radius)
    if np.any(local[:, 2] <= 0.0):
        raise ValueError("reference gradient needs points strictly inside the half space")
    step = 1e-30 * max(1.0, float(np.abs(local).max()))
    grad_local = np.empty((len(pts), 3, 3))
    for b in range(3):
        xc = local.astype(np.complex128)
        xc[:, b] += 1j * step
        u = field(xc[:, 0], xc[:, 1], xc[:, 2], p, qx, qy, shear_modulus, poisson_ratio)
        for a_ in range(3):
            grad_local[:, a_, b] = np.imag(u[a_]) / step
    # grad_world = R^T grad_local R with rows of R = local axes.
    return np.einsum("ia,nab,bj->nij", frame.T, grad_local, frame)
