"""Strain, stress and principal stresses (BRIEF.md §1 steps 7-8, corrected eq. 4).

- Strain: Green-Saint-Venant, E = 1/2 (F^T F - I) with F = I + grad u (the paper's eq. (4)
  writes J = grad u^T, which gives -I/2 for zero displacement; BRIEF.md §2). Computed as
  E = 1/2 (G + G^T + G^T G), G = grad u: the form 1/2 (F^T F - I) subtracts numbers near 1
  and loses about half of the float64 digits when |G| ~ 1e-6, as it is for a brittle solid.
- Stress: isotropic Hooke's law on that strain, S = lambda tr(E) I + 2 mu E (St Venant-
  Kirchhoff; for the tiny strains here it equals the Cauchy stress to O(|G|)).
- Principal stresses: eigenvalues of the symmetric stress by cyclic Jacobi rotations in
  f64 (:func:`sym_eig3_f64`), sorted descending; the directions are the matching columns,
  each signed so that its largest-magnitude component is positive. Why not ``ti.sym_eig``:
  Taichi 1.7.4's 3x3 solver (``taichi/_funcs.py``, Kopp's hybrid method) declares its
  temporaries with bare literals, which take the runtime's ``default_fp`` -- f32 here -- even
  with ``dt=ti.f64``; measured on 20,000 random symmetric matrices its eigenvector residual
  |A v - lambda v| reached 5e-3 x max|A| (Jacobi below: < 1e-14).
- Rankine: a crack forms where the largest principal stress exceeds the tensile strength;
  its plane's normal is that principal direction (BRIEF.md §1 step 8).

Units: stresses in Pa, gradients and strains dimensionless. Arrays float64.
"""


import math

import numpy as np

from ..runtime import ti
from .. import runtime
from ..kinematics import linalg3 as la

_vec3 = ti.types.vector(3, ti.f64)
_mat3 = ti.types.matrix(3, 3, ti.f64)


def lame_parameters(young_modulus, poisson_ratio):
    """(lambda, mu) [Pa] from E [Pa] > 0 and nu in [0, 0.5)."""
    e, nu = float(young_modulus), float(poisson_ratio)
    if not (np.isfinite(e) and e > 0.0):
        raise ValueError(f"young_modulus must be > 0, got {young_modulus!r}")
    if not (0.0 <= nu < 0.5):
        raise ValueError(f"poisson_ratio must be in [0, 0.5), got {poisson_ratio!r}")
    return e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu))


@ti.func
def _load3(a: ti.template(), q):
    m = _mat3(0.0)
    for r, c in ti.static(ti.ndrange(3, 3)):
        m[r, c] = a[q, r, c]
    return m


@ti.func
def sym_eig3_extremes_f64(a):
    """(smallest, largest) eigenvalue of a symmetric f64 3x3 matrix in closed form (the
    trigonometric solution of the characteristic cubic, as :func:`largest_principal_stress`):
    what a conditioning test needs, several times cheaper than the Jacobi sweeps of
    :func:`sym_eig3_f64`. Error ~1e-16 of the matrix's size, up to ~1e-8 where two
    eigenvalues nearly coincide (the cubic's angle keeps half the digits there)."""
    a01 = 0.5 * (a[0, 1] + a[1, 0])
    a02 = 0.5 * (a[0, 2] + a[2, 0])
    a12 = 0.5 * (a[1, 2] + a[2, 1])
    q = (a[0, 0] + a[1, 1] + a[2, 2]) / 3.0
    d0, d1, d2 = a[0, 0] - q, a[1, 1] - q, a[2, 2] - q
    p = ti.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0)
    low = q
    high = q
    if p > 0.0:
        b00, b11, b22 = d0 / p, d1 / p, d2 / p
        b01, b02, b12 = a01 / p, a02 / p, a12 / p
        det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
        phi = ti.acos(ti.min(ti.max(0.5 * det, -1.0), 1.0)) / 3.0
        high = q + 2.0 * p * ti.cos(phi)
        low = q + 2.0 * p * ti.cos(phi + 2.0 * math.pi / 3.0)
    return low, high


