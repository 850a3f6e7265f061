"""The exact stress of the regularised half-space load: the closed-form gradient of the
Boussinesq-Cerruti displacement (``field.py``), summed over a step's contacts.

The displacement of ``field.py`` is a closed form in the contact's local frame (x, y along
the tangent plane, z into the body, the load moved to depth -a), so its gradient is one too.
Every term of BRIEF.md §2's corrected equations is a monomial in (x, y, z) times one of five
radial factors,

    1/rho, 1/rho^3, 1/R, 1/(rho R), 1/(rho R^2),      R = rho + z,

whose gradients are elementary (d rho = p / rho, d R = p / rho + e_z); the product rule
gives d u_a / d x_b exactly, in f64, with no neighbour search and no discretisation error.
Rotated to the body frame (grad_body = E^T grad_local E, rows of E the local axes) and
summed over the contacts (linear elasticity superposes), it goes through the same strain and
Hooke law as the SPH path (``stress.stress_of``).

Points on the outer side of a contact's tangent plane have z clamped to 0 in the
displacement (``field.py``); their z-derivative is 0 accordingly, so the gradient is the
exact gradient of the field that ``field.py`` evaluates everywhere.
"""

import math

import numpy as np

from ..runtime import ti
from .. import runtime
from ..kinematics import linalg3 as la
from .field import _check_material, _as_points, load_rows
from .stress import lame_parameters, stress_of, store_principal, sym_eig3_extremes_f64

_vec3 = ti.types.vector(3, ti.f64)
_mat3 = ti.types.matrix(3, 3, ti.f64)
_RHO_FLOOR = 1.0e-12  # as field.py: only the singular, unregularised load reaches it


@ti.func
def _local_gradient(x: ti.f64, y: ti.f64, z: ti.f64, normal_load: ti.f64, load_x: ti.f64, load_y: ti.f64,
                    shear_modulus: ti.f64, poisson_ratio: ti.f64):
    """grad u (3,3) [-] in the local frame, G[a, b] = d u_a / d x_b, of field.py's
    ``_local_displacement`` (BRIEF.md §2 corrected) at (x, y, z), z > 0."""
    p = _vec3(x, y, z)
    rho = ti.max(la.norm(p), ti.f64(_RHO_FLOOR))
    big_r = rho + z
    a = 1.0 - 2.0 * poisson_ratio
    c = 1.0 / (4.0 * ti.f64(math.pi) * shear_modulus)
    ez = _vec3(0.0, 0.0, 1.0)
    g_rho = p / rho
    g_big_r = g_rho + ez
    # The five radial factors and their gradients.
    i1 = 1.0 / rho
    g_i1 = -p / (rho * rho * rho)
    i3 = i1 * i1 * i1
    g_i3 = -3.0 * i3 / rho * g_rho
    ir = 1.0 / big_r
    g_ir = -ir * ir * g_big_r
    irr = 1.0 / (rho * big_r)
    g_irr = -irr * (g_rho / rho + g_big_r / big_r)
    irr2 = irr / big_r
    g_irr2 = -irr2 * (g_rho / rho + 2.0 * g_big_r / big_r)
    # Monomials' gradients.
    g_x = _vec3(1.0, 0.0, 0.0)
    g_y = _vec3(0.0, 1.0, 0.0)
    g_xz = _vec3(z, 0.0, x)
    g_yz = _vec3(0.0, z, y)
    g_zz = _vec3(0.0, 0.0, 2.0 * z)
    g_xx = _vec3(2.0 * x, 0.0, 0.0)
    g_yy = _vec3(0.0, 2.0 * y, 0.0)
    g_xy = _vec3(y, x, 0.0)
    # d(m f) = f dm + m df, term by term of field.py's equations.
    # Normal load P (Boussinesq).
    d_ux = normal_load * (i3 * g_xz + x * z * g_i3 - a * (irr * g_x + x * g_irr))
    d_uy = normal_load * (i3 * g_yz + y * z * g_i3 - a * (irr * g_y + y * g_irr))
    d_uz = normal_load * (i3 * g_zz + z * z * g_i3 + 2.0 * (1.0 - poisson_ratio) * g_i1)
    # Tangential load Qx (Cerruti).
    d_ux += load_x * (g_i1 + i3 * g_xx + x * x * g_i3 + a * (g_ir - irr2 * g_xx - x * x * g_irr2))
    d_uy += load_x * (i3 * g_xy + x * y * g_i3 - a * (irr2 * g_xy + x * y * g_irr2))
    d_uz += load_x * (i3 * g_xz + x * z * g_i3 + a * (irr * g_x + x * g_irr))
    # Tangential load Qy (Cerruti with x and y swapped).
    d_uy += load_y * (g_i1 + i3 * g_yy + y * y * g_i3 + a * (g_ir - irr2 * g_yy - y * y * g_irr2))
    d_ux += load_y * (i3 * g_xy + x * y * g_i3 - a * (irr2 * g_xy + x * y * g_irr2))
    d_uz += load_y * (i3 * g_yz + y * z * g_i3 + a * (irr * g_y + y * g_irr))
    grad = _mat3(0.0)
    for b in ti.static(range(3)):
        grad[0, b] = c * d_ux[b]
        grad[1, b] = c * d_uy[b]
        grad[2, b] = c * d_uz[b]
    return grad


