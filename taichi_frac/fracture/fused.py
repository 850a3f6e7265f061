"""Steps 5-7 of an impact analysis in one kernel launch (``cracks.analyze_impact``): the
half-space displacement (``field.py``), the SPH gradient (``sph.py``) and the stress
(``stress.py``), each through the same ``ti.func`` their own kernels use: the same
arithmetic (to ~1e-16 relative, not bit for bit: LLVM's fast math may contract it
differently in another kernel). A local analysis evaluates a few hundred particles, where
three launches' Python argument handling would be most of its cost."""

import numpy as np

from ..runtime import ti
from .. import runtime
from .field import displacement_at
from .sph import CORRECTION_MIN_EIGEN_RATIO, gradient_at
from .stress import lame_parameters, stress_of, store_principal, sym_eig3_extremes_f64


@ti.kernel
def _stress_kernel(
    # Model:
    points: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m] body frame
    volumes: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (N,) [m^3]
    # Loads (``field.load_rows``), and where their displacement is needed first:
    loads: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (K,16)
    where: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (W,) particles, read from ``where_count``
    where_count: ti.i32, shear_modulus: ti.f64, poisson_ratio: ti.f64,
    # The stress at ``query``, from its SPH rows:
    query: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q,), read from ``query_count``
    query_count: ti.i32,
    offsets: ti.types.ndarray(dtype=ti.i32, ndim=1),  # (Q+1,) row q: indices[offsets[q]:offsets[q+1]]
    indices: ti.types.ndarray(dtype=ti.i32, ndim=1),
    smoothing_length: ti.f64, corrected: ti.i32, min_eigen_ratio: ti.f64, lame_lambda: ti.f64,
    # Data in/out:
    displacement: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (N,3) [m], rows ``where`` written
    stress_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) [Pa]
    largest_out: ti.types.ndarray(dtype=ti.f64, ndim=1),  # (Q,) [Pa] largest principal stress
    decompose: ti.i32,  # 1: also every query's principal stresses and directions:
    values_out: ti.types.ndarray(dtype=ti.f64, ndim=2),  # (Q,3) [Pa] descending
    directions_out: ti.types.ndarray(dtype=ti.f64, ndim=3),  # (Q,3,3) unit columns
):
    """Steps 5-7 of an analysis in one launch: the superposed half-space displacement at
    ``where`` (``field.displacement_at``), then at each query the SPH gradient
    (``sph.gradient_at``) and the stress (``stress.stress_of``): the functions of
    ``point_loads_displacement``, ``displacement_gradient`` and ``stress_from_gradient`` in one
    launch."""
    for w in range(where_count):
        i = where[w]
        u = displacement_at(points, i, loads, shear_modulus, poisson_ratio)
        for c in ti.static(range(3)):
            displacement[i, c] = u[c]
    for q in range(query_count):
        grad, _fallback = gradient_at(points, volumes, query[q], offsets[q], offsets[q + 1], indices,
                                      smoothing_length, corrected, min_eigen_ratio, displacement)
        s = stress_of(grad, lame_lambda, shear_modulus)
        for a, b in ti.static(ti.ndrange(3, 3)):
            stress_out[q, a, b] = s[a, b]
        # Distinct names: one ``_`` bound first to an i32 and then to an f64 makes Taichi
        # warn that the assignment may lose precision.
        _smallest, largest = sym_eig3_extremes_f64(s)
        largest_out[q] = largest
        if decompose == 1:
            store_principal(s, q, values_out, directions_out)


def stress_at(points, volumes, displacement, loads, where, query, offsets, indices, h, corrected,
              material, *, decompose: bool = False):
    """``_stress_kernel``: fills ``displacement`` (N,3) at ``where`` (None: leave it as it
    is) and returns, at ``query`` from the CSR rows ``offsets`` (Q+1,), ``indices``: the
    stress (Q,3,3) [Pa] and its largest principal stress (Q,) [Pa] (the closed form of
    ``stress.largest_principal_stress``); with ``decompose``, also the principal stresses
    (Q,3) [Pa] and directions (Q,3,3) of ``stress.principal_stresses``. (In the launch: a
    separate decomposition was a third launch, and the largest value a numpy pass.)"""
    runtime.init()
    lam, mu = lame_parameters(material.young_modulus, material.poisson_ratio)
    count = len(query)
    stress = np.zeros((count, 3, 3))
    largest = np.zeros(count)
    values = np.zeros((count if decompose else 1, 3))
    directions = np.zeros((count if decompose else 1, 3, 3))
    where_count = 0 if where is None else len(where)
    if count or where_count:
        def i32(a):  # (a one-element stand-in for an empty array, which a kernel cannot take)
            return np.ascontiguousarray(a if len(a) else [0], dtype=np.int32)
        _stress_kernel(points, volumes, loads, i32([] if where is None else where), where_count, float(mu),
                       float(material.poisson_ratio), i32(query), count, i32(offsets), i32(indices), float(h),
                       int(bool(corrected)), CORRECTION_MIN_EIGEN_RATIO, float(lam), displacement,
                       stress if count else np.zeros((1, 3, 3)), largest if count else np.zeros(1),
                       int(bool(decompose and count)), values if count else np.zeros((1, 3)),
                       directions if count else np.zeros((1, 3, 3)))
    if decompose:
        return stress, largest, values, directions
    return stress, largest