# Cyclic Jacobi sweeps for a 3x3 symmetric matrix: quadratic convergence, so 8 sweeps are far
# more than the 4-5 that reach f64 rounding for any input scaled to unit max entry.
_JACOBI_SWEEPS = 8


@ti.func
def sym_eig3_f64(a):
    """Eigen-decomposition of a symmetric f64 3x3 matrix by cyclic Jacobi rotations
    (Golub & Van Loan, "Matrix Computations", 4th ed., §8.5). Returns (values, vectors):
    an unsorted f64 3-vector and a matrix whose column k is the unit eigenvector of
    values[k]. Scale the input to unit max entry first: the skip test is absolute.

    Each rotation updates only the entries it changes (Numerical Recipes §11.1, eqs.
    11.1.14-11.1.17) instead of forming J^T A J and V J: the three unrolled rotations
    written as 3x3 matrix products made Taichi's Python front end spend ~0.5 s per kernel
    that inlines this function, in every new process (the offline cache keeps only the
    compiled code)."""
    a = a * 1.0  # work on a local copy
    v = ti.Matrix.identity(ti.f64, 3)
    for _sweep in range(_JACOBI_SWEEPS):
        for p, q in ti.static([(0, 1), (0, 2), (1, 2)]):
            r = ti.static(3 - p - q)  # the third index
            apq = a[p, q]
            if apq != 0.0:  # tiny a[p,q]: theta -> inf, t -> 0, no NaN
                # Rotation annihilating a[p, q] (Numerical Recipes §11.1, eqs. 11.1.8-11.1.10).
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = 1.0 / (ti.abs(theta) + ti.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / ti.sqrt(t * t + 1.0)
                s = t * c
                arp = a[r, p]
                arq = a[r, q]
                a[p, p] = a[p, p] - t * apq
                a[q, q] = a[q, q] + t * apq
                a[p, q] = 0.0
                a[q, p] = 0.0
                a[r, p] = c * arp - s * arq
                a[p, r] = a[r, p]
                a[r, q] = s * arp + c * arq
                a[q, r] = a[r, q]
                for k in ti.static(range(3)):
                    vkp = v[k, p]
                    vkq = v[k, q]
                    v[k, p] = c * vkp - s * vkq
                    v[k, q] = s * vkp + c * vkq
    return ti.Vector([a[0, 0], a[1, 1], a[2, 2]], dt=ti.f64), v


@ti.kernel
def _sym_eig_kernel(matrices: ti.types.ndarray(dtype=ti.f64, ndim=3),
                    values_out: ti.types.ndarray(dtype=ti.f64, ndim=2),
                    vectors_out: ti.types.ndarray(dtype=ti.f64, ndim=3)):
    for q in range(matrices.shape[0]):
        values, vectors = sym_eig3_f64(_load3(matrices, q))
        for r in ti.static(range(3)):
            values_out[q, r] = values[r]
            for c in ti.static(range(3)):
                vectors_out[q, r, c] = vectors[r, c]


@ti.func
def _green_strain(g):
    # 1/2 (G + G^T + G^T G) == 1/2 (F^T F - I), F = I + G, without cancellation.
    return 0.5 * (g + g.transpose() + la.mat_t_mat(g, g))


@ti.kernel
def _strain_kernel(grad: ti.types.ndarray(dtype=ti.f64, ndim=3),
                   strain_out: ti.types.ndarray(dtype=ti.f64, ndim=3)):
    for q in range(grad.shape[0]):
        e = _green_strain(_load3(grad, q))
        for r, c in ti.static(ti.ndrange(3, 3)):
            strain_out[q, r, c] = e[r, c]


@ti.kernel
def _stress_kernel(
    grad: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [-] Data in
    lame_lambda: ti.f64, shear_modulus: ti.f64,  # [Pa] Model
    stress_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [Pa] Data out
):
    for q in range(grad.shape[0]):
        s = stress_of(_load3(grad, q), lame_lambda, shear_modulus)
        for r, c in ti.static(ti.ndrange(3, 3)):
            stress_out[q, r, c] = s[r, c]


@ti.func
def stress_of(grad, lame_lambda, shear_modulus):
    """Stress [Pa] (3,3) = lambda tr(E) I + 2 mu E of the Green-Saint-Venant strain E of
    F = I + grad."""
    e = _green_strain(grad)
    return 2.0 * shear_modulus * e + lame_lambda * e.trace() * ti.Matrix.identity(ti.f64, 3)


@ti.func
def principal_of(raw):
    """Principal stresses of the (3,3) f64 stress ``raw`` (symmetrised): values (vec3 [Pa],
    descending) and directions (mat3, unit columns, each signed so its largest-magnitude
    component is positive) by Jacobi rotations (``sym_eig3_f64``) on the matrix scaled to
    unit max entry (the Jacobi skip test is absolute, so 1e-6 N and 1e9 N impacts are
    treated alike). A zero stress gives zero values and the identity."""
    sym = 0.5 * (raw + raw.transpose())
    scale = ti.cast(0.0, ti.f64)  # bare literals would be the default f32
    for r, c in ti.static(ti.ndrange(3, 3)):
        scale = ti.max(scale, ti.abs(sym[r, c]))
    values = _vec3(0.0)
    vectors = ti.Matrix.identity(ti.f64, 3)
    if scale > 0.0:
        values, vectors = sym_eig3_f64(sym / scale)
    # Sort descending: order[e] = column of the e-th largest value.
    order = ti.Vector([0, 1, 2])
    for _pass in ti.static(range(2)):
        for k in ti.static(range(2)):
            if values[order[k]] < values[order[k + 1]]:
                tmp = order[k]
                order[k] = order[k + 1]
                order[k + 1] = tmp
    # Written with fresh names and scalar stores on purpose: in Taichi 1.7.4 re-binding a
    # local vector here (`v = v * sign`) was silently dropped (seen in a unit test).
    sorted_values = _vec3(0.0)
    directions = ti.Matrix.zero(ti.f64, 3, 3)
    for e in ti.static(range(3)):
        col = order[e]
        column = _vec3(vectors[0, col], vectors[1, col], vectors[2, col])
        unit = column.normalized()
        largest = ti.abs(unit[0])
        sign = ti.cast(1.0 if unit[0] >= 0.0 else -1.0, ti.f64)
        for k in ti.static(range(1, 3)):
            if ti.abs(unit[k]) > largest:
                largest = ti.abs(unit[k])
                sign = ti.cast(1.0 if unit[k] >= 0.0 else -1.0, ti.f64)
        sorted_values[e] = values[col] * scale
        for k in ti.static(range(3)):
            directions[k, e] = unit[k] * sign
    return sorted_values, directions


@ti.func
def store_principal(s, q, values_out: ti.template(), directions_out: ti.template()):
    """Write :func:`principal_of` of the stress ``s`` into row ``q`` of ``values_out`` (Q,3)
    [Pa] and ``directions_out`` (Q,3,3) (unit columns)."""
    values, directions = principal_of(s)
    for e in ti.static(range(3)):
        values_out[q, e] = values[e]
        for k in ti.static(range(3)):
            directions_out[q, k, e] = directions[k, e]


@ti.kernel
def _principal_kernel(
    stress: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [Pa] Data in
    values_out: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (Q,3) [Pa] descending
    directions_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) columns
):
    for q in range(stress.shape[0]):
        store_principal(_load3(stress, q), q, values_out, directions_out)


