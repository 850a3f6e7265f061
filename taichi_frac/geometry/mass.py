"""Exact mass properties of tetrahedral solids (not of the particles).

For a tet with vertices v_i (relative to an origin) and volume V, the second moment
C = int x x^T dV = V/20 (sum_i v_i v_i^T + s s^T), s = sum_i v_i (Tonon, "Explicit exact
formulas for the 3-D tetrahedron inertia tensor", J. Math. Stat. 1(1), 2004). The inertia
tensor is I = rho (tr(C) Id - C), shifted to the centre of mass by the parallel-axis rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rows import corner_sum
from .topology import signed_volumes


@dataclass(frozen=True)
class MassProperties:
    """mass [kg]; center_of_mass (3,) [m]; inertia (3,3) [kg m^2] about the centre of
    mass in the mesh's axes; volume [m^3]."""

    mass: float
    center_of_mass: np.ndarray
    inertia: np.ndarray
    volume: float


def tet_mass_properties(vertices: np.ndarray, tets: np.ndarray, density, volumes=None) -> MassProperties:
    """Mass properties of a tet set. ``density`` is a scalar or per-tet (T,) [kg/m^3];
    ``volumes`` (T,) [m^3], the tets' signed volumes when the caller has them already."""
    vertices = np.asarray(vertices, dtype=np.float64)
    p = vertices[tets]  # (T,4,3)
    vol = signed_volumes(vertices, tets) if volumes is None else np.asarray(volumes, dtype=np.float64)
    rho = np.broadcast_to(np.asarray(density, dtype=np.float64), vol.shape)
    m = rho * vol
    mass = float(m.sum())
    com = _weighted_sums(m, corner_sum(p)) / (4.0 * mass)
    q = p - com  # about the centre of mass: no large parallel-axis cancellation
    s = corner_sum(q)
    w = m / 20.0
    # sum_t w_t (sum_i q_ti q_ti^T + s_t s_t^T), entry by entry (_weighted_second_moments)
    c = _weighted_second_moments(np.repeat(w, 4), q.reshape(-1, 3)) + _weighted_second_moments(w, s)
    inertia = np.trace(c) * np.eye(3) - c
    return MassProperties(mass=mass, center_of_mass=com, inertia=0.5 * (inertia + inertia.T), volume=float(vol.sum()))


# These sums are numpy's own pairwise sums, not BLAS products: a threaded BLAS splits a long
# dot product among its threads, so the last bits of a body's centre of mass and inertia, and
# with them every chaotic pile, would depend on the machine's core count.
def _weighted_sums(weights: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(3,) sum_n weights[n] rows[n] over (N,) weights and (N,3) rows."""
    return np.array([np.sum(weights * rows[:, i]) for i in range(3)])


def _weighted_second_moments(weights: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(3,3) sum_n weights[n] rows[n] rows[n]^T over (N,) weights and (N,3) rows."""
    columns = [np.ascontiguousarray(rows[:, i]) for i in range(3)]
    weighted = [weights * column for column in columns]
    c = np.empty((3, 3))
    for i in range(3):
        for j in range(i, 3):
            c[i, j] = c[j, i] = np.sum(weighted[i] * columns[j])
    return c