@ti.func
def halfspace_gradient_at(points: ti.template(), i, loads: ti.template(), shear_modulus, poisson_ratio):
    """grad u (3,3) [-], body frame, at particle ``i`` under every load row of ``loads``
    (``field.load_rows``' layout), summed: the exact gradient of ``field.displacement_at``."""
    total = _mat3(0.0)
    for k in range(loads.shape[0]):
        origin = _vec3(loads[k, 0], loads[k, 1], loads[k, 2])
        frame = _mat3(0.0)  # rows e1, e2, e3
        for r, col in ti.static(ti.ndrange(3, 3)):
            frame[r, col] = loads[k, 3 + 3 * r + col]
        d = _vec3(points[i, 0], points[i, 1], points[i, 2]) - origin
        local = la.mat_vec(frame, d)
        depth = local[2]
        z = ti.max(depth, 0.0) + loads[k, 15]
        g = _local_gradient(local[0], local[1], z, loads[k, 12], loads[k, 13], loads[k, 14], shear_modulus,
                            poisson_ratio)
        if depth < 0.0:  # z clamped there (field.py): the field does not vary with depth
            for r in ti.static(range(3)):
                g[r, 2] = 0.0
        total += la.mat_mat(la.mat_t_mat(frame, g), frame)
    return total


@ti.kernel
def _halfspace_kernel(
    # Model:
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m] body frame
    loads: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (K,16) field.load_rows
    query: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,) particles, read from query_count
    query_count: ti.i32, shear_modulus: ti.f64, poisson_ratio: ti.f64, lame_lambda: ti.f64,
    # Data out:
    grad_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [-]
    stress_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [Pa]
    largest_out: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (Q,) [Pa]
    decompose: ti.i32,  # 1: also the principal stresses and directions:
    values_out: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (Q,3) [Pa] descending
    directions_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) unit columns
):
    for q in range(query_count):
        grad = halfspace_gradient_at(points, query[q], loads, shear_modulus, poisson_ratio)
        s = stress_of(grad, lame_lambda, shear_modulus)
        for a, b in ti.static(ti.ndrange(3, 3)):
            grad_out[q, a, b] = grad[a, b]
            stress_out[q, a, b] = s[a, b]
        _smallest, largest = sym_eig3_extremes_f64(s)
        largest_out[q] = largest
        if decompose == 1:
            store_principal(s, q, values_out, directions_out)


def halfspace_stress_rows(points, loads, query, young_modulus, poisson_ratio, *, decompose=False):
    """The exact half-space stress at particles ``query`` (Q,) of ``points`` (N,3) [m] under
    the load rows ``loads`` (K,16) of ``field.load_rows``. Returns (grad (Q,3,3) [-], stress
    (Q,3,3) [Pa], largest principal stress (Q,) [Pa]) and, with ``decompose``, the principal
    stresses (Q,3) [Pa] descending and directions (Q,3,3) (unit columns)."""
    runtime.init()
    pts = _as_points(points)
    lam, mu = lame_parameters(young_modulus, poisson_ratio)
    query = np.ascontiguousarray(query, dtype=np.int32).reshape(-1)
    count = len(query)
    if count and (query.min() < 0 or query.max() >= len(pts)):
        raise ValueError("query indices out of range")
    grad = np.zeros((max(count, 1), 3, 3))
    stress = np.zeros((max(count, 1), 3, 3))
    largest = np.zeros(max(count, 1))
    values = np.zeros((count if decompose and count else 1, 3))
    directions = np.zeros((count if decompose and count else 1, 3, 3))
    loads = np.ascontiguousarray(loads, dtype=np.float64).reshape(-1, 16)
    if count:
        _halfspace_kernel(pts, loads if len(loads) else np.zeros((1, 16)), query, count if len(loads) else 0,
                          float(mu), float(poisson_ratio), float(lam), grad, stress, largest,
                          int(bool(decompose)), values, directions)
    out = (grad[:count], stress[:count], largest[:count])
    if decompose:
        return out + (values[:count], directions[:count])
    return out


def point_loads_gradient(points, contact_points, normals_in, forces, shear_modulus, poisson_ratio,
                         contact_radii) -> np.ndarray:
    """Exact displacement gradient grad u [-] (N,3,3), (grad u)_ab = d u_a / d x_b, body
    frame, of :func:`field.point_loads_displacement` (the same K contacts superposed: rows
    of ``contact_points``, ``normals_in`` (into the body), ``forces`` (K,3) [N] and
    ``contact_radii`` (K,) [m]). One f64 Taichi launch, closed form."""
    _check_material(shear_modulus, poisson_ratio)
    pts = _as_points(points)
    loads = load_rows(contact_points, normals_in, forces, contact_radii)
    young = 2.0 * float(shear_modulus) * (1.0 + float(poisson_ratio))
    grad, _stress, _largest = halfspace_stress_rows(pts, loads, np.arange(len(pts)), young, poisson_ratio)
    return grad