def _as_tensors(a, name) -> np.ndarray:
    arr = np.ascontiguousarray(a, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1:] != (3, 3):
        raise ValueError(f"{name} must have shape (Q,3,3), got {arr.shape}")
    return arr


def green_strain(grad) -> np.ndarray:
    """Green-Saint-Venant strain 1/2 (G + G^T + G^T G) [-], (Q,3,3) from grad u (Q,3,3)."""
    runtime.init()
    g = _as_tensors(grad, "grad")
    out = np.zeros_like(g)
    if len(g):
        _strain_kernel(g, out)
    return out


def stress_from_gradient(grad, young_modulus, poisson_ratio) -> np.ndarray:
    """Stress [Pa] (Q,3,3) = lambda tr(E) I + 2 mu E, E the Green-Saint-Venant strain of
    F = I + grad (corrected eq. 4), grad (Q,3,3) [-] with grad_ab = d u_a / d x_b.

    E [Pa] > 0, nu in [0, 0.5). Symmetric by construction. f64 Taichi kernel.
    """
    runtime.init()
    g = _as_tensors(grad, "grad")
    lam, mu = lame_parameters(young_modulus, poisson_ratio)
    out = np.zeros_like(g)
    if len(g):
        _stress_kernel(g, lam, mu, out)
    return out


