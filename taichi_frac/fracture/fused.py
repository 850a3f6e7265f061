"""Steps 5-7 of an impact analysis in one kernel launch (``cracks.analyze_impact``): the
half-space displacement (``field.py``), the SPH gradient (``sph.py``) and the stress
(``stress.py``), each through the same ``ti.func`` their own kernels use: the same
arithmetic (to ~1e-16 relative, not bit for bit: LLVM's fast math may contract it
differently in another kernel). A local analysis evaluates a few hundred particles, where
three launches' Python argument handling (~0.55 ms) was most of its cost."""

import numpy as np
import taichi as ti

from .. import runtime
from .field import displacement_at
from .sph import CORRECTION_MIN_EIGEN_RATIO, gradient_at
from .stress import lame_parameters, stress_of


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
        grad, _ = gradient_at(points, volumes, query[q], offsets[q], offsets[q + 1], indices, smoothing_length,
                              corrected, min_eigen_ratio, displacement)
        s = stress_of(grad, lame_lambda, shear_modulus)
        for a, b in ti.static(ti.ndrange(3, 3)):
            stress_out[q, a, b] = s[a, b]


def stress_at(points, volumes, displacement, loads, where, query, offsets, indices, h, corrected,
               material) -> np.ndarray:
    """``_stress_kernel``: fills ``displacement`` (N,3) at ``where`` (None: leave it as it
    is) and returns the stress (Q,3,3) [Pa] at ``query`` from the CSR rows ``offsets``
    (Q+1,), ``indices``."""
    runtime.init()
    lam, mu = lame_parameters(material.young_modulus, material.poisson_ratio)
    stress = np.zeros((len(query), 3, 3))
    where_count = 0 if where is None else len(where)
    if len(query) or where_count:
        def i32(a):  # (a one-element stand-in for an empty array, which a kernel cannot take)
            return np.ascontiguousarray(a if len(a) else [0], dtype=np.int32)
        _stress_kernel(points, volumes, loads, i32([] if where is None else where), where_count, float(mu),
                       float(material.poisson_ratio), i32(query), len(query), i32(offsets), i32(indices), float(h),
                       int(bool(corrected)), CORRECTION_MIN_EIGEN_RATIO, float(lam), displacement,
                       stress if len(query) else np.zeros((1, 3, 3)))
    return stress