def principal_stresses(stress):
    """Principal stresses of symmetric stresses (Q,3,3) [Pa] (``ti.sym_eig``, f64 kernel).

    Returns:
        values (Q,3) [Pa], descending (values[:, 0] is the largest, the Rankine one);
        directions (Q,3,3), unit columns: directions[q, :, k] belongs to values[q, k], each
        signed so that its largest-magnitude component is positive. A zero stress gives
        zero values and the identity.
    """
    runtime.init()
    s = _as_tensors(stress, "stress")
    values = np.zeros((len(s), 3))
    directions = np.zeros_like(s)
    if len(s):
        _principal_kernel(s, values, directions)
    return values, directions


def largest_principal_stress(stress) -> np.ndarray:
    """The largest principal stress [Pa] (Q,) of symmetric stresses (Q,3,3) [Pa], in
    closed form (the trigonometric solution of the characteristic cubic: Smith, "Eigenvalues
    of a symmetric 3 x 3 matrix", CACM 4(4), 1961), vectorised in numpy: what the Rankine
    test and a field's peak stress read, ~10x cheaper than the Jacobi eigenvectors of
    :func:`principal_stresses`. Accurate to ~1e-8 of the stress's size (the cubic's
    angle loses half the digits only where two principal stresses coincide)."""
    s = _as_tensors(stress, "stress")
    s = 0.5 * (s + s.transpose(0, 2, 1))
    q = np.trace(s, axis1=1, axis2=2) / 3.0
    off = s[:, 0, 1] ** 2 + s[:, 0, 2] ** 2 + s[:, 1, 2] ** 2
    d0, d1, d2 = s[:, 0, 0] - q, s[:, 1, 1] - q, s[:, 2, 2] - q
    p = np.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0)
    safe = np.where(p > 0.0, p, 1.0)
    # det((S - q I) / p) / 2, clamped to the cosine's range against rounding.
    b00, b11, b22 = d0 / safe, d1 / safe, d2 / safe
    b01, b02, b12 = s[:, 0, 1] / safe, s[:, 0, 2] / safe, s[:, 1, 2] / safe
    det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    phi = np.arccos(np.clip(0.5 * det, -1.0, 1.0)) / 3.0
    return np.where(p > 0.0, q + 2.0 * p * np.cos(phi), q)


def rankine_flags(principal_values, tensile_strength) -> np.ndarray:
    """Rankine criterion: True where the largest principal stress exceeds the tensile
    strength [Pa] (BRIEF.md §1 step 8). ``principal_values`` is (Q,3) (largest first, as
    :func:`principal_stresses` returns) or (Q,) largest values. Returns (Q,) bool."""
    values = np.asarray(principal_values, dtype=np.float64)
    largest = values[:, 0] if values.ndim == 2 else values.reshape(-1)
    strength = float(tensile_strength)
    if not (np.isfinite(strength) and strength > 0.0):
        raise ValueError(f"tensile_strength must be > 0, got {tensile_strength!r}")
    return largest > strength
